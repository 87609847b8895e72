"""List and stat every blob of a store's blob folders; imports nothing but the standard library,
so that it runs as a script in a child process (see :class:`sweep3d.cache.snapshot.StateSnapshot`).

    python stat_blobs.py STORE/blobs [PART PARTS]

lists the blob folders (with PART and PARTS, only the PART-th of PARTS runs of them in name
order, so that several children share the work and their outputs follow one another in key
order) and writes to standard output the number of blobs n, the byte length k of their keys' text and the
byte length m of the other names (8 bytes each, little-endian), the SHA-256 of the states and
keys that follow (32 bytes), every other name in the blob folders as ``<folder>/<name>``, NUL
between two (m bytes: a killed writer's temp file, a pass's blob), then the blobs' states (n × 4
native int64: size, mtime_ns, ctime_ns, inode) and their keys (k bytes of UTF-8, NUL between
two) in key order (folder by folder, each sorted: the parent's sorted keys then meet them
without a hash lookup). A name that is not UTF-8 is written as the file system gave it
(``surrogateescape``). A parent that needs only the digest and the other names closes the pipe
after them.
A blob is ``<key>.png`` in the folder named by its key's first two characters, as the store
places it. Everything is listed and stat'ed before anything is written: the reader only streams.
"""

from __future__ import annotations

import array
import hashlib
import os
import sys

EXT = ".png"
SEPARATOR = "\0"  # between names: the one character no file name holds


def stat_folder(path: str, folder: str, keys: list[str], states: array.array, others: list[str]) -> None:
    """Add the blobs of the folder at ``path`` (their keys and states), and its other names."""
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        append = states.extend
        for name in sorted(os.listdir(fd)):
            key = name[: -len(EXT)]
            if not name.endswith(EXT) or key[:2] != folder:
                others.append(f"{folder}/{name}")
                continue
            try:
                st = os.stat(name, dir_fd=fd)
            except OSError:
                continue  # gone or unreadable: the caller stats what it does not find here
            keys.append(key)
            append((st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino))
    finally:
        os.close(fd)


def main(blobs: str, part: int = 0, parts: int = 1) -> None:
    keys: list[str] = []
    others: list[str] = []
    states = array.array("q")
    folders = [f for f in sorted(os.listdir(blobs)) if len(f) == 2 and os.path.isdir(os.path.join(blobs, f))]
    for folder in folders[len(folders) * part // parts: len(folders) * (part + 1) // parts]:
        stat_folder(os.path.join(blobs, folder), folder, keys, states, others)
    text = SEPARATOR.join(keys).encode("utf-8", "surrogateescape")  # names as the file system gave them
    rest = SEPARATOR.join(others).encode("utf-8", "surrogateescape")
    digest = hashlib.sha256(states.tobytes())
    digest.update(text)
    out = sys.stdout.buffer
    try:
        out.write(len(keys).to_bytes(8, "little") + len(text).to_bytes(8, "little") + len(rest).to_bytes(8, "little"))
        out.write(digest.digest() + rest)
        out.flush()
        states.tofile(out)  # read only by a parent that looks key by key: one that has the digest may close the pipe
        out.write(text)
        out.flush()
    except BrokenPipeError:
        os._exit(0)


if __name__ == "__main__":
    main(sys.argv[1], *map(int, sys.argv[2:4]))
