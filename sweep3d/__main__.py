"""``python -m sweep3d`` runs the command line."""

from sweep3d.cli import console_main

if __name__ == "__main__":
    console_main()
