"""What a derived file was written from: a digest remembered beside the file's state.

A run writes its plan as the jobs file again and again; at 10⁶ jobs, building and encoding the
table only to find the same bytes takes seconds. The writer remembers the digest of what it
wrote the file from (``verified/written/<name>.json``) together with the file's state right
after writing (size, mtime, change time, inode). A later writer with the same digest leaves the
file alone only while its state is still that one: a file replaced, edited in place or damaged
through the file system has another change time, and is written again.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from sweep3d.cache.store import Store, atomic_write


def written_from(store: Store, path: Path) -> str | None:
    """The digest ``path`` was last written from, if the file is still exactly as written then."""
    try:
        recorded = json.loads(_record_path(store, path).read_bytes())
        return recorded["digest"] if recorded["state"] == _state(path) else None
    except (OSError, ValueError, KeyError, TypeError):
        return None


def remember_written(store: Store, path: Path, digest: str) -> None:
    """Record that ``path``, as it is now, was written from ``digest`` (call it right after)."""
    record = {"digest": digest, "state": _state(path)}
    atomic_write(_record_path(store, path), json.dumps(record).encode(), durable=False)


def _state(path: Path) -> list[int]:
    st = os.stat(path)
    return [st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino]


def _record_path(store: Store, path: Path) -> Path:
    return store.root / "verified" / "written" / f"{path.parent.name}-{path.name}.json"
