"""Which folders may be a store: a new or empty one, or one a store already made.

A store writes ``blobs/``, ``tables/``, ``jobs/`` and a ``lock`` file into its folder, makes
folders in it and, on ``cache gc``, removes files from them. Pointed at ``/``, ``/etc``,
``/proc/self`` or a project's own folder by a typo, the first run would write into a folder it
does not own (or fail half-way in a way that names no mistake). So a spec's store is refused
when it is a system folder, a top-level folder, the home folder itself, or an existing folder
holding other files and none of a store's own entries (how a store is known: it has no marker
file, but every store that was written to holds its ``lock`` and ``tables/`` or ``blobs/``, and
one that was only planned holds nothing but folders a store makes).
"""

from __future__ import annotations

import os
from pathlib import Path

from sweep3d.cache.contracts import known_folder

#: Folders that hold the system: a store may be neither one of them nor inside one.
SYSTEM_FOLDERS = tuple(Path(p) for p in ("/bin", "/boot", "/dev", "/etc", "/lib", "/lib32", "/lib64", "/libx32",
                                         "/proc", "/sbin", "/sys", "/usr"))
#: What a store makes in its folder first (``Store.lock``, ``Store.append``, the blobs): one of
#: them there says the folder is a store's, whatever else a user put beside them.
STORE_ENTRIES = ("lock", "tables", "blobs", "jobs")
#: Everything else the store itself makes at its top (``plan`` extracts a zipped mesh into
#: ``assets/`` before any lock): a folder holding only these, or folders that packages writing the
#: store declare (:func:`~sweep3d.cache.contracts.register_store_folder`), is a store's too.
STORE_MADE = frozenset({*STORE_ENTRIES, "assets", "cache", "models", "outputs", "quarantine", "reports", "tmp",
                        "verified"})
FIX = "set experiment.store to a new or empty folder (relative to the spec), e.g. \".sweep3d\""


def store_folder_problem(path: Path) -> str | None:
    """Why the resolved folder ``path`` cannot be a store, or None when it can (it does not exist
    yet, is empty, or holds a store)."""
    if path == Path(path.anchor) or path.parent == Path(path.anchor):
        return f"{str(path)!r} is a top-level folder of the system, not a store's; {FIX}"
    system = next((folder for folder in SYSTEM_FOLDERS if path.is_relative_to(folder)), None)
    if system is not None:
        return f"{str(path)!r} is inside the system folder {str(system)!r}, not a place for a store; {FIX}"
    if path == _home():
        return f"{str(path)!r} is the home folder itself, whose files a store does not own; {FIX}"
    try:
        if not path.is_dir():
            return f"{str(path)!r} is a file, not a folder; {FIX}" if path.exists() else None
        with os.scandir(path) as entries:
            names = sorted(entry.name for _, entry in zip(range(64), entries))
    except OSError:  # a folder this user cannot list: the store's own errors name it when it is used
        return None
    if all(_store_made(name) for name in names) or any((path / name).exists() for name in STORE_ENTRIES):
        return None
    names = [name for name in names if not _store_made(name)]
    shown = ", ".join(names[:3]) + (", …" if len(names) > 3 else "")
    return (f"{str(path)!r} already holds other files ({shown}) and no sweep3d store (a store's folder has "
            f"{', '.join(STORE_ENTRIES)}), so its files would be mixed with the store's; {FIX}")


def _store_made(name: str) -> bool:
    """Whether a store makes an entry of this ``name`` at its top (the registry's declared folders
    are looked up only for a name that is none of the store's own)."""
    return name in STORE_MADE or name.startswith(".probe-") or known_folder(name)


def _home() -> Path | None:
    try:
        return Path.home().resolve()
    except (RuntimeError, OSError):  # no home folder known
        return None
