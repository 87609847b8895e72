"""The store's files: atomic writes, one-line errors for what the disk refuses, listings, names.

Every write is a temp file plus an atomic rename, so a killed process leaves either a whole file
or none. A full disk or a read-only folder is a :class:`StoreWriteError`, a folder that cannot
be read a :class:`StoreReadError` (one-line user errors); a failed write leaves no temp file.
"""

from __future__ import annotations

import errno
import hashlib
import os
import shutil
import time
import uuid
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterator

import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.core import UserError

#: Write failures the user can fix (free space, permissions, a folder where a file should be),
#: reported as one line, not a traceback.
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EISDIR,
                          errno.ENOTDIR})
#: How to fix what an errno says about a path of the store (permissions, a misplaced file or folder).
FIXES = {errno.EACCES: "fix its permissions", errno.EPERM: "fix its permissions",
         errno.EISDIR: "a folder is where the store keeps a file: move it away",
         errno.ENOTDIR: "a file is where the store keeps a folder: move it away"}
#: What reading a damaged Parquet file raises (pyarrow's ArrowInvalid is a ValueError).
READ_ERRORS = (OSError, ValueError, pa.ArrowException)
MAX_FILENAME_BYTES = 120  # of an experiment's name in file names: with suffixes, well under 255


class StoreWriteError(UserError):
    """The store cannot be written: a full disk, a quota, a read-only or forbidden folder."""


class StoreReadError(UserError):
    """A folder or file of the store cannot be read (its permissions), or is not what the store
    keeps there (a file where a folder should be)."""


def safe_filename(name: str) -> str:
    """A file name for ``name`` that no other name maps to.

    A short name of letters, digits and ``-_.`` is its own file name (existing stores keep their
    paths). Any other keeps those characters, replaces the rest with ``_`` and adds ``~`` and a
    hash of the exact name: ``a/b`` and ``a_b`` once shared a jobs file, and ``~`` never appears
    in a name that is its own file name.
    """
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
    if safe == name and len(name.encode()) <= MAX_FILENAME_BYTES:
        return name
    short = safe.encode()[:MAX_FILENAME_BYTES].decode(errors="ignore")
    return f"{short}~{hashlib.sha256(name.encode()).hexdigest()[:16]}"


def utc_now() -> datetime:
    """Now, in UTC, as a naive timestamp (tz-aware ones would need pytz to read back through DuckDB)."""
    return datetime.now(timezone.utc).replace(tzinfo=None)


#: The way out of a full or read-only disk under the store (a file the user chose elsewhere has its own).
STORE_FIX = "set experiment.store to a folder on another disk"


def atomic_write(path: Path, data: bytes, durable: bool = True, fix: str = STORE_FIX) -> None:
    """Write ``data`` to ``path`` through a temp file in the same folder and a rename; the folder
    is made when it is missing (not asked for each time: writers of many small files call this).

    Args:
        durable: fsync before the rename; a cache whose damaged file is only a miss may skip it.
        fix: what the error advises besides freeing space or permissions: the store's own way
            (:data:`STORE_FIX`), or, for a file written outside the store, how to write it elsewhere.

    Raises:
        StoreWriteError: the disk is full or the folder is not writable (no temp file is left).
    """
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        try:
            fh = open(tmp, "wb")
        except FileNotFoundError:  # its folder is not there yet
            path.parent.mkdir(parents=True, exist_ok=True)
            fh = open(tmp, "wb")
        with fh:
            fh.write(data)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        _unlink_quietly(tmp)
        if _is_write_error(exc):
            raise _as_write_error(exc, path, fix) from None
        raise


def _is_write_error(exc: BaseException) -> bool:
    if not isinstance(exc, OSError):
        return False
    return exc.errno in WRITE_ERRNOS or "No space left on device" in str(exc)


def _as_write_error(exc: BaseException, path: Path, fix: str = STORE_FIX) -> StoreWriteError:
    assert isinstance(exc, OSError)
    code = exc.errno if exc.errno in WRITE_ERRNOS else errno.ENOSPC
    reason = exc.strerror or os.strerror(code)
    if code in (errno.EISDIR, errno.ENOTDIR):
        return StoreWriteError(f"cannot write {path}: {reason}; {FIXES[code]}")
    if code in FULL_ERRNOS:
        return full_disk_error(OSError(code, reason), f"write {path}", path, fix)
    return StoreWriteError(f"cannot write {path}: {reason}; make the folder writable, or {fix}")


#: What a full disk, or a used-up quota, raises.
FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)


def is_full_disk(exc: BaseException) -> bool:
    """Whether ``exc`` says the disk (or the user's quota) is full, however it lost its path."""
    return isinstance(exc, OSError) and (exc.errno in FULL_ERRNOS or "No space left on device" in str(exc))


def full_disk_error(exc: OSError, doing: str, path: Path, fix: str = STORE_FIX) -> StoreWriteError:
    """One line for a full disk met while ``doing`` (``"write <path>"``) at ``path``: that the disk
    is full, which one (where it is mounted, what is left) and the fix (``fix``: the store's, or
    how to write a file of the user's choosing elsewhere)."""
    reason = exc.strerror or os.strerror(exc.errno or errno.ENOSPC)
    what = "the disk quota is used up" if exc.errno == errno.EDQUOT else "the disk is full"
    mount = mount_point(path)
    try:
        left = f"{_size(shutil.disk_usage(mount).free)} free on the disk mounted at {mount}"
    except OSError:
        left = f"the disk mounted at {mount}"
    return StoreWriteError(f"cannot {doing}: {what} ({reason}; {left}); free some disk space, or {fix}")


def mount_point(path: Path) -> Path:
    """The mount point of the file system ``path`` (or its nearest existing folder) is on."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    while not os.path.ismount(path) and path != path.parent:
        path = path.parent
    return path


def _size(n: int) -> str:
    """``n`` bytes for a person: ``0 B``, ``512 kB``, ``3.2 GB``."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} B"


def store_error(exc: OSError, doing: str) -> StoreReadError | StoreWriteError:
    """One line for ``exc``, met reading or writing (``doing``) a path of the store: the path
    (for a permission, the outermost folder that denies it) and how to fix it."""
    path = Path(exc.filename) if exc.filename else Path(".")
    if exc.errno in (errno.EACCES, errno.EPERM):
        path = _blocked(path)
    error = StoreReadError if doing == "read" else StoreWriteError
    return error(f"cannot {doing} {path} ({exc.strerror or exc}); {FIXES.get(exc.errno or 0, 'check the disk')}")


def _blocked(path: Path) -> Path:
    """The outermost of ``path`` and its folders that this process may not read (``path`` itself
    when none is found: a denial that ``os.access`` does not see)."""
    for folder in reversed(path.parents):
        if not os.access(folder, os.R_OK | os.X_OK):
            return folder
    return path


def scan(folder: Path) -> list[os.DirEntry]:
    """The entries of ``folder`` ([] when it is not there).

    Raises:
        StoreReadError: it cannot be read (its permissions, a file in its place): never taken
            for an empty folder, or gc would delete every blob whose row it could not see.
    """
    try:
        with os.scandir(folder) as entries:
            return list(entries)
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise store_error(exc, "read") from None


def read_parquet(path: str | Path, columns: list[str] | None = None, verify: bool = False) -> pa.Table:
    """One Parquet file as a table, its schema's metadata kept (``verify``: check page checksums).

    Through ``pq.ParquetFile``, not ``pq.read_table``: the latter goes through pyarrow.dataset,
    whose import (pandas' with it) adds 0.3 s to every command that reads the store."""
    with pq.ParquetFile(path, page_checksum_verification=verify) as parquet:
        return parquet.read(columns=columns)


def _holds(path: Path, data: pa.Buffer) -> bool:
    """Whether the file at ``path`` holds exactly ``data``."""
    try:
        if os.stat(path).st_size != data.size:
            return False
        with open(path, "rb") as fh:
            return pa.py_buffer(fh.read()).equals(data)
    except OSError:
        return False


def _unlink_quietly(path: Path) -> None:
    try:
        path.unlink()
    except OSError:
        pass


def segment_name() -> str:
    """A new segment's file name: sorts in write order, unique across processes."""
    return f"{time.time_ns():020d}-{os.getpid()}-{uuid.uuid4().hex[:8]}.parquet"


def _is_segment_name(name: str) -> bool:
    """Whether ``name`` could be a segment's (a ``.parquet`` file's name, no folder, not hidden):
    a compaction record naming anything else is not followed out of the table's folder."""
    return name.endswith(".parquet") and not name.startswith(".") and name == Path(name).name


def _relative(path: Path, root: Path) -> Path:
    try:
        return path.relative_to(root)
    except ValueError:
        return Path(path.name)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"


def store_files(folder: Path) -> Iterator[os.DirEntry]:
    """The files under ``folder`` at any depth, as the store wrote them: symbolic links (to a
    file or a folder, or ``folder`` itself one) are not the store's and are skipped, never followed."""
    if folder.is_symlink():
        return
    for entry in scan(folder):
        if entry.is_dir(follow_symlinks=False):
            yield from store_files(Path(entry.path))
        elif entry.is_file(follow_symlinks=False):
            yield entry
