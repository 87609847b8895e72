"""Whether an HDRI holds any light: its pixels, decoded without Blender.

A map whose pixels are all zero, or all negative, lights the scene with nothing: every render is
black and its results look valid. The decoders here are small on purpose: Radiance .hdr (flat
and run-length encoded scanlines; its RGBE pixels cannot be negative, so reading stops at the
first lit pixel) and single-part scanline OpenEXR, uncompressed or ZIP/ZIPS-compressed, HALF or
FLOAT colour channels (R, G, B or Y). Other EXR compressions (PIZ, PXR24, B44, DWA) and layouts
are left to Blender; 8-bit images (.png, .jpg) are read with Pillow (``sniff``).

What is legal: a map with lit pixels and some negative ones (filtering rings around the sun)
renders, with a warning; a map with no positive pixel at all is an error, and so is an EXR with a
NaN or infinite value (Cycles renders a NaN region black and an infinite one white, and the
images count as valid) or a value over :data:`MAX_RADIANCE`.
"""

from __future__ import annotations

import math
import re
import struct
import zlib
from dataclasses import dataclass
from typing import Iterable, Iterator, Sequence

import numpy as np

from sweep3d.core import UserError

HDR_RESOLUTION = re.compile(rb"\n\n[-+][YX] (\d+) [-+][XY] (\d+)\n")
#: EXR pixel types read here: HALF and FLOAT (UINT channels hold ids, not light).
EXR_TYPES = {1: np.dtype("<f2"), 2: np.dtype("<f4")}
EXR_SIZES = {0: 4, 1: 2, 2: 4}
EXR_COLOUR = {"R", "G", "B", "Y"}
EXR_DECODED = {0: 1, 2: 1, 3: 16}  # NONE, ZIPS, ZIP -> scanlines per chunk
#: Bytes of pixels read from a big map, in evenly spread chunks (about 0.05 s).
EXR_BUDGET = 4 << 20
#: The largest radiance a map may hold. Captured maps peak at about 1e5 (an unclipped sun; a HALF
#: EXR cannot pass 65504): 1e6 leaves a tenfold margin, while 1e30 (times ``strength`` up to 1e6,
#: squared in Cycles' variance estimates) overflows 32-bit floats and renders white.
MAX_RADIANCE = 1e6


class Undecided(Exception):
    """The decoder met a layout it does not read; Blender decides."""


@dataclass
class Tally:
    """Counts of colour values read so far."""

    values: int = 0
    positive: int = 0
    negative: int = 0
    pixels: int = 0
    nonfinite: int = 0  # pixels with a NaN or infinite channel
    absurd: int = 0  # pixels with a finite channel over MAX_RADIANCE

    def add(self, chunk: np.ndarray) -> None:
        """Count a chunk of (channels, pixels) values."""
        finite = np.isfinite(chunk)
        with np.errstate(invalid="ignore"):
            self.values += chunk.size
            self.positive += int(np.count_nonzero(finite & (chunk > 0)))
            self.negative += int(np.count_nonzero(finite & (chunk < 0)))
            self.pixels += chunk.shape[1]
            self.nonfinite += int(np.count_nonzero(~finite.all(axis=0)))
            self.absurd += int(np.count_nonzero((finite & (chunk > MAX_RADIANCE)).any(axis=0)))

    @property
    def bad(self) -> bool:
        return bool(self.nonfinite or self.absurd)


def check_hdr(data: bytes) -> None:
    """Refuse a Radiance .hdr map whose pixels are all zero (RGBE cannot be negative)."""
    try:
        for line in hdr_scanlines(data):
            if np.any((line[:, 3] != 0) & (line[:, :3].max(axis=1) != 0)):
                return  # one lit pixel is enough
    except Undecided:
        return
    raise UserError("the .hdr map is black (every pixel is 0), so it would light nothing and every render would be "
                    "black; give a map with light in it")


def check_exr(data: bytes, attrs: dict[str, bytes], offsets: Sequence[int]) -> str | None:
    """Refuse an EXR map with no positive colour value; a warning line when some are negative.

    A big map is judged from evenly spread chunks (about ``EXR_BUDGET`` bytes of pixels), and read
    whole only when those hold no light, before it is refused.
    """
    try:
        _, row, _ = _exr_rows(attrs)
        _, ymin, _, ymax = struct.unpack("<iiii", attrs["dataWindow"][:16])
        step = max(1, math.ceil((ymax - ymin + 1) * row / EXR_BUDGET))
        tally = _tally(exr_colour(data, attrs, offsets[::step]))
        if tally.values and (not tally.positive or tally.bad) and step > 1:
            tally = _tally(exr_colour(data, attrs, offsets))  # before refusing: the whole map, and exact counts
    except (Undecided, ValueError, IndexError, struct.error):
        return None  # a layout these few lines do not read: Blender decides
    if tally.values == 0:
        return None
    _refuse_unusable(tally)
    if tally.positive == 0:
        what = (f"{tally.negative:,} of its {tally.values:,} colour values are negative and none is positive"
                if tally.negative else "every pixel is 0")
        raise UserError(f"the EXR map holds no light ({what}), so every render would be black; give a map with "
                        "positive radiance")
    if tally.negative:
        return (f"{tally.negative / tally.values:.2%} of the map's colour values are negative; negative light is "
                "not physical and may render as dark or odd patches: clamp them to 0")
    return None


def _refuse_unusable(tally: Tally) -> None:
    """Refuse a map with NaN, infinite or absurdly bright pixels, saying how many."""
    if tally.nonfinite:
        raise UserError(f"{tally.nonfinite:,} of the EXR map's {tally.pixels:,} pixels are NaN or infinite; Cycles "
                        "would render them black or white and the images would count as valid: fix or re-export the "
                        "map (e.g. replace them with their neighbours' values)")
    if tally.absurd:
        raise UserError(f"{tally.absurd:,} of the EXR map's {tally.pixels:,} pixels are brighter than "
                        f"{MAX_RADIANCE:g} (no captured sky is), which overflows Cycles' 32-bit light sums and renders "
                        "white: fix the map's scale (use the environment's strength to brighten it)")


def _tally(chunks: Iterator[np.ndarray]) -> Tally:
    tally = Tally()
    for chunk in chunks:
        tally.add(chunk)
    return tally


def hdr_scanlines(data: bytes) -> Iterator[np.ndarray]:
    """The RGBE pixels of a Radiance .hdr image, one (width, 4) uint8 scanline at a time."""
    found = HDR_RESOLUTION.search(data, 0, 1 << 16)
    if found is None:
        raise Undecided
    lines, width = int(found.group(1)), int(found.group(2))
    pos = found.end()
    for done in range(lines):
        if not (8 <= width < 32768 and data[pos:pos + 2] == b"\x02\x02"
                and (data[pos + 2] << 8 | data[pos + 3]) == width):
            yield _flat(data, pos, (lines - done) * width)  # not run-length encoded: all the rest at once
            return
        line, pos = _rle_scanline(data, pos + 4, width)
        yield line


def _flat(data: bytes, pos: int, pixels: int) -> np.ndarray:
    if len(data) - pos != 4 * pixels:
        raise Undecided  # old-style run-length encoding, or a truncated file
    return np.frombuffer(data, np.uint8, 4 * pixels, pos).reshape(pixels, 4)


def _rle_scanline(data: bytes, pos: int, width: int) -> tuple[np.ndarray, int]:
    """One new-style run-length encoded scanline: each of R, G, B, E in runs and literals."""
    line = np.empty((width, 4), np.uint8)
    try:
        for channel in range(4):
            x = 0
            while x < width:
                count = data[pos]
                if count > 128:
                    count -= 128
                    line[x:x + count, channel] = data[pos + 1]
                    pos += 2
                else:
                    line[x:x + count, channel] = np.frombuffer(data, np.uint8, count, pos + 1)
                    pos += 1 + count
                if count == 0 or x + count > width:
                    raise Undecided
                x += count
    except (IndexError, ValueError):
        raise Undecided from None
    return line, pos


def exr_colour(data: bytes, attrs: dict[str, bytes], offsets: Iterable[int]) -> Iterator[np.ndarray]:
    """The colour channels' values of a scanline EXR, one (channels, pixels) array per chunk at ``offsets``."""
    lines_per_chunk = EXR_DECODED.get(attrs["compression"][0])
    if lines_per_chunk is None:
        raise Undecided
    width, row, wanted = _exr_rows(attrs)
    ymax = struct.unpack("<iiii", attrs["dataWindow"][:16])[3]
    for offset in offsets:
        y, size = struct.unpack_from("<ii", data, offset)
        lines = min(lines_per_chunk, ymax + 1 - y)
        rows = _exr_block(data[offset + 8:offset + 8 + size], lines * row).reshape(lines, row)
        yield np.stack([rows[:, start:start + width * t.itemsize].copy().view(t).ravel().astype(np.float32)
                        for start, t in wanted])


def _exr_rows(attrs: dict[str, bytes]) -> tuple[int, int, list[tuple[int, np.dtype]]]:
    """(width, bytes per scanline, (byte offset in a scanline, dtype) of each colour channel)."""
    channels = _channels(attrs.get("channels", b""))
    if any(xs != 1 or ys != 1 for _, _, xs, ys in channels):
        raise Undecided  # subsampled channels
    xmin, _, xmax, _ = struct.unpack("<iiii", attrs["dataWindow"][:16])
    width = xmax - xmin + 1
    sizes = [width * EXR_SIZES.get(kind, 4) for _, kind, _, _ in channels]
    starts = np.cumsum([0] + sizes)
    wanted = [(int(start), EXR_TYPES[kind]) for (name, kind, _, _), start in zip(channels, starts)
              if name in EXR_COLOUR and kind in EXR_TYPES]
    if not wanted:
        raise Undecided
    return width, sum(sizes), wanted


def _exr_block(raw: bytes, size: int) -> np.ndarray:
    """A chunk's bytes as stored uncompressed (a ZIP chunk that would not shrink is stored raw)."""
    if len(raw) != size:
        try:
            raw = zlib.decompress(raw)
        except zlib.error:
            raise Undecided from None
        if len(raw) != size:
            raise Undecided
        return _unzip_predictor(np.frombuffer(raw, np.uint8))
    return np.frombuffer(raw, np.uint8)


def _unzip_predictor(packed: np.ndarray) -> np.ndarray:
    """Undo OpenEXR's ZIP preprocessing: a byte delta predictor, then two interleaved halves."""
    deltas = packed ^ 0x80  # each byte stores (value - previous + 128) mod 256
    deltas[0] = packed[0]
    split = np.cumsum(deltas, dtype=np.uint8)
    out = np.empty_like(split)
    half = (len(split) + 1) // 2
    out[0::2], out[1::2] = split[:half], split[half:]
    return out


def _channels(raw: bytes) -> list[tuple[str, int, int, int]]:
    """(name, pixel type, x sampling, y sampling) of each channel in an EXR ``chlist`` attribute."""
    out = []
    pos = 0
    try:
        while raw[pos] != 0:
            end = raw.index(b"\0", pos)
            kind, _, xs, ys = struct.unpack_from("<iB3xii", raw, end + 1)
            out.append((raw[pos:end].decode("latin-1"), kind, xs, ys))
            pos = end + 17
    except (IndexError, ValueError, struct.error):
        raise Undecided from None
    return out
