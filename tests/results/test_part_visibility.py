"""Part visibility end to end: the UV pass, the parts table and view, and the report panel.

Real Blender renders of a cube at 48×48 turned to four yaws, in two environments; the real classifier.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.core.pixels import decode_png
from sweep3d.core.uv_cells import AZIMUTH_PARTS, PARTS, part_of, sphere_turns
from sweep3d.report import write_report
from sweep3d.results import connect
from sweep3d.results import connect as connect_results
from sweep3d.results.part_views import VISIBLE_SHARE
from tests.helpers import (
    ARTIFACTS,
    TINY_SPEC,
    assert_clean,
    direction,
    load_spec,
    open_page,
    screenshot_panels,
    write_spec,
)

YAWS = (0, 90, 180, 270)
PARTS_SPEC = (TINY_SPEC.replace("resolution = 32", "resolution = 48").replace("yaw = [0, 45]", f"yaw = {list(YAWS)}")
              + "\n[report]\npart_visibility = true\n")


def run_cli(spec: Path) -> None:
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output


@pytest.fixture(scope="module")
def parts_run(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("parts_run")
    run_cli(write_spec(folder, PARTS_SPEC))
    return folder


def query(folder: Path, sql: str) -> list[tuple]:
    return connect(Store(folder / "store"), "tiny").execute(sql).fetchall()


def part_at(azimuth: float, elevation: float) -> int:
    turns, band = sphere_turns(direction(azimuth, elevation))
    return int(part_of(turns / 2, band)[0])


def test_each_render_records_the_parts_facing_the_camera(parts_run: Path) -> None:
    rows = query(parts_run, "SELECT DISTINCT j.orientation_yaw, p.parts, p.pixels, p.object_pixels "
                            "FROM jobs j JOIN parts p USING (parts_key) WHERE environment = 'white' ORDER BY 1")
    assert [r[0] for r in rows] == list(YAWS)
    for yaw, parts, pixels, object_pixels in rows:
        assert object_pixels > 100 and sum(pixels) == object_pixels and all(0 <= p < PARTS for p in parts)
        visible = {p for p, n in zip(parts, pixels) if n >= VISIBLE_SHARE * object_pixels}
        # turning the object by +yaw brings its side at azimuth -yaw in front of the camera
        assert part_at(5 - yaw, 10) in visible, yaw
        assert part_at(185 - yaw, 10) not in visible, yaw  # its back is hidden
    # the four yaws show four different sets of parts, a quarter turn apart
    slices = [{p % AZIMUTH_PARTS for p in parts} for _, parts, _, _ in rows]
    assert all(a != b for i, a in enumerate(slices) for b in slices[i + 1:])


def test_the_view_agrees_with_a_count_by_hand(parts_run: Path) -> None:
    raw = query(parts_run, "SELECT r.correct, p.parts, p.pixels, p.object_pixels FROM results r "
                           "JOIN parts p USING (parts_key) WHERE r.valid")
    expected: dict[int, list[int]] = {}
    for correct, parts, pixels, total in raw:
        for part, n in zip(parts, pixels):
            if n >= max(1, VISIBLE_SHARE * total):
                expected.setdefault(part, []).append(int(correct))
    view = query(parts_run, "SELECT part, n, n_correct, accuracy, object_n, object_accuracy, lift, "
                            "azimuth_from, elevation_to FROM part_visibility WHERE object = 'box'")
    assert {r[0]: (r[1], r[2]) for r in view} == {p: (len(v), sum(v)) for p, v in expected.items()}
    overall = np.mean([int(r[0]) for r in raw])
    for _part, n, n_correct, accuracy, object_n, object_accuracy, lift, *_ in view:
        assert object_n == len(raw) and object_accuracy == pytest.approx(overall)
        assert accuracy == pytest.approx(n_correct / n) and lift == pytest.approx(accuracy - overall)


def test_a_rerun_renders_nothing(parts_run: Path) -> None:
    result = CliRunner().invoke(app, ["plan", str(parts_run / "spec.toml")])
    assert result.exit_code == 0
    assert run_stage_counts(parts_run) == {"render": 0, "infer": 0}


def run_stage_counts(folder: Path) -> dict[str, int]:
    from sweep3d.runner.pipeline import run

    outcome = run(load_spec(folder / "spec.toml"))
    return {s: outcome.outcome(s).computed for s in ("render", "infer")}


def test_switching_the_panel_on_renders_the_pass_only(parts_run: Path, tmp_path: Path) -> None:
    spec = write_spec(tmp_path, PARTS_SPEC.replace("part_visibility = true", "part_visibility = false"))
    run_cli(spec)
    store = Store(tmp_path / "store")
    before = dict(connect_results(store, "tiny").execute("SELECT render_key, sha256 FROM renders").fetchall())
    assert not store.keys("parts")
    spec.write_text(PARTS_SPEC)
    assert run_stage_counts(tmp_path) == {"render": 8, "infer": 0}  # rendered for the pass; nothing re-inferred
    con = connect_results(store, "tiny")
    assert dict(con.execute("SELECT render_key, sha256 FROM renders").fetchall()) == before  # blobs kept
    assert con.execute("SELECT count(*) FROM parts").fetchone()[0] == 8
    # the pass leaves the RGB image alone: the same render keys, the same pixels as the run with it
    other = Store(parts_run / "store")
    for key in before:
        a, b = decode_png(store.blob_path(key)), decode_png(other.blob_path(key))
        assert np.abs(a - b).max() <= 1.5 / 255


@pytest.mark.blender
def test_painted_object_takes_the_colour_of_each_side(tmp_path: Path) -> None:
    from sweep3d.stages.render.cycles.paint import SIDES, paint_objects
    from tests.helpers import write_cube

    colours = np.tile([[0.9, 0.1, 0.1]], (PARTS, 1))  # red all round ...
    for part in range(PARTS):
        if part % AZIMUTH_PARTS in (AZIMUTH_PARTS // 2 - 1, AZIMUTH_PARTS // 2):  # ... green in front
            colours[part] = [0.1, 0.8, 0.1]
    (images,) = paint_objects([(str(write_cube(tmp_path)), colours)], resolution=48, samples=4)
    assert len(images) == len(SIDES)
    by_view = {label: decode_png_bytes(png) for (label, _, _), png in zip(SIDES, images)}
    centre = {label: img[24, 24] for label, img in by_view.items()}
    assert centre["front"][1] > centre["front"][0] + 0.2  # green
    for side in ("back", "left", "right"):
        assert centre[side][0] > centre[side][1] + 0.2, side  # red
    assert np.allclose(by_view["front"][0, 0], 1.0, atol=0.02)  # the plain white background


@pytest.mark.blender
def test_one_worker_switching_objects_sees_each_objects_own_parts(tmp_path: Path) -> None:
    """A worker keeps both objects loaded: the UV pass of each is its own, also after a switch."""
    from sweep3d.stages.render.pool import RenderPool
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob, RenderSettings
    from tests.helpers import write_cube

    cube = str(write_cube(tmp_path))
    slab = tmp_path / "slab.obj"  # a flat box: far fewer of the cube's parts face the camera
    slab.write_text("".join(f"v {x} {y} {z}\n" for x in (-1, 1) for y in (-1, 1) for z in (-0.1, 0.1))
                    + "f 1 2 4 3\nf 5 7 8 6\nf 1 5 6 2\nf 3 4 8 7\nf 1 3 7 5\nf 2 6 8 4\n")
    white = EnvironmentRef(color=(1.0, 1.0, 1.0))
    jobs = [RenderJob(key, mesh, white) for key, mesh in (("a", cube), ("b", str(slab)), ("c", cube))]
    settings = RenderSettings(resolution=48, samples=1, denoise=False, passes=("uv",))
    with RenderPool(settings, workers=1) as pool:
        parts = {reply.render_key: reply.info.parts for reply in pool.run([jobs])}
    assert parts["a"] == parts["c"] and parts["a"]["object_pixels"] > 100
    assert parts["b"] != parts["a"]


def decode_png_bytes(png: bytes) -> np.ndarray:
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float32) / 255.0


def test_report_panel_only_when_asked_for(parts_run: Path, tiny_run: Path) -> None:
    html = write_report(load_spec(parts_run / "spec.toml")).read_text()
    assert '<section id="part-visibility"' in html
    assert html.count('alt="box, ') == 6 and "FROM part_visibility WHERE object = &#39;box&#39;" in html
    assert 'id="part-visibility"' not in write_report(load_spec(tiny_run / "spec.toml")).read_text()
    painted = list((parts_run / "store" / "cache" / "paint").glob("*/*.png"))
    assert len(painted) == 6
    stamps = {p: p.stat().st_mtime_ns for p in painted}
    write_report(load_spec(parts_run / "spec.toml"))  # painted once, then read from the store
    assert {p: p.stat().st_mtime_ns for p in painted} == stamps


@pytest.mark.browser
def test_part_visibility_panel_draws_in_chromium(parts_run: Path, tmp_path: Path, chromium) -> None:
    folder = tmp_path / "copy"
    shutil.copytree(parts_run, folder)
    spec = folder / "spec.toml"
    spec.write_text(spec.read_text().replace('name = "box"', 'name = "<b>box</b>"'))  # names stay text
    run_cli(spec)
    path = write_report(load_spec(spec))
    with open_page(chromium, path) as (page, events):
        panel = page.locator("#part-visibility")
        assert panel.locator("h3").first.inner_text().startswith("<b>box</b>")
        widths = panel.evaluate("p => Array.from(p.querySelectorAll('.part-sides img')).map(i => i.naturalWidth)")
        assert widths == [160] * 6
        traces = page.evaluate("document.getElementById('fig-parts-0').data.map(t => t.type)")
        assert traces == ["heatmap", "heatmap"] and panel.locator("svg.main-svg").count() >= 1
        screenshot_panels(page, "parts")
        panel.screenshot(path=str(ARTIFACTS / "parts-part-visibility.png"))
        assert_clean(path, events)

