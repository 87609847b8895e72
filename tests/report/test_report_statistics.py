"""What the report claims from its statistics: image cards name only what varies, failure modes
only what is significant, per-object sensitivity only what enough results support.

The store is the synthetic one of ``benchmarks/report_scale.py`` (no Blender, no model, no image
blobs), with its camera elevation fixed at 0 in the spec and in every job.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from sweep3d.cache.store import Store
from sweep3d.report import build_context, render_html
from sweep3d.results import connect
from tests.helpers import build_store, load_spec

FIXED = "camera_elevation"


@pytest.fixture(scope="module")
def fixed_elevation(tmp_path_factory) -> Path:
    """A synthetic store of 600 results whose spec and jobs hold one elevation: its spec's path."""
    spec = build_store(tmp_path_factory.mktemp("stats") / "run", 600, seed=4, images=False)
    spec.write_text(spec.read_text().replace("elevation = [0, 30, 60]", "elevation = 0"))
    loaded = load_spec(spec)
    store = Store(loaded.store)
    path = store.jobs_path(loaded.name)
    jobs = pq.read_table(path)
    column = jobs.schema.get_field_index(FIXED)
    jobs = jobs.set_column(column, FIXED, pa.array([0.0] * len(jobs)))
    store.write_table_file(path, jobs)
    return spec


def context_of(spec: Path) -> dict[str, Any]:
    loaded = load_spec(spec)
    store = Store(loaded.store)
    return build_context(loaded, connect(store, loaded.name), store)


def panel(context: dict[str, Any], panel_id: str) -> dict[str, Any]:
    return next(p for p in context["panels"] if p.id == panel_id).data


def test_image_cards_leave_out_a_parameter_with_one_value_and_the_header_states_it(fixed_elevation: Path) -> None:
    context = context_of(fixed_elevation)
    assert context["fixed"] == [(FIXED, "0")]
    cards = panel(context, "failures")["cards"]
    assert cards and all([name for name, _ in card["controls"]] == ["orientation_yaw", "blur_sigma"]
                         for card in cards)
    tiles = [t for mode in panel(context, "failure-modes")["modes"] for t in mode["examples"]]
    tiles += [c["example"] for row in panel(context, "objects")["objects"] for c in row["confusions"] if c["example"]]
    assert tiles and all("orientation_yaw = " in t["title"] and "blur_sigma = " in t["title"]
                         and f"{FIXED} = " not in t["title"] for t in tiles)
    assert all("object = " in t["title"] and "environment = " in t["title"] for t in tiles)  # the scene, always

    html = render_html(context)
    header = re.search(r'<p class="fixed" id="fixed">(.*?)</p>', html, re.S).group(1)
    assert f'<span class="param">{FIXED}</span> = <b>0</b>' in header
    assert html.count(f"{FIXED} = ") == 0  # no card or tile says it again (the header's markup splits it)


def test_failure_modes_show_significant_regions_and_set_the_others_apart(fixed_elevation: Path) -> None:
    loaded = load_spec(fixed_elevation)
    con = connect(Store(loaded.store), loaded.name)
    context = context_of(fixed_elevation)
    data = panel(context, "failure-modes")
    min_count = data["min_count"]
    significant = con.execute(f"SELECT count(*) FROM failure_modes(min_count := {min_count}) WHERE significant"
                              ).fetchone()[0]
    weak = con.execute(f"SELECT count(*) FROM failure_modes(min_count := {min_count}) WHERE NOT significant"
                       ).fetchone()[0]
    assert significant and weak  # the synthetic model's weak spots, and some noise below the overall
    assert len(data["modes"]) == min(significant, 12) and data["weak_total"] == weak
    shown = {tuple(map(tuple, m["terms"])) for m in data["modes"]}
    for mode in data["weak"]:  # the not significant ones are listed apart, never among the failure modes
        assert tuple(map(tuple, mode["terms"])) not in shown
    figure = re.search(r'"y":\s*\[(.*?)\]', data["figure"].json).group(1)
    assert figure.count('"') == 2 * len(data["modes"])  # the dot plot draws the significant ones only
    html = render_html(context)
    assert 'id="not-significant"' in html and "not significant" in html


def test_per_object_sensitivity_shows_the_count_behind_worst_and_best(fixed_elevation: Path) -> None:
    data = panel(context_of(fixed_elevation), "objects")
    listed = [s for row in data["objects"] for s in row["sensitive"]]
    assert listed and all(s["worst_n"] >= data["min_count"] and s["best_n"] >= data["min_count"] for s in listed)
    assert all(s["parameter"] != FIXED for s in listed)
    html = render_html(context_of(fixed_elevation))
    first = listed[0]
    assert f"{first['worst_accuracy']} of {first['worst_n']}" in html
