"""``[postprocess] store``: a run that keeps no post-processed image gives the same results, keys
and findings as one that stores every image, and what looks at the images (the report, export)
gets them, made again from their renders, byte for byte what the storing run wrote."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from tests.helpers import TINY_SPEC, write_spec

pytestmark = [pytest.mark.blender, pytest.mark.torch, pytest.mark.slow]

#: Results columns that say when or how long, not what.
TIMING = ("seconds", "created_at", "run_id")


def _run(folder: Path, store: str) -> Path:
    spec = write_spec(folder, TINY_SPEC + f'\n[postprocess]\nstore = "{store}"\n')
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    return spec


def _results(spec: Path) -> list[dict]:
    import sweep3d

    table = sweep3d.load(spec).sql("SELECT * FROM results ORDER BY job")
    return [{k: v for k, v in row.items() if not any(t in k for t in TIMING)} for row in table.to_pylist()]


def _post_keys(spec: Path) -> list[str]:
    import sweep3d

    table = sweep3d.load(spec).sql("SELECT DISTINCT image_key FROM results WHERE image_key <> render_key ORDER BY 1")
    return table.column(0).to_pylist()


@pytest.fixture(scope="module")
def both(tmp_path_factory) -> tuple[Path, Path]:
    """(a run storing every image, the same spec storing none), each in its own store."""
    return _run(tmp_path_factory.mktemp("all"), "all"), _run(tmp_path_factory.mktemp("none"), "none")


def test_results_keys_and_findings_are_the_same_without_stored_images(both: tuple[Path, Path]) -> None:
    stored, unstored = both
    assert _results(stored) == _results(unstored)
    post = _post_keys(unstored)
    assert post and post == _post_keys(stored)
    kept = Store(unstored.parent / "store")
    assert not any(kept.blob_path(k).exists() for k in post)  # made in memory only
    assert all(Store(stored.parent / "store").blob_path(k).exists() for k in post)
    findings = [CliRunner().invoke(app, ["query", str(s), "SELECT count(*) AS n, sum(correct::INT) AS c FROM results"])
                for s in both]
    assert findings[0].exit_code == findings[1].exit_code == 0
    assert findings[0].output == findings[1].output


def test_inference_without_the_images_makes_them_again_from_the_renders(both: tuple[Path, Path],
                                                                        tmp_path: Path) -> None:
    """Predictions lost (or a new model): the images are not in memory nor stored, so inference
    makes them again from their renders, and answers as the storing run did; nothing else runs."""
    import sweep3d

    stored, unstored = both
    copy = tmp_path / "copy"
    shutil.copytree(unstored.parent, copy)
    shutil.rmtree(copy / "store" / "tables" / "predictions")
    run = sweep3d.load(copy / "spec.toml").run(progress=False)
    assert (run.outcome("render").computed, run.outcome("postprocess").computed) == (0, 0)
    assert run.outcome("infer").computed == len(_results(stored))
    assert _results(copy / "spec.toml") == _results(stored)
    again = sweep3d.load(copy / "spec.toml").run(progress=False)
    assert [o.computed for o in again.outcomes] == [0, 0, 0]


def test_report_and_export_make_the_images_again_as_the_storing_run_wrote_them(both: tuple[Path, Path],
                                                                               tmp_path: Path) -> None:
    stored, unstored = both
    result = CliRunner().invoke(app, ["report", str(unstored)])
    assert result.exit_code == 0, result.output
    kept, made = Store(stored.parent / "store"), Store(unstored.parent / "store")
    shown = [k for k in _post_keys(unstored) if made.blob_path(k).exists()]
    assert shown, "the report made none of the images it shows"
    for key in shown:
        assert made.blob_path(key).read_bytes() == kept.blob_path(key).read_bytes()
    out = tmp_path / "export"
    result = CliRunner().invoke(app, ["export", str(unstored), "--format", "imagefolder", "--where", "true",
                                      "-o", str(out)])
    assert result.exit_code == 0, result.output
    from PIL import Image

    exported = sorted(out.rglob("*.png"))
    assert len(exported) == len(_results(unstored))
    for key in _post_keys(unstored):
        assert made.blob_path(key).read_bytes() == kept.blob_path(key).read_bytes()
    pixels = [np.asarray(Image.open(p)) for p in exported]
    assert all(p.shape == (32, 32, 3) for p in pixels)
