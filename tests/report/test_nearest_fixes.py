"""The report's *Nearest fixes* panel on a synthetic store and a counterfactuals file written
here (no render, no search): what its sentence says was searched, and what each pair's caption
and hover text say.

The caption's percentage is the probability the model gave the true class, and says so
(``balloon · p(basketball) 19.6 %``, not ``balloon · 19.6 % basketball``); each image's hover
text names the job and its configuration; "a seeded sample within a budget" only when the
budget left failures unsearched.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from sweep3d.cache.store import Store
from sweep3d.followups import explain
from sweep3d.report import build_context, render_html
from sweep3d.report.panels import PANELS
from sweep3d.results import SCHEMA, connect, legacy_counterfactuals_path
from tests.helpers import build_store, load_spec

NEAREST = tuple(p for p in PANELS if p.id == "nearest-fixes")


def failures(spec: Path) -> list[dict]:
    """The synthetic run's failures, as explain finds them (counted, wrong), in job order."""
    loaded = load_spec(spec)
    con = connect(Store(loaded.store), loaded.name)
    try:
        cursor = con.execute("SELECT job, object, environment, pred_key, image_key, top1_label, label_prob, "
                             "blur_sigma FROM results WHERE counted AND NOT correct ORDER BY job")
        names = [d[0] for d in cursor.description]
        return [dict(zip(names, row)) for row in cursor.fetchall()]
    finally:
        con.close()


def write_counterfactuals(spec: Path, rows: list[dict], budget: int | None, old: bool = False, **more) -> None:
    """One found fix per row; ``more``: further columns, a list (one value per row) or one value for
    all; ``old``: a file of a store from before the table, written before ``fix_fragile`` and the
    columns after it were added."""
    loaded = load_spec(spec)
    out = []
    for i, r in enumerate(rows):
        row = {name: None for name in SCHEMA.names}
        row.update(experiment=loaded.name, model=loaded.model.label, failure_job=r["job"], object=r["object"],
                   environment=r["environment"], true_labels=f"{r['object']}-label", failure_pred_key=r["pred_key"],
                   failure_image_key=r["image_key"], failure_label=r["top1_label"], failure_correct=False,
                   failure_probability=r["label_prob"], found=True, complete=True, probes=3,
                   fix_image_key=r["image_key"], fix_label=f"{r['object']}-label", fix_correct=True,
                   fix_probability=0.62, parameters=["blur_sigma"], from_values=[str(r["blur_sigma"])],
                   to_values=["0"], deltas=[-r["blur_sigma"]], shares=[-0.5], n_changed=1, distance=0.5,
                   change="blur_sigma -1", seed=0, budget=budget)
        row.update({k: v[i] if isinstance(v, list) else v for k, v in more.items()})
        out.append(row)
    explain.write_counterfactuals(Store(loaded.store), loaded.name, [] if old else out)  # as explain keeps them
    if not old:
        return
    path = legacy_counterfactuals_path(Store(loaded.store), loaded.name)  # a store's file from before the table
    path.parent.mkdir(exist_ok=True)
    schema = pa.schema(list(SCHEMA)[:SCHEMA.get_field_index("fix_fragile")])
    pq.write_table(pa.Table.from_pylist([{k: row[k] for k in schema.names} for row in out], schema=schema), path)


def panel_html(spec: Path) -> str:
    loaded = load_spec(spec)
    store = Store(loaded.store)
    page = render_html(build_context(loaded, connect(store, loaded.name), store, NEAREST))
    return re.search(r'<section id="nearest-fixes"[^>]*>(.*?)</section>', page, re.S).group(1)  # folded or not


def text(fragment: str) -> str:
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", fragment)).split())


@pytest.fixture(scope="module")
def spec(tmp_path_factory) -> Path:
    return build_store(tmp_path_factory.mktemp("fixes"), 60, images=False)


@pytest.mark.parametrize("searched, budget, says", [
    ("all", 20, "For all {n} of the run's failures (within a budget of 20 new configurations),"),
    ("all", None, "For all {n} of the run's failures,"),
    (2, 20, "For 2 of the run's {n} failures (a seeded sample: those a budget of 20 new configurations reached),"),
])
def test_the_sentence_says_a_sample_only_when_the_budget_left_failures_unsearched(spec: Path, searched, budget,
                                                                                 says: str) -> None:
    wrong = failures(spec)
    assert len(wrong) > 2
    write_counterfactuals(spec, wrong if searched == "all" else wrong[:searched], budget)
    assert text(panel_html(spec)).removeprefix("Nearest fixes ").startswith(says.format(n=len(wrong)))


def test_each_caption_says_whose_probability_and_each_image_names_its_job_and_configuration(spec: Path) -> None:
    wrong = failures(spec)[:3]
    write_counterfactuals(spec, wrong, None)
    found = panel_html(spec)
    for r in wrong:
        pair = re.search(rf'<div class="fix-pair" data-job="{r["job"]}">(.*?)<div class="body">', found, re.S).group(1)
        failure, fix = re.findall(r"<figure (.*?)</figure>", pair, re.S)
        true = f"p({r['object']}-label)"
        assert text(failure.split(">", 1)[1]) == f"{r['top1_label']} · {true} {r['label_prob']:.1%}"
        assert text(fix.split(">", 1)[1]) == f"{r['object']}-label · {true} 62.0%"
        failure_title = html.unescape(re.search(r'title="([^"]*)"', failure).group(1))
        fix_title = html.unescape(re.search(r'title="([^"]*)"', fix).group(1))
        configuration = f"job {r['job']} · object = {r['object']} · environment = {r['environment']}"
        assert failure_title.startswith(configuration) and "blur_sigma = " in failure_title, failure_title
        assert fix_title.startswith(f"nearest fix of {configuration}") and "blur_sigma" in fix_title, fix_title
        assert f"with blur_sigma {r['blur_sigma']} → 0" in fix_title


def test_each_pair_says_its_margin_whether_it_is_fragile_and_the_searchs_resolution(spec: Path) -> None:
    wrong = failures(spec)[:3]
    write_counterfactuals(spec, wrong, None, fix_margin=[0.012, 0.3, 0.21], fix_fragile=[True, False, False],
                          fragile_threshold=0.05, further_probes=[6, 0, 3], resolution=1 / 64,
                          resolutions=[[3 / 64]] * 3, nearest_distance=[None, None, 0.4],
                          nearest_margin=[None, None, 0.02], nearest_change=[None, None, "-0.9 blur_sigma"])
    found = panel_html(spec)
    note = text(found.split('<div class="gallery', 1)[0])
    assert "\"nearest\" is to within 1/64 of each range" in note
    assert "Fragile: 1 of 3 fixes are right by a margin below the stability check's threshold (0.05)" in note
    assert "1 found a sturdier fix there, shown instead" in note
    pairs = {int(job): (classes, body) for classes, job, body in
             re.findall(r'<div class="fix-pair([^"]*)" data-job="(\d+)">(.*?)</div>\s*</div>', found, re.S)}
    trust = {job: text(re.search(r'<div class="trust">(.*?)</div>', body, re.S).group(1))
             for job, (_, body) in pairs.items()}
    first, second, third = (r["job"] for r in wrong)
    assert pairs[first][0] == " fragile" and pairs[second][0] == pairs[third][0] == ""
    assert trust[first] == ("fragile: margin +0.012, below the stability check's 0.05, and none of 6 probes further "
                            "along the change clears it; nearest to within 1/64 of the range: blur_sigma 0.0469")
    assert trust[second] == "margin +0.3, not fragile; nearest to within 1/64 of the range: blur_sigma 0.0469"
    assert trust[third].startswith("margin +0.21, not fragile; the nearest fix, -0.9 blur_sigma at distance 0.4, "
                                   "is fragile: margin +0.02")


def test_a_file_from_before_the_trust_columns_reads_them_as_null(spec: Path) -> None:
    wrong = failures(spec)[:2]
    write_counterfactuals(spec, wrong, None, old=True)
    note = text(panel_html(spec))
    assert "Whether a fix is fragile is unknown until sweep3d stability has checked the run" in note
    loaded = load_spec(spec)
    con = connect(Store(loaded.store), loaded.name)
    try:
        assert con.execute("SELECT count(*), count(sentence), count(fix_fragile) FROM counterfactuals").fetchone() \
            == (2, 0, 0)
    finally:
        con.close()
