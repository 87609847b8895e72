"""The README's examples work as written."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from sweep3d.stages import load_spec
from sweep3d.stages.postprocess import apply_post
from tests.conftest import REPO, TINY_SPEC, plan_for, write_spec


def readme_block(after: str) -> str:
    text = (REPO / "README.md").read_text()
    start = text.index(after)
    return re.search(r"```python\n(.*?)```", text[start:], re.S).group(1)


def test_ci_runs_the_readmes_test_command() -> None:
    command = (REPO / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert f"\n    {command}\n" in (REPO / "README.md").read_text()


def test_custom_control_from_the_readme(tmp_path: Path, monkeypatch) -> None:
    code = readme_block("### Your own control")
    assert len(code.strip().splitlines()) < 30
    (tmp_path / "mycontrols.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    spec = write_spec(tmp_path, TINY_SPEC.replace(
        "[policy]", '[[controls]]\ntype = "mycontrols:Vignette"\nstrength = [0, 0.5, 1]\n\n[policy]'))
    loaded = load_spec(spec)
    plan = plan_for(loaded, "m")
    assert len(plan.jobs) == 24
    # strength 0 is neutral: those jobs share their keys with a spec that lacks the control
    (tmp_path / "plain").mkdir()
    plain = plan_for(load_spec(write_spec(tmp_path / "plain", TINY_SPEC)), "m")
    neutral = {j.image_key for j in plan.jobs if j.values["Vignette"]["strength"] == 0}
    assert neutral == {j.image_key for j in plain.jobs}
    control = next(c for c in loaded.controls if c.id == "Vignette")
    image = np.ones((16, 16, 3), np.float32)
    out = apply_post(image, [control], {"Vignette": {"strength": 1.0}}, "ab" * 10)
    assert out[0, 0].max() < 0.05 and out[8, 8].min() > 0.9
