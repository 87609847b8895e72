"""Failure boundaries: the step fit's interval covers a known threshold, no boundary where the
control does not matter, the view, the findings line, ``query`` and the report's panel.

Outcomes are synthetic (a stand-in model that fails below a set elevation, with or without
label noise); stores are written row by row (``make_store``) or with the report benchmark's
bulk writer, so nothing renders.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.cli.output import by_parameter, describe_boundary, describe_flat
from sweep3d.report import build_context, render_html, write_report
from sweep3d.results import connect, summarise
from sweep3d.results.boundaries import Scale, adjust, failure_boundaries, fit_parameter, numeric_scales
from sweep3d.results.summary import boundary_findings
from sweep3d.stages.plan.step_fit import CRITICAL, fit_step
from tests.helpers import build_store, load_spec, make_store

THRESHOLD = 12.0
LOW, HIGH = 0.0, 60.0


def stand_in(rng: np.random.Generator, n: int, noise: float) -> tuple[np.ndarray, np.ndarray]:
    """Elevations drawn over the range and a model that fails below :data:`THRESHOLD`, each label
    flipped with probability ``noise``."""
    x = rng.uniform(LOW, HIGH, n)
    correct = (x >= THRESHOLD) ^ (rng.random(n) < noise)
    return x, correct


def test_the_critical_value_is_the_95_percent_point_of_the_location_ratio() -> None:
    # (1 - exp(-c / 2))² = 0.95: both one-sided suprema of 2W(t) - |t| below c
    assert (1 - np.exp(-CRITICAL / 2)) ** 2 == pytest.approx(0.95)
    assert CRITICAL == pytest.approx(7.35, abs=0.01)


@pytest.mark.parametrize("noise", [0.0, 0.15])
@pytest.mark.parametrize("n", [30, 60, 200])
def test_the_interval_covers_the_threshold_in_at_least_90_percent_of_seeds(n: int, noise: float) -> None:
    covered, widths = 0, []
    for seed in range(100):
        x, correct = stand_in(np.random.default_rng([seed, n]), n, noise)
        fit = fit_step(x, correct, test=False)
        covered += fit.interval_low <= THRESHOLD <= fit.interval_high
        widths.append(fit.interval_high - fit.interval_low)
        assert fit.interval_low <= fit.low_side < fit.high_side <= fit.interval_high
    assert covered >= 90, f"{covered} of 100"
    assert np.median(widths) < (HIGH - LOW) / 3  # and it says something


def test_a_deterministic_threshold_is_located_between_the_last_failure_and_the_first_success() -> None:
    x, correct = stand_in(np.random.default_rng(3), 40, 0.0)
    fit = fit_step(x, correct, seed=1)
    assert fit.low_side == x[~correct].max() and fit.high_side == x[correct].min()  # complete separation: finite
    assert (fit.accuracy_below, fit.accuracy_above) == (0.0, 1.0)
    assert fit.p_value < 0.001 and fit.permutations > 999  # resolved beyond the first 999 permutations


@pytest.mark.parametrize("n", [30, 200])
def test_no_boundary_where_the_control_does_not_matter(n: int) -> None:
    """The permutation test is exact: under no effect a boundary is called in at most 5 % of
    seeds; over 400 seeds the observed rate stays within two standard errors of that."""
    seeds = 400
    false = 0
    for seed in range(seeds):
        rng = np.random.default_rng([seed, n, 7])
        x = rng.uniform(LOW, HIGH, n)
        false += fit_step(x, rng.random(n) < 0.6, seed=seed).p_value < 0.05
    assert false / seeds <= 0.05 + 2 * np.sqrt(0.05 * 0.95 / seeds), f"{false} of {seeds}"


def test_permutations_within_scenes_keep_a_scene_effect_from_looking_like_a_step() -> None:
    # two scenes sampled at different elevations with different base accuracies, no step in either
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(0, 30, 60), rng.uniform(30, 60, 60)])
    correct = np.concatenate([rng.random(60) < 0.2, rng.random(60) < 0.9])
    scenes = np.repeat([0, 1], 60)
    assert fit_step(x, correct, seed=2).p_value < 0.01  # pooled, the scene effect is a step
    assert fit_step(x, correct, scenes, seed=2).p_value > 0.05  # within scenes, there is none


def test_many_values_are_merged_into_groups_and_still_cover() -> None:
    x, correct = stand_in(np.random.default_rng(9), 5000, 0.1)
    fit = fit_step(x, correct, seed=0)
    assert fit.values == 5000 and fit.interval_low <= THRESHOLD <= fit.interval_high
    assert fit.interval_high - fit.interval_low < 3 and fit.p_value < 0.001


def elevation_rows(seed: int = 0) -> list[dict]:
    """The toaster fails below 12°, the ball never does; blur does not matter; two environments."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(240):
        obj, env = ("toaster", "ball")[i % 2], ("studio", "forest")[i // 2 % 2]
        x = float(rng.uniform(LOW, HIGH))
        fails = obj == "toaster" and x < THRESHOLD
        rows.append({"object": obj, "environment": env, "camera_elevation": x,
                     "blur_sigma": float(rng.uniform(0, 3)), "orientation_yaw": float(rng.uniform(-180, 180)),
                     "correct": bool(fails == (rng.random() < 0.05))})
    return rows


SCALES = {"camera_elevation": Scale(), "blur_sigma": Scale(), "orientation_yaw": Scale(wraps=True)}


def test_the_view_names_the_boundary_where_it_is_and_none_elsewhere(tmp_path: Path) -> None:
    con = make_store(tmp_path, elevation_rows())
    rows = failure_boundaries(con, SCALES).to_pylist()
    found = {(r["parameter"], r["scope"], r["object"] or r["environment"]): r for r in rows}
    assert {p for p, _, _ in found} == {"camera_elevation", "blur_sigma"}  # a whole turn is not fitted
    toaster = found[("camera_elevation", "object", "toaster")]
    assert toaster["significant"] and toaster["fails"] == "below"
    assert toaster["boundary_low"] <= THRESHOLD <= toaster["boundary_high"]
    assert toaster["accuracy_below"] < 0.2 < 0.8 < toaster["accuracy_above"]
    assert toaster["level"] == pytest.approx((toaster["accuracy_below"] + toaster["accuracy_above"]) / 2)
    assert not found[("camera_elevation", "object", "ball")]["significant"]
    boundaries = [key for key, r in found.items() if r["significant"]]
    assert all(p == "camera_elevation" for p, _, _ in boundaries)  # blur: no boundary anywhere
    for r in rows:  # no boundary: its columns are empty, the fit still says what was seen
        assert (r["boundary"] is None) == (not r["significant"]) and r["q_value"] >= r["p_value"]
    again = failure_boundaries(con, SCALES).to_pylist()
    assert again == rows  # seeded by names: the same numbers every time


def test_without_a_spec_the_binned_numbers_are_fitted(tmp_path: Path) -> None:
    con = make_store(tmp_path, elevation_rows())
    fitted = {r["parameter"] for r in failure_boundaries(con).to_pylist()}
    assert fitted == {"camera_elevation", "blur_sigma", "orientation_yaw"}  # all three have > 12 values


def test_the_findings_name_the_boundaries_and_nothing_for_a_control_that_does_not_matter(tmp_path: Path) -> None:
    con = make_store(tmp_path, elevation_rows())
    summary = summarise(con, list(SCALES), scales=SCALES)
    assert summary.boundaries and {b["parameter"] for b in summary.boundaries} == {"camera_elevation"}
    toaster = next(b for b in summary.boundaries if b["object"] == "toaster")
    line = describe_boundary(toaster)
    assert line.startswith("toaster: camera_elevation fails below 1")
    passing = f"{toaster['accuracy_above']:.0%} of {toaster['n_above']}"
    assert f"(95% interval {toaster['boundary_low']:.3g}–{toaster['boundary_high']:.3g}), {passing} → " in line
    groups = [r for r in failure_boundaries(con, SCALES).to_pylist() if r["significant"] and r["scope"] != "all"]
    named, _, more = boundary_findings(con, SCALES, limit=1)  # the rest are kept for the findings list
    assert len(groups) >= 2 and len(more) == len(groups) - 1 and sum(r["scope"] != "all" for r in named) == 1
    assert {(r["scope"], r[r["scope"]]) for r in named + more if r["scope"] != "all"} == \
        {(g["scope"], g[g["scope"]]) for g in groups}  # none lost

    rng = np.random.default_rng(1)
    null = [{"camera_elevation": float(rng.uniform(0, 60)), "correct": bool(rng.random() < 0.7)} for _ in range(80)]
    con = make_store(tmp_path / "null", null)
    assert summarise(con, ["camera_elevation"], scales={"camera_elevation": Scale()}).boundaries == []


def test_the_false_boundary_rate_of_the_view_over_seeds() -> None:
    """A null model with two objects and two environments (five fits, adjusted together as the view
    does): in at most 5 % of seeds (within two standard errors, over 100 seeds) is any boundary named."""
    seeds, named = 100, 0
    objects, environments = np.array(["a", "b"] * 40, object), np.array(["e", "e", "f", "f"] * 20, object)
    for seed in range(seeds):
        rng = np.random.default_rng([seed, 11])
        rows = fit_parameter("camera_elevation", Scale(), rng.uniform(0, 60, 80), rng.random(80) < 0.6,
                             objects, environments)
        assert len(rows) == 5
        named += any(r["significant"] for r in adjust(rows))
    assert named / seeds <= 0.05 + 2 * np.sqrt(0.05 * 0.95 / seeds), f"{named} of {seeds}"


def test_numeric_scales_follow_the_spec(tmp_path: Path) -> None:
    spec = build_store(tmp_path / "run", 40, images=False)
    scales = numeric_scales(load_spec(spec).controls)
    assert scales == {"orientation_yaw": Scale(wraps=True), "camera_elevation": Scale(), "blur_sigma": Scale()}


@pytest.mark.parametrize("yaws, wraps", [
    ("[-120, 0, 120]", True),  # round the turn, evenly
    ("[0, 180]", True),  # two opposite views: neither is below the other
    ("[0, 90, 180, 270]", True),
    ("[0, 51, 102, 153, 204, 255, 306]", True),  # nearly even: 54° back to the first
    ("[0, 90]", True),  # either arc of the circle separates two values
    ("[0, 30, 60]", False),  # a sector: below and above mean something
    ("[-45, 0, 45, 90]", False),
    ("[0, 90, 180]", False),  # half the turn
])
def test_a_list_of_a_periodic_parameter_wraps_when_it_goes_round_the_turn(tmp_path: Path, yaws: str,
                                                                       wraps: bool) -> None:
    spec = build_store(tmp_path / "run", 8, images=False)
    spec.write_text(spec.read_text().replace("yaw = { range = [-180, 180] }", f"yaw = {yaws}")
                    .replace('sigma = [0.0, 1.0, 2.0]', 'sigma = [0.0]'))
    scales = numeric_scales(load_spec(spec).controls)
    assert scales == {"orientation_yaw": Scale(wraps=wraps), "camera_elevation": Scale()}  # one blur: nothing to fit


def test_two_values_are_tested_and_the_interval_is_the_gap_between_them() -> None:
    rng = np.random.default_rng(4)
    x = np.repeat([5.0, 35.0], 120)
    objects, environments = np.array(["a"] * 240, object), np.array(["e"] * 240, object)
    stepped = fit_parameter("camera_elevation", Scale(), x, rng.random(240) < np.where(x < 20, 0.3, 0.8),
                            objects, environments)
    flat = fit_parameter("camera_elevation", Scale(), x, rng.random(240) < 0.7, objects, environments)
    (step,), (none,) = adjust(stepped), adjust(flat)
    assert step["significant"] and step["fails"] == "below" and step["values"] == 2
    assert (step["boundary"], step["boundary_low"], step["boundary_high"]) == (20.0, 5.0, 35.0)
    assert not none["significant"] and none["boundary"] is None and none["p_value"] > 0.05
    # the midpoint was never rendered: the findings name the value it fails at against the other
    line = describe_boundary(step)
    assert line.startswith("camera_elevation fails at 5 against 35, ") and "interval" not in line
    # ... and the accuracies in the order of those words: at 5 (failing), then against 35
    assert line.endswith(f"{step['accuracy_below']:.0%} of 120 against {step['accuracy_above']:.0%} of 120")
    above = dict(step, fails="above")
    assert describe_boundary(above) == (f"camera_elevation fails at 35 against 5, {step['accuracy_above']:.0%} of 120 "
                                        f"against {step['accuracy_below']:.0%} of 120")


def test_the_two_value_sentence_gives_each_value_its_own_accuracy_as_on_the_quickstart() -> None:
    """The quickstart's elevations 5 and 35, 480 results each, 61.7 % right at 5 and 69 % at 35:
    the line's first accuracy is that of the value it fails at (the words' order), counted here
    from the results, not read from the fit."""
    rng = np.random.default_rng(45)
    x = np.repeat([5.0, 35.0], 480)
    right = {5.0: 296, 35.0: 331}  # 61.7 % and 69.0 % of 480
    correct = np.concatenate([rng.permutation(np.arange(480) < right[v]) for v in (5.0, 35.0)])
    objects, environments = np.array(["a"] * 960, object), np.array(["e"] * 960, object)
    (row,) = adjust(fit_parameter("camera_elevation", Scale(), x, correct, objects, environments))
    assert row["significant"] and row["fails"] == "below"
    seen = {v: f"{correct[x == v].mean():.0%} of {int((x == v).sum())}" for v in (5.0, 35.0)}
    assert seen == {5.0: "62% of 480", 35.0: "69% of 480"}
    assert describe_boundary(row) == f"camera_elevation fails at 5 against 35, {seen[5.0]} against {seen[35.0]}"


def test_the_findings_say_where_there_is_no_boundary(tmp_path: Path) -> None:
    """Per parameter: over all results with its largest step when nothing steps overall, else the
    objects and environments without a boundary."""
    con = make_store(tmp_path, elevation_rows())
    summary = summarise(con, list(SCALES), scales=SCALES)
    flat = {(r["parameter"], r["scope"], r["object"] or r["environment"]) for r in summary.no_boundaries}
    assert ("blur_sigma", "all", None) in flat and ("camera_elevation", "object", "ball") in flat
    assert not {key for key in flat if key[0] == "camera_elevation"} & {("camera_elevation", "all", None),
                                                                      ("camera_elevation", "object", "toaster")}
    lines = {rows[0]["parameter"]: describe_flat(rows) for rows in by_parameter(summary.no_boundaries)}
    blur = next(r for r in summary.no_boundaries if r["parameter"] == "blur_sigma" and r["scope"] == "all")
    assert lines["blur_sigma"].startswith(f"blur_sigma: all results, largest step {blur['accuracy_below']:.0%} of "
                                          f"{blur['n_below']} → ")
    assert lines["blur_sigma"].endswith(f", q = {blur['q_value']:.2f}")
    assert lines["camera_elevation"].startswith("camera_elevation for objects ") and "ball" in lines["camera_elevation"]
    always = {"parameter": "q", "scope": "all", "object": None, "environment": None, "accuracy_below": 1.0,
              "accuracy_above": 1.0, "n_below": 5, "n_above": 7, "estimate": 1.0, "q_value": 1.0}
    assert describe_flat([always]) == "q: all results, always right"
    many = [{"parameter": "p", "scope": "object", "object": f"o{i}", "environment": None} for i in range(10)]
    assert describe_flat(many + [{"parameter": "p", "scope": "environment", "object": None, "environment": "[red]"}]) \
        == "p for objects o0, o1, o2, o3, o4, o5, o6, o7 and 2 more and environments \\[red]"


# -- query and report ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def elevation_spec(tmp_path_factory) -> Path:
    """The report benchmark's synthetic store with its camera elevation a range [0, 60] in the spec
    and, in the jobs, drawn so that accuracy steps down below 12: its spec's path."""
    spec = build_store(tmp_path_factory.mktemp("boundary") / "run", 400, seed=3, images=True)
    spec.write_text(spec.read_text().replace("elevation = [0, 30, 60]", "elevation = { range = [0, 60] }"))
    loaded = load_spec(spec)
    store = Store(loaded.store)
    correct = dict(connect(store, loaded.name).execute("SELECT job, correct FROM results").fetchall())
    path = store.jobs_path(loaded.name)
    jobs = pq.read_table(path)
    rng = np.random.default_rng(0)
    below = [rng.random() < (0.1 if correct.get(job) else 0.7) for job in jobs.column("job").to_pylist()]
    x = np.where(below, rng.uniform(0, THRESHOLD, len(below)), rng.uniform(THRESHOLD, 60, len(below)))
    jobs = jobs.set_column(jobs.schema.get_field_index("camera_elevation"), "camera_elevation", pa.array(x))
    store.write_table_file(path, jobs)
    return spec


def test_query_computes_the_boundaries_only_when_asked(elevation_spec: Path, monkeypatch) -> None:
    runner = CliRunner()
    result = runner.invoke(app, ["query", str(elevation_spec), "SELECT parameter, scope, boundary_low, boundary_high "
                                 "FROM failure_boundaries WHERE significant AND scope = 'all' AND "
                                 "parameter = 'camera_elevation'", "--format", "csv"])
    assert result.exit_code == 0, result.output
    lines = result.output.strip().splitlines()
    assert lines[0] == "parameter,scope,boundary_low,boundary_high" and len(lines) == 2
    _, scope, low, high = lines[1].split(",")
    assert scope == "all" and float(low) <= THRESHOLD <= float(high)

    import sweep3d.results.sql as sql_module

    def refuse(*args, **kwargs):
        raise AssertionError("computed for a query that does not name it")

    monkeypatch.setattr(sql_module, "register_failure_boundaries", refuse)
    result = runner.invoke(app, ["query", str(elevation_spec), "SELECT count(*) AS n FROM results", "--format", "csv"])
    assert result.exit_code == 0 and result.output.split() == ["n", "400"]


def test_the_report_draws_the_boundary_with_its_band(elevation_spec: Path) -> None:
    loaded = load_spec(elevation_spec)
    store = Store(loaded.store)
    context = build_context(loaded, connect(store, loaded.name), store)
    ids = [p.id for p in context["panels"]]
    assert ids.index("boundaries") == ids.index("failure-modes") + 1
    data = next(p for p in context["panels"] if p.id == "boundaries").data
    assert data["figures"] and data["rows"][0]["who"] == "all results" and data["rows"][0]["significant"]
    overall = next(b for b in context["summary"].boundaries if b["scope"] == "all")
    assert overall["boundary_low"] <= THRESHOLD <= overall["boundary_high"]
    html = render_html(context)
    assert "fig-boundary-1" in html and "Failure boundaries" in html and "failure_boundaries" in html


@pytest.mark.browser
def test_the_boundary_panel_draws_in_chromium(elevation_spec: Path, chromium) -> None:
    from tests.helpers import ARTIFACTS, assert_clean, open_page

    path = write_report(load_spec(elevation_spec))
    with open_page(chromium, path) as (page, events):
        drawn = page.evaluate("Array.from(document.querySelectorAll('#boundaries .js-plotly-plot'))"
                              ".filter(d => d.querySelector('svg.main-svg')).map(d => d.id)")
        assert drawn and drawn[0] == "fig-boundary-1"
        figure = page.evaluate("""() => { const gd = document.getElementById('fig-boundary-1');
            return {names: gd.data.map(t => t.name), band: gd.layout.shapes[0], counts: gd.data[1].customdata}; }""")
        assert figure["names"] == ["step fit", "binned accuracy"]
        assert figure["band"]["x0"] <= THRESHOLD <= figure["band"]["x1"]
        assert sum(n for _, n in figure["counts"]) == rows_count(elevation_spec)
        assert "fails below" in page.inner_text("#boundaries")
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#boundaries").screenshot(path=str(ARTIFACTS / "report-boundaries.png"))
        assert_clean(path, events)


def rows_count(spec: Path) -> int:
    loaded = load_spec(spec)
    return connect(Store(loaded.store), loaded.name).execute("SELECT count(*) FROM results WHERE counted").fetchone()[0]


# -- the boundary policy -----------------------------------------------------------------------


def boundary_policy(**params):
    from sweep3d.stages.plan.policies import POLICIES

    cls = POLICIES.get("boundary")
    return cls(cls.Params(**params))


def run_rounds(policy, shape, seed: int, fails, rounds: int = 30):
    """Drive ``policy`` as the pipeline does: (every call's points, the final history)."""
    from sweep3d.stages.plan.policies import Outcome

    history: dict = {}
    calls = []
    for _ in range(rounds):
        points = policy.points(shape, seed, history)
        calls.append(points)
        if all(q in history for q in points):
            break
        history.update({q: Outcome(failed=fails(q), loss=float(fails(q))) for q in points if q not in history})
    return calls, history


def test_the_boundary_policy_is_a_pure_function_that_resumes_from_its_history() -> None:
    from sweep3d.spec.space import SpaceShape

    shape = SpaceShape(2, (3,), wraps=(False, True))
    policy = boundary_policy(samples=40, initial=8, batch=4)
    fails = lambda q: q.unit[0] < 0.2  # noqa: E731  (fails below a fifth of the first range)
    calls, history = run_rounds(policy, shape, 5, fails)
    final = calls[-1]
    assert len(final) == 40 and len(set(final)) == 40 and len(calls) == 1 + (40 - 8) // 4 + 1
    for earlier, later in zip(calls, calls[1:]):
        assert later[: len(earlier)] == earlier  # earlier rounds never change
    assert all(0 <= u <= 1 for q in final for u in q.unit) and all(0 <= q.choice[0] < 3 for q in final)
    again, _ = run_rounds(boundary_policy(samples=40, initial=8, batch=4), shape, 5, fails)
    assert again == calls  # deterministic for a seed
    assert run_rounds(policy, shape, 6, fails)[0][-1] != final  # and the seed matters
    # resumes: given the history a killed run left after any round, it proposes the same points
    for k, earlier in enumerate(calls[:-1]):
        known = {q: history[q] for q in earlier}
        assert policy.points(shape, 5, known) == calls[k + 1]
    assert policy.count(shape) == 40


def test_the_boundary_policy_spends_its_budget_where_the_boundary_is_uncertain() -> None:
    from sweep3d.spec.space import SpaceShape

    shape = SpaceShape(2, ())
    fails = lambda q: q.unit[1] < 0.3  # noqa: E731  (the second dimension matters, the first does not)
    policy = boundary_policy(samples=48, initial=16, batch=4)
    calls, history = run_rounds(policy, shape, 1, fails)
    later = calls[-1][16:]
    near = sum(abs(q.unit[1] - 0.3) < 0.1 for q in later)
    assert near / len(later) > 0.8  # against 0.2 for uniform sampling
    assert policy.target(shape, calls[-1], history)[0] == 1
    _, low, high = policy.target(shape, calls[-1], history)
    assert low <= 0.3 <= high and high - low < 0.01


def test_the_boundary_policy_explores_where_it_sees_no_step() -> None:
    from sweep3d.spec.space import SpaceShape

    shape = SpaceShape(1, ())
    calls, _ = run_rounds(boundary_policy(samples=32, initial=8, batch=8), shape, 2, lambda q: False)
    units = sorted(q.unit[0] for q in calls[-1][8:])
    assert units[0] < 0.2 and units[-1] > 0.8  # spread over the range, not aimed anywhere


def test_scenes_that_are_all_right_keep_their_successes_in_every_permutation() -> None:
    # a step in one scene; the other scenes all right (they add the same successes to each
    # permutation, as they do to the observed counts)
    rng = np.random.default_rng(4)
    x = np.tile(np.linspace(0, 60, 6), 40)
    scenes = np.repeat(np.arange(10), 24)
    correct = np.where(scenes == 0, (x >= 30) ^ (rng.random(240) < 0.1), True)
    fit = fit_step(x, correct, scenes, seed=3)
    assert fit.p_value < 0.01
    null = np.where(scenes == 0, rng.random(240) < 0.5, True)
    assert fit_step(x, null, scenes, seed=3).p_value > 0.05
