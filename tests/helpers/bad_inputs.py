"""The corpus of bad inputs that every command reading them must refuse in one line: specs, the
files a spec names (meshes, maps, included specs, materials) and photographs.

tests/cli/test_bad_input_corpus.py runs each spec case against ``plan``, ``run`` and ``realism
score``, and each photograph against ``realism score``: one ``error:`` line, exit code 2, no
traceback, and the store's files unchanged, byte for byte. Big inputs are made at test time, and
cheaply: a photograph of 16,000² pixels is a 31 kB PNG of one colour, one of 100,000² a header
that claims it. The table of bad meshes, maps and values the loader refuses
(tests/spec/test_bad_input.py) stays beside the specs it edits, and runs against the same three
commands there.

To add a case, add it to the list of its kind: :data:`SPECS`, :data:`ASSETS`, :data:`MATERIALS`
(bad ``.mtl`` files: an OBJ naming them, in :attr:`BadSpec.files`) or :data:`PHOTOS`.
"""

from __future__ import annotations

import hashlib
import io
import os
import struct
import threading
import zlib
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

from tests.helpers import CUBE_OBJ, TINY_SPEC

#: A FIFO's reader waits for a writer for ever: past this many seconds, :func:`fifo_watch` calls that a hang.
FIFO_SECONDS = 1.0


@dataclass(frozen=True)
class BadSpec:
    """A spec (``TINY_SPEC`` with ``edit`` made, or ``text``) and the files beside it."""

    id: str
    expect: tuple[str, ...]  # substrings of the error line
    edit: tuple[str, str] | None = None  # (old, new) in TINY_SPEC
    text: str | None = None  # the whole spec instead
    files: dict[str, bytes] = field(default_factory=dict)  # written beside the spec
    fifos: tuple[str, ...] = ()  # named pipes made beside the spec ("spec.toml": the spec itself)

    def write(self, folder: Path, name: str = "bad.toml") -> Path:
        """The spec and its files in ``folder``; returns the spec's path."""
        spec = folder / name
        for file, data in self.files.items():
            (folder / file).write_bytes(data)
        for fifo in self.fifos:
            os.mkfifo(folder / (name if fifo == "spec.toml" else fifo))
        if "spec.toml" not in self.fifos:
            text = self.text if self.text is not None else TINY_SPEC
            if self.edit is not None:
                assert self.edit[0] in text, self.edit[0]
                text = text.replace(*self.edit, 1)
            spec.write_text(text)
        return spec


def nested(depth: int, opening: str = "[", closing: str = "]", inner: str = "") -> str:
    """``depth`` arrays (or inline tables: ``opening="{a = "``) inside one another."""
    return opening * depth + inner + closing * depth


#: Specs that are bad as text.
SPECS: list[BadSpec] = [
    BadSpec("nested-arrays-5000", ("values nested too deeply to read", "flatten them"),
            text=f"a = {nested(5000)}\n{TINY_SPEC}"),  # 10 kB: tomllib's recursion ends first
    BadSpec("nested-tables-5000", ("values nested too deeply to read",),
            edit=("yaw = [0, 45]", f"yaw = {nested(5000, '{a = ', '}', '1')}")),
    BadSpec("nested-arrays-300-in-a-control", ("controls[0].yaw[0]…: values nested more than 32 levels deep",),
            edit=("yaw = [0, 45]", f"yaw = {nested(300, inner='1')}")),
    BadSpec("spec-is-a-fifo", ("is a FIFO (named pipe), not a spec file",), fifos=("spec.toml",)),
    BadSpec("include-is-a-fifo", ("include: 'shared.toml' is a FIFO (named pipe), not a TOML file",),
            text=f'include = "shared.toml"\n{TINY_SPEC}', fifos=("shared.toml",)),
]

#: Specs whose mistake is in a file they name.
ASSETS: list[BadSpec] = [
    BadSpec("mesh-is-a-fifo", ("objects[0].mesh", "is a FIFO (named pipe), not a file"),
            edit=('mesh = "cube.obj"', 'mesh = "pipe.obj"'), fifos=("pipe.obj",)),
    BadSpec("mesh-is-text", ("objects[0].mesh", "not a text OBJ"), edit=('mesh = "cube.obj"', 'mesh = "text.obj"'),
            files={"text.obj": bytes(range(256)) * 8}),
    BadSpec("hdri-is-a-fifo", ("environments[1].hdri", "is a FIFO (named pipe)"),
            edit=('hdri = "builtin:studio"', 'hdri = "pipe.exr"'), fifos=("pipe.exr",)),
]

def _material(id_: str, mtl: str | None, expect: tuple[str, ...], extra: dict[str, bytes] | None = None) -> BadSpec:
    """The spec's cube as ``m.obj`` naming ``m.mtl`` (absent when ``mtl`` is None) with material ``m``."""
    files = {"m.obj": ("mtllib m.mtl\nusemtl m\n" + CUBE_OBJ).encode(), **(extra or {})}
    if mtl is not None:
        files["m.mtl"] = mtl.encode()
    return BadSpec(id_, expect, edit=('mesh = "cube.obj"', 'mesh = "m.obj"'), files=files)


#: Bad materials (``.mtl`` files an OBJ names, written in ``files``); each runs against every
#: command as the other specs do (tests/assets/test_materials.py has the whole table).
MATERIALS: list[BadSpec] = [
    _material("mtl-missing", None, ("m.mtl",)),
    _material("mtl-kd-huge-negative", "newmtl m\nKd 1e300 1e300 -5\n", ("m.mtl line 2", "too large")),
    _material("mtl-kd-nan", "newmtl m\nKd 1 nan 0\n", ("m.mtl line 2", "not a finite number")),
    _material("mtl-ns-word", "newmtl m\nNs abc\n", ("m.mtl line 2", "'abc' is not a number")),
    _material("mtl-texture-missing", "newmtl m\nmap_Kd wood.png\n", ("wood.png does not exist",)),
    _material("mtl-texture-not-an-image", "newmtl m\nmap_Kd tex.png\n", ("tex.png is not a readable image",),
              {"tex.png": b"not an image\n"}),
]

#: Every spec case: what ``plan``, ``run`` and ``realism score`` are each given.
SPEC_CASES: list[BadSpec] = [*SPECS, *ASSETS, *MATERIALS]


@dataclass(frozen=True)
class BadPhoto:
    """A photograph written in place of a job's (``make(path)``), and what its error line says."""

    id: str
    make: Callable[[Path], None]
    expect: tuple[str, ...]


def png_header(width: int, height: int, pad: int = 1000) -> bytes:
    """A PNG whose header claims ``width`` × ``height`` pixels (bilevel) and whose data is a few
    zero bytes: a decompression bomb's claim, about ``pad`` bytes long."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0))
    return b"\x89PNG\r\n\x1a\n" + header + chunk(b"IDAT", zlib.compress(bytes(pad))) + chunk(b"IEND", b"")


def plain_png(width: int, height: int, mode: str = "RGB") -> bytes:
    """A real PNG of one colour (mode ``"1"``: one bit a pixel, so 16,000² pixels are 31 kB)."""
    from PIL import Image

    out = io.BytesIO()
    Image.new(mode, (width, height)).save(out, format="PNG")
    return out.getvalue()


def _writer(data: Callable[[], bytes]) -> Callable[[Path], None]:
    return lambda path: path.write_bytes(data())


PHOTOS: list[BadPhoto] = [
    BadPhoto("bomb-16000", _writer(lambda: plain_png(16_000, 16_000, "1")),
             ("is too large (256 megapixels): sweep3d reads photographs of at most 89 megapixels", "save it smaller")),
    BadPhoto("bomb-header-100000", _writer(lambda: png_header(100_000, 100_000)),
             ("is too large (10000 megapixels)", "save it smaller")),
    BadPhoto("large-header-10000", _writer(lambda: png_header(10_000, 10_000)),
             ("is too large (10000×10000 pixels, 100 megapixels)",)),
    BadPhoto("fifo", lambda path: os.mkfifo(path), ("is a FIFO (named pipe), not an image",)),
    BadPhoto("one-pixel", _writer(lambda: plain_png(1, 1)),
             ("is 1×1 pixels, smaller than its render (32×32)", "never enlarged", "at least 32×32 pixels")),
]


def checksums(root: Path) -> dict[str, str]:
    """Every file under ``root`` (but the lock, which records its last holder) and its SHA-256."""
    if not root.exists():
        return {}
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file() and p.name != "lock"}


@contextmanager
def fifo_watch(folder: Path, after: float = FIFO_SECONDS) -> Iterator[list[Path]]:
    """The FIFOs under ``folder`` that a reader waited on for more than ``after`` seconds (filled in
    as the block runs): each such reader is given an end of file, so a command that would hang for
    ever ends, and the test fails instead of hanging."""
    fifos = [p for p in folder.rglob("*") if p.is_fifo()]
    waited: list[Path] = []
    done = threading.Event()

    def watch() -> None:
        if done.wait(after):
            return
        while not done.wait(0.1):
            for fifo in fifos:
                try:
                    fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)  # ENXIO: no reader waits on it
                except OSError:
                    continue
                os.close(fd)  # the reader reads an end of file
                waited.append(fifo)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    try:
        yield waited
    finally:
        done.set()
        thread.join()
