"""The explorer: its counts against SQL, and in headless Chromium axes, sliders and a clicked cell's gallery.

The page carries the joint table's counts (or each pair's), not the results: the fast tests
check those counts and the image sample against SQL on a synthetic store (rows written
directly, with right, wrong and invalid predictions and a binned parameter). The browser tests
drive the page of the real tiny run (Blender + the real model) and of synthetic stores, and
check every cell the browser sums, with sliders and in the pairs-only mode, against SQL.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import json
from pathlib import Path
from typing import Any

import duckdb
import pytest

from sweep3d.cache.store import Store
from sweep3d.report import build_context, render_html, write_report
from sweep3d.report.panels import PANELS, explorer
from sweep3d.report.reading import WRONG, Results, materialise_views
from sweep3d.results import connect
from sweep3d.results.measures import MEASURES
from tests.helpers import ARTIFACTS, assert_clean, build_store, cell_centre, load_spec, open_page


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    """A synthetic store of 400 results (no image blobs): its spec's path."""
    return build_store(tmp_path_factory.mktemp("explorer") / "run", 400, seed=3, images=False)


def opened(spec: Path) -> tuple[Any, duckdb.DuckDBPyConnection, Store]:
    loaded = load_spec(spec)
    store = Store(loaded.store)
    return loaded, connect(store, loaded.name), store


def explorer_payload(context: dict[str, Any]) -> dict[str, Any]:
    panel = next(p for p in context["panels"] if p.id == "explorer")
    return json.loads(panel.data["json"])


def expected_cell(con: duckdb.DuckDBPyConnection, where: dict[str, int]) -> tuple[int, int, int]:
    """(valid, correct, all) results at the given level of each parameter, straight from SQL."""
    terms = " AND ".join("job IN (SELECT job FROM control_levels WHERE parameter = ? AND level = ?)" for _ in where)
    return con.execute(
        "SELECT count(*) FILTER (WHERE valid), count(*) FILTER (WHERE valid AND correct), count(*) FROM results"
        + (f" WHERE {terms}" if terms else ""), [v for item in where.items() for v in item]).fetchone()


def summed(table: dict[str, Any], where: dict[int, int]) -> tuple[int, int, int]:
    """(valid, correct, all) summed over the table's cells at the given level of each parameter."""
    cells = [c for c in range(len(table["n"])) if all(table["level"][table["params"].index(p)][c] == level
                                                      for p, level in where.items())]
    return tuple(sum(table[column][c] for c in cells) for column in ("n", "k", "total"))


def test_the_joint_table_sums_to_every_slice_sql_gives(synthetic: Path) -> None:
    loaded, con, store = opened(synthetic)
    data = explorer_payload(build_context(loaded, con, store))
    names = [p["name"] for p in data["params"]]
    assert data["mode"] == "joint" and len(data["tables"]) == 1
    table = data["tables"][0]
    levels = [len(p["labels"]) for p in data["params"]]
    assert data["cells"] == len(table["n"]) <= min(400, 5 * 4 * 10 * 3 * 3)
    assert summed(table, {}) == expected_cell(con, {}) and sum(table["total"]) > sum(table["n"])  # invalid ones too
    pairs = con.execute(  # any two axes, nothing else fixed: (valid, correct, all) by SQL
        "SELECT a.parameter, a.level, b.parameter, b.level, count(*) FILTER (WHERE a.valid), "
        "count(*) FILTER (WHERE a.valid AND a.correct), count(*) FROM control_levels a JOIN control_levels b "
        "ON a.job = b.job AND a.position < b.position GROUP BY ALL").fetchall()
    assert "margin" in names  # a measure is an axis too (its levels are not crossed with the others')
    crossed = [i for i, name in enumerate(names) if name not in MEASURES]
    assert len([p for p in pairs if p[0] not in MEASURES and p[2] not in MEASURES]) == sum(
        levels[a] * levels[b] for a, b in itertools.combinations(crossed, 2))
    for a, la, b, lb, *expected in pairs:
        assert summed(table, {names.index(a): la, names.index(b): lb}) == tuple(expected)
    yaw, elevation, blur, obj = (names.index(n) for n in ("orientation_yaw", "camera_elevation", "blur_sigma",
                                                          "object"))
    for ly, le in itertools.product(range(levels[yaw]), range(levels[elevation])):  # two axes, two sliders
        where = {yaw: ly, elevation: le, blur: 1, obj: 2}
        assert summed(table, where) == expected_cell(con, {names[p]: level for p, level in where.items()})


def test_the_sample_takes_the_worst_of_every_cell_first(synthetic: Path) -> None:
    loaded, con, _ = opened(synthetic)
    materialise_views(con)
    results = Results(con, ["object", "environment", *loaded.parameter_columns])
    every = list(range(len(results.parameters)))
    cells = results.cells(every)
    jobs = results.sample([every], [], 0, cells)  # one round: one result per cell
    rows = results.rows(jobs)
    assert len({r.levels for r in rows}) == len(rows) == cells
    for row in rows[::10]:  # the most telling result of its cell: a wrong one when the cell has one
        where = {p.name: level for p, level in zip(results.parameters, row.levels)}
        worst = results.examples(where, 1)
        assert row.job == (worst[0].job if worst else row.job) and (row.outcome == WRONG) == bool(worst)
    first = [results.index("object"), results.index("environment")]
    scenes = [r.levels[0:2] for r in results.rows(results.sample([every], first, 2, 40))]
    assert sorted(scenes) == sorted(s for s in itertools.product(range(5), range(4)) for _ in range(2))


def test_a_joint_table_over_budget_becomes_pair_tables(synthetic: Path) -> None:
    loaded, con, store = opened(synthetic)
    context = build_context(loaded, con, store, with_max_cells(50))
    data = explorer_payload(context)
    names = [p["name"] for p in data["params"]]
    assert data["mode"] == "pairs" and data["cells"] > 50
    assert [t["params"] for t in data["tables"]] == [list(p) for p in itertools.combinations(range(len(names)), 2)]
    for table in data["tables"]:
        a, b = table["params"]
        rows = con.execute(  # pair_accuracy's counts, for measures too (which it leaves out)
            "SELECT a.level, b.level, count(*) FILTER (WHERE a.counted), count(*) FILTER (WHERE a.counted AND "
            "a.correct) FROM control_levels a JOIN control_levels b ON a.job = b.job "
            "WHERE a.parameter = ? AND b.parameter = ? GROUP BY ALL", [names[a], names[b]]).fetchall()
        if names[a] not in MEASURES and names[b] not in MEASURES:
            assert sorted(rows) == sorted(con.execute(
                "SELECT level_a, level_b, n, n_correct FROM pair_accuracy WHERE parameter_a = ? AND parameter_b = ?",
                [names[a], names[b]]).fetchall())
        assert {(la, lb): (n, k) for la, lb, n, k in rows if n} == {
            (la, lb): (n, k) for la, lb, n, k in zip(*table["level"], table["n"], table["k"]) if n}
    assert "Sliders are off" in render_html(context)


def with_max_cells(max_cells: int) -> tuple:
    """The report's panels with the explorer's joint-table budget set to ``max_cells``."""
    build = functools.partial(explorer.build, max_cells=max_cells)
    return tuple(dataclasses.replace(p, build=build) if p.id == "explorer" else p for p in PANELS)


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


@pytest.mark.browser
def test_axis_slider_and_cell_click_change_the_plot_and_the_gallery(tiny_run: Path, chromium) -> None:
    loaded = load_spec(tiny_run / "spec.toml")
    path = write_report(loaded)
    con = connect(Store(loaded.store), loaded.name)
    with open_page(chromium, path, wait_all=False) as (page, events):
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


@pytest.mark.browser
def test_heat_map_matches_sql_and_shows_right_and_wrong(tmp_path: Path, chromium) -> None:
    spec = build_store(tmp_path / "run", 400, seed=3)
    loaded = load_spec(spec)
    path = write_report(loaded)
    con = connect(Store(loaded.store), loaded.name)
    with open_page(chromium, path, wait_all=False) as (page, events):
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
        assert outcomes == sorted(outcomes, key=["wrong", "correct", "invalid"].index)  # wrong ones first
        borders = {t["outcome"]: t["border"] for t in tiles}
        assert (borders["wrong"], borders["correct"]) == ("rgb(214, 69, 69)", "rgb(46, 157, 91)")
        valid, correct, total = expected_cell(con, {"orientation_yaw": 0})
        assert len(tiles) == total  # 400 results: every image is embedded
        assert page.inner_text("#explorer-gallery .note").startswith(f"{correct} of {valid} correct")
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#explorer").screenshot(path=str(ARTIFACTS / "explorer-synthetic.png"))

        page.select_option("select[aria-label='role of camera_elevation']", "x")  # two axes, two sliders
        for name, steps in (("blur_sigma", 1), ("object", 2)):
            page.select_option(f"select[aria-label='role of {name}']", "slider")
            page.focus(f"input[aria-label='value of {name}']")
            for _ in range(steps):
                page.keyboard.press("ArrowRight")
        # the parameters' sliders (the measures, margin here, come after them)
        page.wait_for_function("() => window.sweep3d.explorer.state.slider.slice(0, 5).join() === '2,0,0,0,1'")
        sliced = heatmap(page)
        assert sliced["x"] == ["0", "30", "60"] and len(sliced["y"]) == 10
        for y, x in itertools.product(range(10), range(3)):
            valid, correct, _ = expected_cell(con, {"orientation_yaw": y, "camera_elevation": x, "blur_sigma": 1,
                                                    "object": 2})
            assert sliced["text"][y][x].endswith(f"<br>n={valid}") if valid else sliced["text"][y][x] == ""
            assert sliced["z"][y][x] == (pytest.approx(correct / valid) if valid else None)
        click_cell(page, 1, 4)
        for blur in (1, 2):  # the clicked cell's counts follow the sliders
            valid, correct, total = expected_cell(con, {"orientation_yaw": 4, "camera_elevation": 1,
                                                        "blur_sigma": blur, "object": 2})
            page.wait_for_function("(text) => document.querySelector('#explorer-gallery .note').textContent"
                                   ".startsWith(text)", arg=f"{correct} of {valid} correct")
            assert len(gallery(page)) == total
            page.focus("input[aria-label='value of blur_sigma']")
            page.keyboard.press("ArrowRight")
        assert_clean(path, events)


@pytest.mark.browser
def test_pairs_mode_keeps_any_two_axes_exact_and_switches_sliders_off(synthetic: Path, tmp_path: Path, chromium) -> None:
    loaded, con, store = opened(synthetic)
    path = tmp_path / "pairs.html"
    path.write_text(render_html(build_context(loaded, con, store, with_max_cells(50))), encoding="utf-8")
    with open_page(chromium, path, wait_all=False) as (page, events):
        assert "Sliders are off" in page.inner_text("#explorer-degraded")
        assert page.evaluate("Array.from(document.querySelectorAll('#explorer-controls option[value=slider]'))"
                             ".every(o => o.disabled)")
        page.select_option("select[aria-label='role of orientation_yaw']", "y")
        page.select_option("select[aria-label='role of blur_sigma']", "x")
        drawn = heatmap(page)
        rows = con.execute("SELECT level_a, level_b, n, accuracy FROM pair_accuracy WHERE parameter_a = "
                           "'orientation_yaw' AND parameter_b = 'blur_sigma'").fetchall()
        assert len(rows) == 30
        for y, x, n, accuracy in rows:
            assert drawn["z"][y][x] == pytest.approx(accuracy) and drawn["text"][y][x].endswith(f"n={n}")
        assert page.inner_text("#explorer-status").startswith(f"{expected_cell(con, {})[0]} valid results")
        assert_clean(path, events)
