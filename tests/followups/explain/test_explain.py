"""``sweep3d explain`` end to end on a tiny real spec: a user model that calls an image a carton
only when it is sharp fails on the blurred jobs, deterministically; the search renders and infers
its probes through the stages, the ``counterfactuals`` view says what fixes each failure, every
fixing job's stored prediction is right, a rerun renders nothing, and the report shows the pairs
side by side (in Chromium)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.api import Experiment
from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.report import write_report
from tests.helpers import ARTIFACTS, assert_clean, open_page, spec_toml, write_spec

SHARP_MODEL = '''
import torch
from sweep3d.stages.infer import Classifier, Preprocess


class Sharp(torch.nn.Module):
    """A carton when the image is sharp (mean absolute gradient above a threshold), else blurred."""

    def __init__(self, threshold):
        super().__init__()
        self.threshold = torch.nn.Parameter(torch.tensor(float(threshold)))

    def forward(self, x):
        g = (x[..., 1:, :] - x[..., :-1, :]).abs().mean(dim=(1, 2, 3)) + (x[..., 1:] - x[..., :-1]).abs().mean(dim=(1, 2, 3))
        s = (g - self.threshold) * 50
        return torch.stack([s, -s], dim=1)


def sharp():
    return Classifier(Sharp(0.09), Preprocess(resize=32, crop=32), labels=["carton", "blurred"])
'''

SPEC = spec_toml("explain-tiny", seed=3, model={"name": "explain_sharp_model:sharp", "batch_size": 8}, body="""\
[[controls]]
type = "orientation"
yaw = { range = [0, 90] }

[[controls]]
type = "blur"
sigma = { range = [0.0, 3.0] }

[policy]
type = "grid"
samples_per_dim = 3
""")

pytestmark = [pytest.mark.blender, pytest.mark.torch, pytest.mark.slow]


@pytest.fixture(scope="module")
def explained(tmp_path_factory) -> Path:
    """A run of the tiny spec, then ``sweep3d explain`` on it (no budget: every failure)."""
    folder = tmp_path_factory.mktemp("explain")
    (folder / "explain_sharp_model.py").write_text(SHARP_MODEL)
    spec = write_spec(folder, SPEC)
    runner = CliRunner()
    result = runner.invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, ["explain", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    assert "explain round 1:" in result.output and "have a nearest fix" in result.output  # progress, then the end
    return folder


def test_every_failure_gets_a_fix_whose_stored_prediction_is_right(explained: Path) -> None:
    experiment = Experiment(explained / "spec.toml")
    failures = experiment.sql("SELECT job FROM results WHERE counted AND NOT correct").column("job").to_pylist()
    assert 2 <= len(failures) <= 4
    rows = experiment.counterfactuals().to_pylist()
    assert sorted(r["failure_job"] for r in rows) == sorted(failures)
    store = Store(experiment.store)
    con = store.connect()
    for row in rows:
        assert row["found"] and row["complete"], row
        assert row["failure_label"] == "blurred" and row["failure_correct"] is False
        valid, correct, label = con.execute("SELECT valid, correct, top1_label FROM predictions WHERE pred_key = ?",
                                            [row["fix_pred_key"]]).fetchone()
        assert valid and correct and label == "carton" == row["fix_label"]
        assert row["fix_correct"] and row["fix_margin"] > 0 > row["failure_margin"]
        assert 1 <= row["n_changed"] <= 2 and len(row["deltas"]) == len(row["shares"]) == row["n_changed"]
        assert row["distance"] == pytest.approx(sum(s * s for s in row["shares"]) ** 0.5)
        for parameter, delta, share in zip(row["parameters"], row["deltas"], row["shares"]):
            span = 90.0 if parameter == "orientation_yaw" else 3.0
            assert delta == pytest.approx(share * span, abs=1e-9), row  # own units against share of range
        assert store.blob_path(row["fix_image_key"]).exists()  # the report shows it
    cheapest = experiment.sql("SELECT parameter, cheapest FROM counterfactual_parameters").to_pylist()
    assert sum(p["cheapest"] for p in cheapest) == sum(r["n_changed"] for r in rows)
    query = CliRunner().invoke(app, ["query", str(explained / "spec.toml"),
                                     "SELECT count(*) AS n FROM counterfactuals WHERE found"])
    assert query.exit_code == 0 and str(len(rows)) in query.output


def test_a_rerun_renders_nothing_and_writes_the_same_counterfactuals(explained: Path) -> None:
    """Its rows are the store's ``counterfactuals`` table's: the same rows found again are not written again."""
    experiment = Experiment(explained / "spec.toml")
    store = Store(experiment.store)
    segments = store.segments("counterfactuals")
    before = experiment.counterfactuals()
    again = experiment.explain(progress=False)
    assert again.rendered == 0 and again.found == len(again.fixes) >= 2
    assert store.segments("counterfactuals") == segments and len(segments) == 1
    assert experiment.counterfactuals().equals(before)


def test_a_budget_and_a_missing_run_are_one_line_each(tmp_path: Path) -> None:
    """Neither needs a run (a test that takes ``explained`` makes its worker run it)."""
    runner = CliRunner()
    (tmp_path / "explain_sharp_model.py").write_text(SHARP_MODEL)
    fresh = write_spec(tmp_path, SPEC)
    sys.modules.pop("explain_sharp_model", None)
    bad = runner.invoke(app, ["explain", str(fresh), "--budget", "-1"])
    assert bad.exit_code == 2 and "--budget -1" in bad.output and "Traceback" not in bad.output
    early = runner.invoke(app, ["explain", str(fresh)])
    assert early.exit_code == 2 and f"sweep3d run {fresh}" in early.output, early.output
    assert not (tmp_path / "store").exists()  # refused before the lock would make the store


@pytest.mark.browser
def test_the_nearest_fixes_panel_shows_each_failure_beside_its_fix(explained: Path, chromium) -> None:
    experiment = Experiment(explained / "spec.toml")
    n = len(experiment.counterfactuals())
    report = write_report(experiment.spec)
    with open_page(chromium, report) as (page, events):
        pairs = page.evaluate("""Array.from(document.querySelectorAll('#nearest-fixes .fix-pair')).map(p => {
            const [a, b] = Array.from(p.querySelectorAll('img')).map(i => i.getBoundingClientRect());
            const loaded = Array.from(p.querySelectorAll('img')).every(i => i.naturalWidth > 0);
            return {left: a.left, right: a.right, fixLeft: b.left, top: a.top, fixTop: b.top, loaded,
                    sentence: p.querySelector('.sentence').textContent,
                    moved: p.querySelector('.controls').textContent};
        })""")
        assert len(pairs) == n
        for pair in pairs:
            assert pair["loaded"], pair
            assert pair["top"] == pair["fixTop"] and pair["right"] <= pair["fixLeft"], pair  # side by side
            assert pair["sentence"].endswith("makes it a carton"), pair
            assert "orientation_yaw" in pair["moved"] or "blur_sigma" in pair["moved"], pair
            assert "→" in pair["moved"] and "distance" in pair["moved"], pair
        rows = page.evaluate("Array.from(document.querySelectorAll('#nearest-fixes table.cheapest tbody tr'))"
                             ".map(r => r.textContent)")
        assert rows and all("%" in r for r in rows)
        assert page.evaluate("document.documentElement.scrollWidth") <= 1280
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#nearest-fixes").screenshot(path=str(ARTIFACTS / "nearest-fixes.png"))
        assert_clean(report, events)


def test_after_a_stability_check_fragile_fixes_are_marked_or_searched_past(explained: Path, tmp_path: Path) -> None:
    """The check's rows are written here (every run image flipped, at margins just below a bin edge
    that some nearest fix falls under), so its threshold is that edge; explain again (on a copy of
    the store) marks each fix by the rule, goes past the fragile ones, and prints the sentences."""
    from datetime import datetime, timezone

    from sweep3d.followups.stability.check import SCHEMA, stability_key
    from sweep3d.results.fragile import MARGIN_EDGES

    folder = tmp_path / "copy"
    shutil.copytree(explained, folder)
    experiment = Experiment(folder / "spec.toml")
    before = {r["failure_job"]: r for r in experiment.counterfactuals().to_pylist()}
    lowest = min(r["fix_margin"] for r in before.values())
    edge = next(i for i, e in enumerate(MARGIN_EDGES) if e > lowest)
    middle = ((MARGIN_EDGES[edge - 1] if edge else 0.0) + MARGIN_EDGES[edge]) / 2
    keys = experiment.sql("SELECT pred_key FROM results").column("pred_key").to_pylist()
    now = datetime.now(timezone.utc)
    Store(experiment.store).append("stability", [
        {"stability_key": stability_key(k, "noise", 0), "pred_key": k, "image_key": k, "change": "noise", "seed": 0,
         "base_correct": True, "base_margin": middle, "correct": False, "margin": -middle, "flipped": True,
         "created_at": now} for k in keys], SCHEMA)
    threshold = experiment.sql("SELECT threshold FROM fragile_threshold").column("threshold").to_pylist()[0]
    assert threshold == MARGIN_EDGES[edge]
    result = CliRunner().invoke(app, ["explain", str(folder / "spec.toml"), "--no-report"], env={"COLUMNS": "400"})
    assert result.exit_code == 0, result.output
    rows = experiment.counterfactuals().to_pylist()
    assert [r["failure_job"] for r in rows] == sorted(before)
    for row in rows:
        assert row["found"] and row["fragile_threshold"] == threshold and row["resolution"] == pytest.approx(1 / 64)
        assert row["fix_fragile"] == (row["fix_margin"] < threshold or row["fix_pred_key"] in keys), row
        nearest = before[row["failure_job"]]
        if row["nearest_distance"] is not None:  # a sturdier fix further along the same change
            assert not row["fix_fragile"] and row["nearest_margin"] < threshold <= row["fix_margin"]
            assert row["nearest_distance"] == pytest.approx(nearest["distance"])
            assert row["distance"] > nearest["distance"]
            assert row["parameters"] == nearest["parameters"] and row["further_probes"] >= 1
        else:
            assert row["fix_pred_key"] == nearest["fix_pred_key"]  # the nearest fix, marked
        if row["fix_fragile"]:
            assert row["sentence"].split("(", 1)[1].startswith("fragile: ")
        assert row["sentence"] in " ".join(result.output.split())
    assert any(r["further_probes"] for r in rows)  # some nearest fix was fragile and searched past
    assert f"fragile: {sum(r['fix_fragile'] for r in rows)} of {len(rows)} fixes" in result.output
