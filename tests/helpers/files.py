"""Small asset files written byte by byte, so tests need no image or mesh library: OpenEXR and
Radiance .hdr maps, binary PLY and STL meshes, and a GLB."""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np

EXR_MAGIC = b"\x76\x2f\x31\x01"


def exr(pixels: np.ndarray, zip_compressed: bool = False) -> bytes:
    """A single-part scanline OpenEXR with FLOAT B, G, R channels, uncompressed or ZIP (16 lines a chunk)."""
    height, width, _ = pixels.shape
    channels = b"".join(c + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for c in (b"B", b"G", b"R")) + b"\0"
    window = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    header = EXR_MAGIC + struct.pack("<I", 2) + b"".join([
        _attr("channels", "chlist", channels), _attr("compression", "compression", bytes([3 if zip_compressed else 0])),
        _attr("dataWindow", "box2i", window), _attr("displayWindow", "box2i", window),
        _attr("lineOrder", "lineOrder", b"\0"), _attr("pixelAspectRatio", "float", struct.pack("<f", 1)),
        _attr("screenWindowCenter", "v2f", struct.pack("<ff", 0, 0)),
        _attr("screenWindowWidth", "float", struct.pack("<f", 1))]) + b"\0"
    lines = 16 if zip_compressed else 1
    chunks = []
    for y in range(0, height, lines):
        rows = pixels[y:y + lines].astype("<f4")
        raw = b"".join(rows[r, :, c].tobytes() for r in range(len(rows)) for c in (2, 1, 0))
        data = zlib.compress(_exr_zip_predictor(raw)) if zip_compressed else raw
        chunks.append(struct.pack("<ii", y, len(data)) + data)
    offset = len(header) + 8 * len(chunks)
    table = b""
    for chunk in chunks:
        table += struct.pack("<Q", offset)
        offset += len(chunk)
    return header + table + b"".join(chunks)


def _attr(name: str, kind: str, value: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def _exr_zip_predictor(raw: bytes) -> bytes:
    """OpenEXR's preprocessing before zlib: bytes split into two interleaved halves, then deltas + 128."""
    data = np.frombuffer(raw, np.uint8)
    split = np.concatenate([data[0::2], data[1::2]])
    deltas = (np.diff(split.astype(np.int16)) + 128) & 0xFF
    return bytes(np.concatenate([split[:1], deltas.astype(np.uint8)]))


def hdr(pixels: np.ndarray) -> bytes:
    """A Radiance .hdr image, each scanline run-length encoded (a constant channel as runs, others literally)."""
    height, width, _ = pixels.shape
    out = [b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n", f"-Y {height} +X {width}\n".encode()]
    for row in _rgbe(pixels):
        out.append(b"\x02\x02" + struct.pack(">H", width))
        for channel in row.T:
            out.append(_runs(channel) if (channel == channel[0]).all() else _literals(channel))
    return b"".join(out)


def _rgbe(pixels: np.ndarray) -> np.ndarray:
    brightest = pixels.max(axis=2)
    mantissa, exponent = np.frexp(brightest)
    scale = np.where(brightest > 1e-32, mantissa * 256.0 / np.maximum(brightest, 1e-32), 0)
    rgb = (pixels * scale[..., None]).astype(np.uint8)
    e = np.where(brightest > 1e-32, exponent + 128, 0).astype(np.uint8)
    return np.concatenate([rgb, e[..., None]], axis=2)


def _runs(channel: np.ndarray) -> bytes:
    out, left = b"", len(channel)
    while left:
        n = min(left, 127)
        out += bytes([128 + n, int(channel[0])])
        left -= n
    return out


def _literals(channel: np.ndarray) -> bytes:
    return b"".join(bytes([len(part)]) + part.tobytes() for part in np.array_split(channel, -(-len(channel) // 128)))


def ply_binary(vertices: list[tuple[float, float, float]]) -> bytes:
    """A little-endian binary PLY: the vertices and one triangle."""
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\nproperty float x\n"
              "property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n"
              "end_header\n")
    return header.encode() + np.array(vertices, "<f4").tobytes() + b"\x03" + np.array([0, 1, 2], "<i4").tobytes()


def stl_binary(triangles: list[list[tuple[float, float, float]]]) -> bytes:
    """A binary STL: an 80-byte header, the count, and 50 bytes a triangle."""
    body = b"".join(struct.pack("<3f", 0, 0, 1) + np.array(t, "<f4").tobytes() + b"\0\0" for t in triangles)
    return b"\0" * 80 + struct.pack("<I", len(triangles)) + body


def glb(vertices: list[tuple[float, float, float]]) -> bytes:
    """A binary glTF with one mesh whose POSITION accessor holds ``vertices``."""
    data = np.array(vertices, "<f4").tobytes()
    doc = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": len(data)}],
           "bufferViews": [{"buffer": 0, "byteLength": len(data)}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(vertices), "type": "VEC3"}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}]}
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(data), 0x004E4942) + data
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body
