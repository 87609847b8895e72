"""A tiny spec and a model that fails exactly below a brightness: a planted failure boundary that
the run finds and the follow-ups (confirm, grade) must replicate. Shared by their tests."""

from __future__ import annotations

from pathlib import Path

from tests.helpers import spec_toml, write_spec

FRESH_SPEC = spec_toml("fresh", seed=3, model={"batch_size": 8}, body="""\
[[controls]]
type = "orientation"
yaw = { range = [-180, 180] }
pitch = { range = [-20, 20] }

[policy]
type = "random"
samples = 4
""")

BRIGHT_MODEL = '''\
import torch
from sweep3d.stages.infer.models import Classifier, Normalize


class Bright(torch.nn.Module):
    """Says "carton" for a bright image, "dark" otherwise: fails exactly below a brightness."""

    def forward(self, x):
        m = x.mean(dim=(1, 2, 3))
        return torch.stack([(m - 0.45) * 50, (0.45 - m) * 50], dim=1)


def make():
    return Classifier(Bright(), Normalize(), labels=["carton", "dark"])
'''


def bright_spec(folder: Path) -> Path:
    """The fresh spec with ``brightmodel:make`` beside it and a brightness control, 30 random jobs."""
    (folder / "brightmodel.py").write_text(BRIGHT_MODEL)
    text = (FRESH_SPEC.replace("[model]\nbatch_size = 8", '[model]\nname = "brightmodel:make"')
            .replace("pitch = { range = [-20, 20] }", "\n[[controls]]\ntype = \"brightness_contrast\"\n"
                     "brightness = { range = [-0.8, 0.2] }").replace("samples = 4", "samples = 30"))
    return write_spec(folder, text)
