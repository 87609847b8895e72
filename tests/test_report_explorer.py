"""The explorer in headless Chromium: axes, sliders and a clicked cell's gallery.

The first test drives the page of the real tiny run (Blender + the real model); the second a
synthetic store (rows written directly, with right and wrong predictions and a binned
parameter) and checks the heat map computed in JavaScript against the SQL views.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from benchmarks.report_scale import build_store
from sweep3d.cache.store import Store
from sweep3d.report import write_report
from sweep3d.stages import load_spec
from sweep3d.stages.aggregate import connect
from tests.test_report import ARTIFACTS, assert_clean, cell_centre, open_page

pytestmark = pytest.mark.browser


def heatmap(page: Any) -> dict[str, Any]:
    """The explorer heat map as drawn: tick labels, cell texts and accuracies."""
    return page.evaluate(
        """() => { const gd = document.getElementById('explorer-plot'), t = gd.data[0];
                   return {x: gd.layout.xaxis.ticktext, y: gd.layout.yaxis.ticktext, text: t.text, z: t.z}; }""")


def gallery(page: Any) -> list[dict[str, str]]:
    return page.evaluate(
        """() => Array.from(document.querySelectorAll('#explorer-gallery .tile')).map(t => ({
                 outcome: ['wrong', 'correct', 'invalid'].find(c => t.classList.contains(c)),
                 caption: t.querySelector('figcaption').textContent, title: t.title,
                 src: (t.querySelector('img') || {}).src || '',
                 border: getComputedStyle(t.querySelector('img, .missing')).borderTopColor}))""")


def click_cell(page: Any, x: int, y: int) -> None:
    before = page.inner_text("#explorer-gallery")
    page.mouse.click(*cell_centre(page, x, y))
    page.wait_for_function("(before) => document.getElementById('explorer-gallery').innerText !== before", arg=before)


def test_axis_slider_and_cell_click_change_the_plot_and_the_gallery(tiny_run: Path) -> None:
    loaded = load_spec(tiny_run / "spec.toml")
    path = write_report(loaded)
    con = connect(Store(loaded.store), loaded.name)
    with open_page(path, wait_all=False) as (page, events):
        first = heatmap(page)
        assert first["x"] == ["studio", "white"] and first["y"] == ["box"]
        assert first["text"] == [["0%<br>n=4", "0%<br>n=4"]]
        assert "Click a cell" in page.inner_text("#explorer-gallery")

        page.select_option("select[aria-label='role of orientation_yaw']", "x")  # an axis
        turned = heatmap(page)
        assert turned["x"] == ["0", "45"] and turned != first
        assert page.eval_on_selector("select[aria-label='role of environment']", "s => s.value") == "pooled"

        page.select_option("select[aria-label='role of blur_sigma']", "slider")  # a slider at its first value
        sliced = heatmap(page)
        assert sliced["text"] == [["0%<br>n=2", "0%<br>n=2"]]
        assert page.inner_text("#explorer-status").startswith("4 valid results")
        assert page.inner_text(".explorer-control.slider output") == "0"

        click_cell(page, 1, 0)  # yaw 45, blur 0: two images (one per environment)
        tiles = gallery(page)
        expected = con.execute(
            "SELECT top1_label FROM results WHERE orientation_yaw = 45 AND blur_sigma = 0").fetchall()
        assert sorted(t["caption"] for t in tiles) == sorted(r[0] for r in expected)
        assert all(t["outcome"] == "wrong" and t["border"] == "rgb(214, 69, 69)" for t in tiles)
        assert all(t["src"].startswith("data:image/") for t in tiles)
        assert "orientation_yaw = 45" in page.inner_text("#explorer-gallery h3")
        assert page.evaluate("document.getElementById('explorer-plot').layout.shapes.length") == 1  # cell outlined
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#explorer").screenshot(path=str(ARTIFACTS / "explorer-clicked.png"))

        page.focus("input[aria-label='value of blur_sigma']")  # move the slider with the keyboard
        page.keyboard.press("ArrowRight")
        page.wait_for_function("() => document.querySelector('.explorer-control.slider output').textContent === '1.5'")
        moved = gallery(page)
        assert "blur_sigma = 1.5" in page.inner_text("#explorer-gallery h3")
        assert {t["src"] for t in moved}.isdisjoint({t["src"] for t in tiles})  # other images: blurred ones
        assert all("blur_sigma = 1.5" in t["title"] for t in moved)
        page.locator("#explorer").screenshot(path=str(ARTIFACTS / "explorer-slider.png"))
        assert_clean(path, events)


def test_heat_map_matches_sql_and_shows_right_and_wrong(tmp_path: Path) -> None:
    spec = build_store(tmp_path / "run", 400, seed=3)
    loaded = load_spec(spec)
    path = write_report(loaded)
    con = connect(Store(loaded.store), loaded.name)
    with open_page(path, wait_all=False) as (page, events):
        drawn = heatmap(page)
        assert drawn["x"] == ["city", "forest", "night", "studio"]  # environments across, objects down
        for y, obj in enumerate(drawn["y"]):
            for x, env in enumerate(drawn["x"]):
                accuracy = con.execute("SELECT accuracy FROM scene_accuracy WHERE object = ? AND environment = ?",
                                       [obj, env]).fetchone()[0]
                assert drawn["z"][y][x] == pytest.approx(accuracy)
        assert "orientation_yaw (binned)" in page.inner_text("#explorer-controls")

        page.select_option("select[aria-label='role of orientation_yaw']", "y")
        yaw = heatmap(page)
        assert len(yaw["y"]) == 10 and yaw["y"][0].startswith("-")
        levels = con.execute("SELECT label, accuracy FROM control_accuracy WHERE parameter = 'orientation_yaw' "
                             "ORDER BY level").fetchall()
        assert yaw["y"] == [label for label, _ in levels]
        page.select_option("select[aria-label='role of environment']", "pooled")
        page.select_option("select[aria-label='role of object']", "pooled")
        column = heatmap(page)
        assert [row[0] for row in column["z"]] == pytest.approx([accuracy for _, accuracy in levels])

        low, high = con.execute("SELECT wilson_low(3, 10), wilson_high(3, 10)").fetchone()
        assert page.evaluate("window.sweep3d.wilson(3, 10)") == pytest.approx([low, high])  # JS = SQL

        click_cell(page, 0, 0)
        tiles = gallery(page)
        outcomes = [t["outcome"] for t in tiles]
        assert {"correct", "wrong"} <= set(outcomes)
        assert outcomes == sorted(outcomes, key=lambda o: o != "wrong")  # wrong ones first
        borders = {t["outcome"]: t["border"] for t in tiles}
        assert borders == {"wrong": "rgb(214, 69, 69)", "correct": "rgb(46, 157, 91)"}
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#explorer").screenshot(path=str(ARTIFACTS / "explorer-synthetic.png"))
        assert_clean(path, events)
