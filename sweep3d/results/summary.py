"""Summaries of a run's results, computed by DuckDB over the ``results`` view.

Accuracy counts only the results ``results.counted`` marks: valid predictions (a render or model
output with NaN/inf is excluded and counted separately, so no non-finite value is ever averaged in
silently) of jobs not known to be unevaluable (out of frame, or too little of the object visible:
counted apart, from the ``not_evaluable`` view, with the reason).

:func:`stored_summary` remembers a summary in the store, keyed by exactly the files and code it
was computed from, so a run that changed nothing prints its findings without computing them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import duckdb

from sweep3d.cache import Store, atomic_write, safe_filename
from sweep3d.core import UserError
from sweep3d.results.base_views import results_roles
from sweep3d.results.boundaries import Scale, boundary_rows
from sweep3d.results.rules import SUMMARY_LIMIT as RULES_LIMIT
from sweep3d.results.rules import rule_dict, rules_of
from sweep3d.results.views import connect, has_view, materialise, register_views

FAILURE_LIMIT = 48  # failures a summary lists, worst first
REGION_LIMIT = 3  # control values a summary names where the model fails, most certainly bad first
BOUNDARY_LIMIT = 3  # boundaries of single objects or environments a summary names, most certain first
#: Bump when :func:`summarise` gives other numbers for the same rows without a change to this
#: module or to the views' module (both are part of a remembered summary's key).
SUMMARY_FORMAT = 7


@dataclass
class ControlEffect:
    """Accuracy at each level (value or bin) of one parameter, with its 95 % Wilson interval."""

    column: str
    levels: list[int]  # level index in the ``control_levels`` view
    labels: list[str]
    accuracy: list[float | None]
    count: list[int]
    low: list[float | None]
    high: list[float | None]


@dataclass
class Summary:
    """What a run found. The jobs split into ``counted`` (their accuracy is ``accuracy``),
    ``invalid`` (NaN/inf outputs), ``not_evaluable`` (out of frame or hidden, whatever their
    prediction) and those without a prediction yet."""

    jobs: int
    evaluated: int  # results: jobs with a prediction
    invalid: int  # results with non-finite outputs, not counted as unevaluable
    correct: int
    accuracy: float | None
    objects: list[str]
    environments: list[str]
    scene_accuracy: list[list[float | None]]  # [object][environment]
    scene_count: list[list[int]]
    effects: list[ControlEffect] = field(default_factory=list)
    failures: list[dict[str, Any]] = field(default_factory=list)
    per_object: list[dict[str, Any]] = field(default_factory=list)
    counted: int = 0  # valid results of jobs not known to be unevaluable: what accuracy averages
    not_evaluable: int = 0  # jobs of the plan with evaluable = false (rendered or not)
    not_evaluable_reasons: dict[str, int] = field(default_factory=dict)  # reason -> jobs
    min_visible: float | None = None  # the threshold behind the reason "hidden" (None: no truth passes)
    #: control values significantly below the rest of their parameter (``failure_modes``), most certainly bad first
    regions: list[dict[str, Any]] = field(default_factory=list)
    #: when no value is significant: the one nearest to significance (see :func:`value_findings`)
    gap: dict[str, Any] | None = None
    #: significant failure boundaries (``failure_boundaries`` rows): every overall one, then the
    #: most certain of single objects and environments (see :func:`boundary_findings`)
    boundaries: list[dict[str, Any]] = field(default_factory=list)
    #: fits without a significant step (over all results, then objects and environments, in
    #: ``failure_boundaries`` order): where accuracy does not change along a control beyond
    #: chance (same fields as ``boundaries``, the boundary columns None)
    no_boundaries: list[dict[str, Any]] = field(default_factory=list)
    #: significant boundaries of single objects or environments beyond the ones named
    boundaries_left_out: int = 0
    #: those boundaries themselves (as ``boundaries``), in the same order: the findings list has them all
    boundaries_more: list[dict[str, Any]] = field(default_factory=list)
    #: failures whose verdict the stability check says changes no eye sees could flip (None: no check
    #: yet, or an evaluator without a margin); see ``results.fragile``
    fragile_failures: int | None = None
    fragile_threshold: float | None = None  # |margin| below which a result is fragile
    fragile_checked: int = 0  # images the stability check re-inferred
    fragile_dropped: int = 0  # fragile results left out of what is counted ([aggregate] drop_fragile)
    #: boxes over several parameters where the model fails more (``rules.rule_dict``; best first;
    #: none beyond ``rules.SUMMARY_LIMIT`` counted results)
    rules: list[dict[str, Any]] = field(default_factory=list)
    #: each level of each parameter as [parameter, label, value or bin centre, bin width when binned]
    #: (``control_accuracy``): what a failure mode's fresh twins are drawn around
    levels: list[list[Any]] = field(default_factory=list)

    @property
    def wrong(self) -> int:
        """Counted results that are not correct."""
        return self.counted - self.correct


def summarise(con: duckdb.DuckDBPyConnection, columns: list[str], failure_limit: int = FAILURE_LIMIT,
              scales: dict[str, Scale] | None = None) -> Summary:
    """Summarise the ``results`` view of ``con`` (see :func:`~sweep3d.results.connect`).

    ``results`` and the levels are computed once into temp tables that the views then read (as
    the report does, :func:`~sweep3d.results.views.materialise`): the queries here read
    them several times.

    Args:
        columns: the control-parameter columns of the jobs table.
        scales: the numeric parameters of the spec (``boundaries.numeric_scales``), whose failure
            boundaries the summary names; None: the numeric parameters the level views bin.
    """
    jobs = con.execute("SELECT count(*) FROM jobs").fetchone()[0] if has_view(con, "jobs") else 0
    if not has_view(con, "results"):
        return Summary(jobs, 0, 0, 0, None, [], [], [], [])
    if not has_view(con, "control_accuracy"):  # a connection made without results.connect
        register_views(con)
    # failure_modes (the significant values) reads the levels and their pairs several times
    materialise(con, ["results", "control_stats", "control_levels", "control_parameters", "control_accuracy",
                      "pair_accuracy"])
    # ``results`` holds the experiment's evaluator's columns only; its roles say which are which.
    have = {row[0] for row in con.execute("DESCRIBE results").fetchall()}
    roles = results_roles(con)
    unevaluable = "evaluable IS FALSE" if "evaluable" in have else "false"
    evaluated, counted, invalid, correct = con.execute(
        f"SELECT count(*), count(*) FILTER (WHERE counted), count(*) FILTER (WHERE NOT valid AND NOT ({unevaluable})), "
        "count(*) FILTER (WHERE counted AND correct) FROM results"
    ).fetchone()
    accuracy = correct / counted if counted else None
    reasons, min_visible = not_evaluable_reasons(con)

    objects = [r[0] for r in con.execute("SELECT DISTINCT object FROM jobs ORDER BY 1").fetchall()]
    environments = [r[0] for r in con.execute("SELECT DISTINCT environment FROM jobs ORDER BY 1").fetchall()]
    cells = {
        (o, e): (acc, n)
        for o, e, acc, n in con.execute(
            "SELECT object, environment, accuracy, n FROM scene_accuracy WHERE n > 0"
        ).fetchall()
    }
    scene_accuracy = [[cells.get((o, e), (None, 0))[0] for e in environments] for o in objects]
    scene_count = [[cells.get((o, e), (None, 0))[1] for e in environments] for o in objects]

    effects = control_effects(con, columns)
    shown = ["top1_label", "topk_labels", "topk_probs", "loss"]
    picked = ", ".join(name if name in have else f"NULL AS {name}" for name in shown)
    worst = "loss DESC" if roles.has("loss") else "iou NULLS FIRST" if roles.has("iou") else "job"
    failures = [
        dict(zip(["job", "object", "environment", "image_key", *shown], r))
        for r in con.execute(
            f"SELECT job, object, environment, image_key, {picked} "
            f"FROM results WHERE counted AND NOT correct ORDER BY {worst}, job LIMIT ?", [failure_limit]
        ).fetchall()
    ]
    top1 = "top1_label" if roles.has("prediction") else "NULL::VARCHAR"
    per_object = [
        dict(zip(["object", "accuracy", "count", "top_wrong"], r))
        for r in con.execute(
            "SELECT object, avg(correct::DOUBLE), count(*), "
            f"mode({top1}) FILTER (WHERE NOT correct) FROM results WHERE counted GROUP BY 1 ORDER BY 1"
        ).fetchall()
    ]
    min_count = region_min_count(counted)
    regions, gap = value_findings(con, columns, min_count)
    boundaries, no_boundaries, more = boundary_findings(con, scales)
    rules = [rule_dict(rule) for rule in rules_of(con)] if counted <= RULES_LIMIT else []
    return Summary(jobs, evaluated, invalid, correct, accuracy, objects, environments, scene_accuracy,
                   scene_count, effects, failures, per_object, counted, sum(reasons.values()), reasons, min_visible,
                   regions, gap, boundaries, no_boundaries, len(more), more, *fragile_findings(con, have), rules,
                   level_values(con))


def level_values(con: duckdb.DuckDBPyConnection) -> list[list[Any]]:
    """[parameter, label, value or bin centre, bin width when binned] of each level present
    (``control_accuracy`` with ``control_stats``); none without those views."""
    if not has_view(con, "control_accuracy"):
        return []
    rows = con.execute("SELECT a.parameter, a.label, a.value, CASE WHEN s.binned THEN s.width END "
                       "FROM control_accuracy a JOIN control_stats s USING (parameter, position) "
                       "WHERE NOT a.absent ORDER BY a.parameter, a.label").fetchall()
    return [[p, label, value, width] for p, label, value, width in rows]


def fragile_findings(con: duckdb.DuckDBPyConnection, have: set[str]) -> tuple[int | None, float | None, int, int]:
    """(fragile failures, threshold, images checked, fragile results not counted) of the model
    ``results`` shows; (None, None, 0, 0) before any stability check (or without a margin)."""
    if "fragile" not in have or not has_view(con, "fragile_threshold"):
        return None, None, 0, 0
    model = con.execute("SELECT any_value(model) FROM results").fetchone()[0] if "model" in have else None
    found = con.execute("SELECT threshold, checked FROM fragile_threshold WHERE model IS NOT DISTINCT FROM ?",
                        [model]).fetchone()
    if found is None:
        return None, None, 0, 0
    before = "counted_with_fragile" if "counted_with_fragile" in have else "counted"
    fragile, dropped = con.execute(
        f"SELECT count(*) FILTER (WHERE {before} AND NOT correct AND fragile), "
        f"count(*) FILTER (WHERE {before} AND NOT counted) FROM results").fetchone()
    return int(fragile), float(found[0]), int(found[1]), int(dropped)


#: What the findings keep of a boundary (``failure_boundaries`` columns).
_BOUNDARY_FIELDS = ("parameter", "scope", "object", "environment", "n", "values", "fails", "estimate", "boundary",
                    "boundary_low", "boundary_high", "accuracy_below", "n_below", "accuracy_above", "n_above",
                    "q_value")


def boundary_findings(con: duckdb.DuckDBPyConnection, scales: dict[str, Scale] | None,
                      limit: int = BOUNDARY_LIMIT) -> tuple[list[dict[str, Any]], list[dict[str, Any]],
                                                            list[dict[str, Any]]]:
    """The significant failure boundaries: each parameter's over all results (spec order), then
    at most ``limit`` of single objects or environments, most certain first (smallest q-value,
    then the narrowest interval relative to the parameter's overall span); the fits without one,
    in the view's order; and the significant ones of single groups left out (same order)."""
    fits = boundary_rows(con, scales)
    rows = [row for row in fits if row["significant"]]
    overall = [row for row in rows if row["scope"] == "all"]
    groups = sorted((row for row in rows if row["scope"] != "all"),
                    key=lambda r: (r["q_value"], r["boundary_high"] - r["boundary_low"], r["position"]))
    flat = [row for row in fits if not row["significant"]]
    return ([{k: row[k] for k in _BOUNDARY_FIELDS} for row in overall + groups[:limit]],
            [{k: row[k] for k in _BOUNDARY_FIELDS} for row in flat],
            [{k: row[k] for k in _BOUNDARY_FIELDS} for row in groups[limit:]])


RULE_LIMIT = 2  # rules over several parameters a summary names


def named_rules(summary: Summary, limit: int = RULE_LIMIT) -> list[dict[str, Any]]:
    """The rules ``run`` names: boxes of two conditions or more whose discovery p-value, adjusted
    for every box the search scored (Bonferroni), is below 0.05; best first, at most ``limit``."""
    from sweep3d.results.compare import ALPHA

    return [r for r in summary.rules if len(r["conditions"]) >= 2 and r["p_adjusted"] < ALPHA][:limit]


def rules_left_out(summary: Summary, limit: int = RULE_LIMIT) -> int:
    """How many boxes :func:`named_rules` would name but for ``limit`` (the findings view lists them)."""
    return len(named_rules(summary, limit=len(summary.rules))) - len(named_rules(summary, limit))


def region_min_count(counted: int) -> int:
    """The fewest counted results a region needs to be tested as a failure mode: 5 % of the
    counted results, between 2 and 10 (the report and the printed findings use the same)."""
    return min(10, max(2, counted // 20))


#: What the findings say of each value (``failure_modes`` columns, renamed).
_REGION_FIELDS = {"parameter_a": "column", "label_a": "label", "accuracy": "accuracy", "n": "count",
                  "accuracy_rest": "accuracy_rest", "n_rest": "count_rest", "difference": "difference",
                  "difference_low": "difference_low", "difference_high": "difference_high", "q_value": "q_value"}


def value_findings(con: duckdb.DuckDBPyConnection, columns: list[str], min_count: int,
                   limit: int = REGION_LIMIT) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
    """What the findings say of single values (of ``columns``, object and environment), from one
    evaluation of ``failure_modes`` (at 10⁶ results, seconds each):

    - those significantly below the rest of their parameter, as it ranks them (at most ``limit``);
    - when there are none, the one nearest to significance (the smallest p-value) among those
      below the rest but not significantly, so a run with no failure mode says what it saw (the
      report's panel names the same one); else None.
    """
    names = ", ".join(_REGION_FIELDS)
    rows = con.execute(
        f"SELECT {names}, significant, p_value FROM failure_modes(min_count := ?) "
        "WHERE size = 1 AND list_contains(?, parameter_a)", [min_count, ["object", "environment", *columns]]
    ).fetchall()
    found = [(dict(zip(_REGION_FIELDS.values(), row)), significant, p) for *row, significant, p in rows]
    significant = [values for values, is_significant, _ in found if is_significant][:limit]
    misses = sorted(((p, values["difference"], i) for i, (values, is_significant, p) in enumerate(found)
                     if not is_significant))
    nearest = found[misses[0][2]][0] if misses and not significant else None
    return significant, nearest


def not_evaluable_reasons(con: duckdb.DuckDBPyConnection) -> tuple[dict[str, int], float | None]:
    """Unevaluable jobs per reason (from the ``not_evaluable`` view, reasons in name order) and the
    plan's ``min_visible`` behind them; ``({}, None)`` when the store cannot tell."""
    if not has_view(con, "not_evaluable"):
        return {}, None
    rows = con.execute("SELECT reason, sum(n)::BIGINT, any_value(min_visible) FROM not_evaluable "
                       "GROUP BY reason ORDER BY reason").fetchall()
    thresholds = {row[2] for row in rows if row[2] is not None}
    return {reason: int(n) for reason, n, _ in rows}, (thresholds.pop() if thresholds else None)



def control_effects(con: duckdb.DuckDBPyConnection, columns: list[str]) -> list[ControlEffect]:
    """Accuracy per level of each of ``columns`` that takes two levels or more, in that order.

    Read from the ``control_accuracy`` view (levels and bins as defined there), which has a row
    per level of each parameter: its rows per parameter are ``control_parameters.levels``,
    counted here without computing the levels a second time.
    """
    rows = con.execute(
        "SELECT parameter, level, label, accuracy, n, wilson_low, wilson_high FROM ("
        "SELECT *, count(*) OVER (PARTITION BY parameter) AS levels FROM control_accuracy "
        "WHERE list_contains(?, parameter)) WHERE levels > 1 ORDER BY level", [columns]
    ).fetchall()
    effects = {c: ControlEffect(c, [], [], [], [], [], []) for c in columns}
    for column, level, label, accuracy, count, low, high in rows:
        effect = effects[column]
        for values, value in ((effect.levels, level), (effect.labels, label), (effect.accuracy, accuracy),
                              (effect.count, count), (effect.low, low), (effect.high, high)):
            values.append(value)
    return [e for e in effects.values() if e.levels]


@dataclass(frozen=True)
class Region:
    """One control parameter's value (or bin) where the model does worse than at the parameter's
    other values: its accuracy and count, the rest's, and the difference with its 95 % interval."""

    column: str
    label: str
    accuracy: float
    count: int
    accuracy_rest: float
    count_rest: int
    difference: float
    difference_low: float
    difference_high: float
    q_value: float


def weakest_regions(summary: Summary, top: int = REGION_LIMIT) -> list[Region]:
    """The control values significantly below the rest of their parameter (one-sided exact test,
    Benjamini–Hochberg over every region tested, as in ``failure_modes``), most certainly bad
    first; none when no value is."""
    return [Region(**r) for r in summary.regions[:top]]


def nearest_miss_region(summary: Summary) -> Region | None:
    """The value nearest to significance, not significant (None if no value is below the rest)."""
    return Region(**summary.gap) if summary.gap else None


# -- remembered summaries ---------------------------------------------------------------------


def stored_summary(store: Store, experiment: str, columns: list[str], failure_limit: int = FAILURE_LIMIT,
                   scales: dict[str, Scale] | None = None) -> Summary:
    """:func:`summarise` of ``experiment``'s results in ``store``, remembered there.

    The summary reads the experiment's jobs file, the ``predictions`` segments and the ``truths``
    segments (``results`` is their join; ``evaluable`` comes from the truths) and nothing else.
    It is remembered under ``cache/summary/`` with a key of those files' states (name, size, modification and change times, inode: a segment or jobs
    file rewritten in any way is a new state, as for the blob memo of
    :func:`sweep3d.cache.blobs.damaged_blobs`), the arguments, this module's and the views'
    source and DuckDB's version; a remembered summary is used only under the same key, so an
    unchanged store gives the summary it gave before, and any new segment, compaction or plan
    computes it again. A summary that cannot be remembered (a full disk, a value JSON does not
    hold) is computed every time.
    """
    key = summary_key(store, experiment, columns, failure_limit, scales)
    path = summary_path(store, experiment)
    remembered = _read_summary(path, key)
    if remembered is not None:
        return remembered
    con = connect(store, experiment, read_once=True)
    try:
        summary = summarise(con, columns, failure_limit, scales)
    finally:
        con.close()
    try:
        text = json.dumps({"key": key, "summary": dataclasses.asdict(summary)}, allow_nan=False)
        atomic_write(path, text.encode())
    except (TypeError, ValueError, OSError, UserError):
        pass  # not remembered: computed again next time
    return summary


def summary_path(store: Store, experiment: str) -> Path:
    """Where the summary of ``experiment`` is remembered."""
    return store.root / "cache" / "summary" / f"{safe_filename(experiment)}.json"


def summary_key(store: Store, experiment: str, columns: list[str], failure_limit: int = FAILURE_LIMIT,
                scales: dict[str, Scale] | None = None) -> str:
    """What a summary of ``experiment`` is computed from, as a hex digest (see :func:`stored_summary`)."""
    files = [store.jobs_path(experiment), *store.segments("predictions"), *store.segments("truths"),
             *store.segments("stability")]  # the stability check's rows say which results are fragile
    states = []
    for path in files:
        try:
            st = os.stat(path)
            states.append([path.name, st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino])
        except OSError:
            states.append([path.name, None])
    # every module of this package (a view's code: class names, boundaries, ... changes what is
    # summarised) and the step fit the boundaries view imports from the planner
    here = Path(__file__).parent
    sources = [path.read_bytes() for path in [*sorted(here.glob("*.py")), here.parent / "stages" / "plan" / "step_fit.py"]]
    code = hashlib.sha256(b"\0".join(sources)).hexdigest()
    described = {"format": SUMMARY_FORMAT, "experiment": experiment, "columns": list(columns),
                 "failure_limit": failure_limit, "files": states, "code": code, "duckdb": duckdb.__version__,
                 "scales": None if scales is None else {c: dataclasses.astuple(s) for c, s in sorted(scales.items())}}
    return hashlib.sha256(json.dumps(described, sort_keys=True).encode()).hexdigest()


def _read_summary(path: Path, key: str) -> Summary | None:
    """The summary remembered at ``path`` under ``key``; None when there is none, it was
    remembered under another key, or it does not read back."""
    try:
        stored = json.loads(path.read_bytes())
        if not isinstance(stored, dict) or stored.get("key") != key:
            return None
        fields = dict(stored["summary"])
        effects = [ControlEffect(**effect) for effect in fields.pop("effects")]
        return Summary(**fields, effects=effects)
    except (OSError, ValueError, TypeError, KeyError):
        return None
