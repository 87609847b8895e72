"""Whether a material's texture file is an image, and which format it holds.

Blender loads a texture that is not an image (a text file named ``wood.png``, a truncated PNG)
as a magenta "missing" image without an error; Mitsuba fails every job on it. Pillow identifies
the format from the file's bytes and checks its structure (a PNG's chunks and their checksums)
without decoding the pixels; OpenEXR and Radiance ``.hdr``, which Pillow does not read, are
judged by their magic numbers.
"""

from __future__ import annotations

import io
import warnings
from functools import lru_cache
from pathlib import Path

#: The magic number each HDR format starts with (Pillow reads neither).
HDR_MAGIC = {"EXR": (b"\x76\x2f\x31\x01",), "HDR": (b"#?RADIANCE", b"#?RGBE")}
#: Formats (Pillow's names, and EXR/HDR) Mitsuba's bitmap reader takes; it refuses TIFF, WebP and GIF.
MITSUBA_FORMATS = frozenset({"PNG", "JPEG", "BMP", "TGA", "PPM", "PFM", "EXR", "HDR"})


class NotAnImage(ValueError):
    """The bytes are not an image any reader takes; the message says what the reader found."""


def image_format(data: bytes) -> str:
    """The format of an image file's bytes (``"PNG"``, ``"JPEG"``, ``"EXR"``, ...).

    Raises:
        NotAnImage: the bytes are empty, of no image format, or damaged.
    """
    if not data:
        raise NotAnImage("the file is empty")
    for name, magics in HDR_MAGIC.items():
        if data.startswith(magics):
            return name
    from PIL import Image, UnidentifiedImageError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a large texture is not an error here
            with Image.open(io.BytesIO(data)) as img:
                name = img.format or "?"
                img.verify()
    except UnidentifiedImageError:  # its message names the BytesIO object, not the file
        raise NotAnImage("no image format recognised in its bytes") from None
    except Exception as exc:  # noqa: BLE001  (any decoder complaint means it is not a readable image)
        raise NotAnImage(" ".join(str(exc).split()) or type(exc).__name__) from None
    return name


def file_format(path: Path) -> str:
    """:func:`image_format` of a regular file, remembered while the file's size and time stay the same."""
    info = path.stat()
    return _file_format(str(path), info.st_size, info.st_mtime_ns)


@lru_cache(maxsize=256)
def _file_format(path: str, size: int, mtime_ns: int) -> str:
    return image_format(Path(path).read_bytes())
