"""``python -m sweep3d`` runs the command line."""

from sweep3d.cli import main

if __name__ == "__main__":
    main()
