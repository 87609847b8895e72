"""A third engine in one folder, as a new renderer would be added: its :class:`Backend`, with
what it cannot render declared once per control type. Its scene draws nothing: the tests that
register it only plan (tests/stages/render/test_backends.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sweep3d.core import encode_png
from sweep3d.stages.render import Backend, SceneState
from sweep3d.stages.render.backend import refuse_when


class FlatScene:
    """A worker's scene of the fake engine: a flat grey image of the settings' size."""

    def __init__(self, resolution: int) -> None:
        self.resolution = resolution
        self.load_seconds, self.parts, self.truth_pass = 0.0, None, None
        self.state = SceneState()

    def prepare(self, mesh_path: str, environment, look=None) -> None:
        self.load_seconds = 0.0

    def pose_scene(self, state: SceneState) -> None:
        self.state = state

    def render(self) -> np.ndarray:
        return np.full((self.resolution, self.resolution, 3), 0.5, dtype=np.float32)

    def render_png(self) -> bytes:
        return encode_png(self.render())

    def rebuild_if_stale(self) -> None:
        return None


class FakeBackend(Backend):
    """Renders on the CPU, with the mask pass only, and cannot turn its world."""

    name = "fake"
    title = "Fake"
    passes = frozenset({"mask"})
    seconds_224 = (0.01, 0.01)
    support = {"hdri": refuse_when("rotation", lambda v: v != 0, "its world cannot turn")}

    def scene(self, settings, scratch: Path, log=None, gpu=None) -> FlatScene:
        return FlatScene(settings.resolution)

    def key(self) -> dict:
        return {"name": self.name, "version": "1"}
