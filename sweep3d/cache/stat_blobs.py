"""Stat every PNG blob of a store's blob folders; imports nothing but the standard library, so
that it runs as a script in a child process (see :class:`sweep3d.cache.snapshot.StateSnapshot`).

    python stat_blobs.py STORE/blobs

writes to standard output the number of blobs n (8 bytes, little-endian), their states (n × 4
native int64: size, mtime_ns, ctime_ns, inode) and their keys (UTF-8, one per line), in key
order (folder by folder, each sorted: the parent's sorted keys then meet them without a lookup).
Everything is stat'ed before anything is written: the reader then only streams.
"""

from __future__ import annotations

import array
import os
import sys

EXT = ".png"


def stat_folder(path: str, names: list[str], states: array.array) -> None:
    """Add the PNG blobs of folder ``path`` (names without the extension) and their states."""
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        append = states.extend
        for name in sorted(os.listdir(fd)):
            if not name.endswith(EXT):
                continue
            try:
                st = os.stat(name, dir_fd=fd)
            except OSError:
                continue  # gone or unreadable: the caller stats what it does not find here
            names.append(name[: -len(EXT)])
            append((st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino))
    finally:
        os.close(fd)


def main(blobs: str) -> None:
    names: list[str] = []
    states = array.array("q")
    for folder in sorted(os.listdir(blobs)):
        path = os.path.join(blobs, folder)
        if len(folder) == 2 and os.path.isdir(path):
            stat_folder(path, names, states)
    out = sys.stdout.buffer
    out.write(len(names).to_bytes(8, "little"))
    states.tofile(out)
    out.write("\n".join(names).encode())
    out.flush()


if __name__ == "__main__":
    main(sys.argv[1])
