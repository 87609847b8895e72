"""The page on matching another tool lists every default of sweep3d's that differs from Blender's
own: checked against Blender's factory settings here (bpy in a child process, as the page tells a
user to print them) and against sweep3d's ``[render]`` defaults, so neither can drift from the page."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from sweep3d.spec.models import RenderSpec
from tests.helpers import REPO

PAGE = REPO / "docs" / "how-to" / "match-another-tool.md"
FACTORY = """
import json, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
c, r = scene.cycles, scene.render
print(json.dumps({"engine": r.engine, "samples": c.samples, "adaptive": c.use_adaptive_sampling,
                  "threshold": round(c.adaptive_threshold, 6), "max_bounces": c.max_bounces,
                  "prefilter": c.denoising_prefilter, "resolution": [r.resolution_x, r.resolution_y],
                  "view": scene.view_settings.view_transform, "seed": c.seed, "dither": r.dither_intensity,
                  "world": bpy.data.worlds.new("w").cycles.sampling_method}))
"""


@pytest.mark.blender
def test_the_page_names_each_default_that_differs_from_blender_s_factory_settings() -> None:
    out = subprocess.run([sys.executable, "-c", FACTORY], capture_output=True, text=True, timeout=300, check=True)
    blender = json.loads(out.stdout.strip().splitlines()[-1])
    ours = RenderSpec()
    page = " ".join(PAGE.read_text().split())
    rows = {  # the page's row: (sweep3d's, Blender's), each read from the source it names
        "samples (`cycles.samples`)": (ours.samples, blender["samples"]),
        "total bounces (`cycles.max_bounces`)": (ours.max_bounces, blender["max_bounces"]),
        "denoiser prefilter (`cycles.denoising_prefilter`)": (ours.denoise_prefilter, blender["prefilter"].lower()),
        "adaptive sampling (`cycles.use_adaptive_sampling`, `adaptive_threshold`)": (
            "off" if not ours.adaptive_threshold else ours.adaptive_threshold,
            f"on, threshold {blender['threshold']:g}" if blender["adaptive"] else "off"),
        "resolution (`render.resolution_x`, `_y`)": (f"{ours.resolution} × {ours.resolution}",
                                                    " × ".join(map(str, blender["resolution"]))),
    }
    for name, (mine, theirs) in rows.items():
        assert mine != theirs, name  # a row for a default that does differ ...
        assert f"| {name} | {mine} | {theirs} |" in page, name  # ... with both values as they are
    assert (blender["engine"], blender["view"]) == ("BLENDER_EEVEE_NEXT", "AgX")  # the page's EEVEE and AgX rows
    # what the page calls Blender's and sweep3d's alike is alike
    assert (ours.seed, ours.dither, ours.world_sampling) == (blender["seed"], blender["dither"], blender["world"].lower())
