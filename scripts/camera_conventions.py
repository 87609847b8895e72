"""Render the camera control's angle conventions into docs/images/camera_conventions.png.

An asymmetric object written as a Y-up OBJ (a grey body, a red nose on the file's +Z: its
front; a blue fin on +X; a green knob on +Y: up) is rendered at azimuth 0, 90, 180, -90 and
elevation -30, 0, 30, beside a top view of where those cameras stand. The picture is what the
renderer does, not what a docstring says:

    PYTHONPATH=. .venv/bin/python scripts/camera_conventions.py [--out docs/images/camera_conventions.png]
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

#: (name, low corner, high corner, RGB) of each box, in the OBJ file's own (Y-up) coordinates.
PARTS = [
    ("body", (-1.0, -1.0, -1.0), (1.0, 1.0, 1.0), (0.6, 0.6, 0.6)),
    ("nose", (-0.3, -0.3, 1.0), (0.3, 0.3, 2.2), (0.85, 0.1, 0.08)),  # +Z: the file's front
    ("fin", (1.0, -0.6, -0.15), (1.9, 0.6, 0.15), (0.1, 0.25, 0.9)),  # +X
    ("knob", (-0.35, 1.0, -0.35), (0.35, 1.6, 0.35), (0.1, 0.7, 0.15)),  # +Y: up
]
AZIMUTHS = (0.0, 90.0, 180.0, -90.0)
ELEVATIONS = (30.0, 0.0, -30.0)
TILE = 128
FONT = ImageFont.load_default(size=13)


def write_object(folder: Path) -> Path:
    """The asymmetric object as an OBJ with a material per part (colours from ``PARTS``)."""
    lines, mtl = ["mtllib parts.mtl"], []
    for i, (name, lo, hi, rgb) in enumerate(PARTS):
        corners = [(x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        lines += [f"v {x} {y} {z}" for x, y, z in corners]
        lines += [f"usemtl {name}"]
        base = 8 * i + 1
        for face in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)):
            lines.append("f " + " ".join(str(base + k) for k in face))
        mtl += [f"newmtl {name}", "Kd {} {} {}".format(*rgb), ""]
    (folder / "parts.mtl").write_text("\n".join(mtl))
    path = folder / "conventions.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def render_tiles(mesh: Path, scratch: Path) -> dict[tuple[float, float], Image.Image]:
    """Each (azimuth, elevation)'s render on a light grey plain background with its key light."""
    from sweep3d.spec.models import KeyLightSpec
    from sweep3d.stages.render.cycles.scene import BlenderScene
    from sweep3d.stages.render.state import SceneState
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderSettings

    scene = BlenderScene(RenderSettings(resolution=TILE, samples=16, denoise=False), scratch)
    env = EnvironmentRef(color=(0.92, 0.92, 0.92), key_light=KeyLightSpec())
    scene.prepare(str(mesh), env)
    tiles = {}
    for el in ELEVATIONS:
        for az in AZIMUTHS:
            scene.pose_scene(SceneState(azimuth=az, elevation=el, zoom=1.05))
            pixels = np.clip(scene.render() * 255.0 + 0.5, 0, 255).astype(np.uint8)
            tiles[az, el] = Image.fromarray(pixels)
    return tiles


def top_view(size: int) -> Image.Image:
    """Where the cameras stand, seen from above (+X right, +Y up the page), and which way azimuth grows."""
    img = Image.new("RGB", (size, size), "white")
    d = ImageDraw.Draw(img)
    c, r = size / 2, size * 0.3
    d.rectangle((c - 22, c - 22, c + 22, c + 22), fill=(150, 150, 150))  # the body
    d.rectangle((c - 6, c + 22, c + 6, c + 48), fill=(215, 25, 20))  # the nose: -Y in Blender (the front)
    d.rectangle((c + 22, c - 4, c + 42, c + 4), fill=(25, 65, 230))  # the fin: +X
    d.text((6, 6), "top view: +X right, +Y up the page", fill="black", font=FONT)
    d.arc((c - r, c - r, c + r, c + r), 0, 360, fill=(120, 120, 120))
    for az in AZIMUTHS:
        a = math.radians(az)
        x, y = c + r * math.sin(a), c + r * math.cos(a)  # world (sin az, -cos az), page y down
        d.ellipse((x - 7, y - 7, x + 7, y + 7), fill="black")
        dx, dy = (x - c) / r, (y - c) / r
        d.text((x + 34 * dx, y + 18 * dy), f"az {az:g}", fill="black", font=FONT, anchor="mm")
    a0, a1 = math.radians(20), math.radians(70)  # positive azimuth: counter-clockwise from above
    pts = [(c + (r + 18) * math.sin(a), c + (r + 18) * math.cos(a)) for a in np.linspace(a0, a1, 12)]
    d.line(pts, fill=(200, 0, 0), width=2)
    (xe, ye), (xp, yp) = pts[-1], pts[-2]
    ux, uy = (xe - xp) / math.hypot(xe - xp, ye - yp), (ye - yp) / math.hypot(xe - xp, ye - yp)
    d.polygon([(xe + 6 * ux, ye + 6 * uy), (xe - 6 * ux - 5 * uy, ye - 6 * uy + 5 * ux),
               (xe - 6 * ux + 5 * uy, ye - 6 * uy - 5 * ux)], fill=(200, 0, 0))
    d.text((c + r * 0.72, c + r * 0.98), "+azimuth", fill=(200, 0, 0), font=FONT)
    d.text((6, size - 48), "red nose: the file's +Z (Y-up OBJ/glTF)", fill="black", font=FONT)
    d.text((6, size - 32), "blue fin: +X   green knob: up", fill="black", font=FONT)
    d.text((6, size - 16), "elevation > 0: camera above", fill="black", font=FONT)
    return img


def sheet(tiles: dict[tuple[float, float], Image.Image]) -> Image.Image:
    """The tiles in a grid (rows: elevation, columns: azimuth) with the top view on the left."""
    label, gutter = 18, 64
    side = TILE * len(ELEVATIONS) + label
    out = Image.new("RGB", (side + gutter + TILE * len(AZIMUTHS), side), "white")
    out.paste(top_view(side), (0, 0))
    d = ImageDraw.Draw(out)
    left = side + gutter
    for j, az in enumerate(AZIMUTHS):
        d.text((left + j * TILE + 4, 3), f"azimuth {az:g}", fill="black", font=FONT)
    for i, el in enumerate(ELEVATIONS):
        d.text((side + 1, label + i * TILE + TILE // 2 - 6), f"elev. {el:+g}", fill="black", font=FONT)
        for j, az in enumerate(AZIMUTHS):
            out.paste(tiles[az, el], (left + j * TILE, label + i * TILE))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/images/camera_conventions.png"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        tiles = render_tiles(write_object(folder), folder)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    sheet(tiles).save(args.out, optimize=True)
    print(args.out)


if __name__ == "__main__":
    main()
