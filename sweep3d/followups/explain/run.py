"""``sweep3d explain``: run the nearest-fix search (:mod:`.search`) on a finished run's failures,
its probes answered through the stages (render → postprocess → infer).

Each round of probes becomes a plan of its own: the spec with a listing policy that gives
exactly those configurations (as the ``table`` policy lists a design's jobs), planned for the
run's model, so its keys are the keys any run would give the same configurations. The stages
compute what the store lacks and skip the rest: a probe that a run or an earlier ``explain``
made costs nothing, and a search killed and started again replays its rounds from the cache
and goes on. The experiment's jobs table is left alone: the probes are not the experiment's
jobs (the accuracy would lean towards right answers); what the search found goes to the store's
``counterfactuals`` table (:mod:`.stored`), read by the ``counterfactuals`` views.
"""

from __future__ import annotations

import dataclasses
import math
import shlex
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
from rich.console import Console
from rich.markup import escape

from sweep3d.cache import Store
from sweep3d.core import UserError
from sweep3d.driver import Job, Plan
from sweep3d.followups.explain.fragility import Rule, read_rule
from sweep3d.followups.explain.further import Judged, needs_further, search_further
from sweep3d.followups.explain.search import Axis, Config, Fix, Progress, explain
from sweep3d.followups.explain.sentence import fix_sentence, move_words, share_words
from sweep3d.followups.explain.stored import write_counterfactuals
from sweep3d.results import COUNTERFACTUALS, create_margin_macro, margin_sql, no_results
from sweep3d.runner import Runner, plan_spec, plans_as_run, running
from sweep3d.spec import LoadedSpec, Point, Range, SearchSpace
from sweep3d.stages.infer import ModelHandle
from sweep3d.stages.plan import Listed, Policy, PolicyParams
from sweep3d.stages.render import LOCAL, Executor

CONCURRENT = 16  # failures searched together when the budget allows
SHOWN = 10  # sentences the console prints, nearest first (the rest: the report and the query)


@dataclass(frozen=True)
class Verdict:
    """What the model did on one job: ``right`` is valid, evaluable (in frame, enough of the
    object visible) and correct."""

    right: bool
    evaluable: bool = True
    label: str | None = None
    correct: bool | None = None
    loss: float | None = None
    probability: float | None = None  # of the true class, when the evaluator records it
    margin: float | None = None  # that probability less the best other class's


@dataclass
class ExplainResult:
    """What ``explain`` did: the fixes (one per failure searched), how many failures the run had,
    the probes asked and renders made, and the seconds it took; where its rows are kept (the
    table's folder) and the rows (each with its ``sentence``), the stability check's threshold
    (None: no check) and the search's resolution."""

    fixes: list[Fix]
    failures: int
    probes: int
    charged: int
    rendered: int
    seconds: float
    path: Any = None
    rows: list[dict[str, Any]] = field(default_factory=list)
    threshold: float | None = None
    resolution: float = 1 / 64

    @property
    def found(self) -> int:
        return sum(f.fix is not None for f in self.fixes)


class _Listing(Policy):
    """Lists exactly the configurations of one round (as the ``table`` policy lists a design)."""

    lists_jobs = True

    def __init__(self, configs: Sequence[Config]) -> None:
        super().__init__(PolicyParams())
        self.by_scene: dict[tuple[str, str], list[Point]] = {}
        for config in configs:
            self.by_scene.setdefault(config.scene, []).append(config.point)

    def listed(self, space: SearchSpace, object_name: str, environment: str) -> Listed:
        points = self.by_scene.get((object_name, environment), [])
        unit = np.array([p.unit for p in points], dtype=np.float64).reshape(len(points), len(space.continuous))
        choice = np.array([p.choice for p in points], dtype=np.int64).reshape(len(points), len(space.discrete))
        return Listed(unit, choice, {})

    def count(self, shape) -> None:
        return None


def scene_axes(spec: LoadedSpec, scene: tuple[str, str]) -> tuple[SearchSpace, list[Axis]]:
    """A scene's open parameters, as the planner orders them (ranges, then lists)."""
    space = SearchSpace([c for c in spec.controls if c.applies_to(*scene)])
    axes = [Axis(dim.column, "range", i, wraps=dim.wraps) for i, dim in enumerate(space.continuous)]
    axes += [Axis(dim.column, "list", i, size=len(dim.space.options)) for i, dim in enumerate(space.discrete)]
    return space, axes


class _Stages:
    """The runner's stages a round's plan goes through, kept open (Blender workers stay warm) for the search."""

    def __init__(self, spec: LoadedSpec, runner: Runner, model: ModelHandle) -> None:
        self.spec, self.runner, self.model = spec, runner, model
        self.store, self.post = runner.store, runner.post
        self.rendered = 0
        self.plans: list[Plan] = []
        self.fix_plan: Plan | None = None  # the fixes, planned together once the search ends
        self.seen: dict[Config, tuple[Verdict, str | None]] = {}  # every probe's verdict and prediction key

    def plan(self, configs: Sequence[Config]) -> Plan:
        return plan_spec(dataclasses.replace(self.spec, policy=_Listing(configs)), self.model)

    def verdicts(self, configs: list[Config]) -> list[bool]:
        plan = self.plan(configs)
        outcomes = self.runner.run(plan, self.model)  # the model tried first: a broken one fails before a render
        self.rendered += next((o.computed for o in outcomes if o.stage == "render"), 0)
        self.plans.append(plan)
        found = read_verdicts(plan, self.store)
        by_config = {Config(job.scene, job.point): (found.get(job.pred_key, Verdict(False)), job.pred_key)
                     for job in plan.jobs}  # out of frame: not a fix
        for config in configs:
            self.seen[config] = by_config.get(config, (Verdict(False), None))
        return [self.seen[c][0].right for c in configs]

    def judged(self, rule: Rule) -> Callable[[list[Config]], list[Judged]]:
        """The further search's judge: right, the margin, and whether the rule calls it fragile."""
        def judge(configs: list[Config]) -> list[Judged]:
            self.verdicts(configs)
            return [self.judge(config, rule) for config in configs]
        return judge

    def judge(self, config: Config, rule: Rule) -> Judged:
        verdict, key = self.seen.get(config, (Verdict(False), None))
        return Judged(verdict.right, verdict.margin, rule.fragile(verdict.margin, key) if verdict.right else None)


def read_verdicts(plan: Plan, store: Store, jobs: Sequence[Job] | None = None) -> dict[str, Verdict]:
    """The verdict of each in-frame job of ``plan`` (or of ``jobs``) with a prediction, by pred key."""
    jobs = list(plan.jobs if jobs is None else jobs)
    if not jobs or not store.segments("predictions"):
        return {}
    roles = plan.evaluator_record().roles
    con = store.connect()
    try:
        present = {row[0] for row in con.execute("DESCRIBE predictions").fetchall()}
        label = f'"{roles.prediction}"' if roles.prediction else "NULL"
        loss = f'"{roles.loss}"' if roles.loss else "NULL"
        prob = "label_prob" if "label_prob" in present else "NULL"
        margin = margin_sql(present, prefix="")  # the results' own margin: one meaning everywhere
        if margin is not None:
            create_margin_macro(con)
        rows = con.execute(
            f'SELECT pred_key, "{roles.valid}", "{roles.correct}", {label}, {loss}, {prob}, {margin or "NULL"} '
            "FROM predictions WHERE pred_key IN (SELECT unnest(?))", [[j.pred_key for j in jobs]]).fetchall()
        hidden = _hidden(jobs, store, con, plan.spec.evaluator.min_visible)
    finally:
        con.close()
    out = {}
    truth_of = {j.pred_key: j.truth_key for j in jobs}
    for key, valid, correct, name, loss_value, probability, margin_value in rows:
        evaluable = truth_of.get(key) not in hidden
        out[key] = Verdict(bool(valid and correct) and evaluable, evaluable, name, bool(correct) if valid else None, _finite(loss_value),
                           _finite(probability), _finite(margin_value) if valid else None)
    return out


def _hidden(jobs: Sequence[Job], store: Store, con, min_visible: float) -> set[str]:
    keys = [j.truth_key for j in jobs if j.truth_key is not None]
    if not keys or not store.segments("truths"):
        return set()
    return {r[0] for r in con.execute(
        "SELECT truth_key FROM truths WHERE truth_key IN (SELECT unnest(?)) AND coalesce(visible_fraction, 0) < ?",
        [keys, min_visible]).fetchall()}


def _finite(value: Any) -> float | None:
    return float(value) if value is not None and math.isfinite(float(value)) else None


def run_failures(spec: LoadedSpec, store: Store) -> tuple[Plan, list[Job]]:
    """The run's plan (first model) and its failures: evaluable jobs the model got wrong.

    Raises:
        UserError: the spec has not run to its end (some job has no result yet).
    """
    plan = plans_as_run(spec, store)[0]
    verdicts = read_verdicts(plan, store)
    missing = sum(job.pred_key not in verdicts for job in plan.jobs)
    if missing:
        raise UserError(f"{spec.path}: {missing} of {len(plan.jobs)} jobs have no result yet; explain extends a "
                        f"finished run: run `sweep3d run {spec.path}` first")
    failures = [job for job in plan.jobs if verdicts[job.pred_key].evaluable and verdicts[job.pred_key].correct is False]
    return plan, failures


def explain_spec(spec: LoadedSpec, *, budget: int | None = None, seed: int | None = None,
                 console: Console | None = None, wait: float = 0.0, resolution: float = 1 / 64,
                 executor: Executor = LOCAL) -> ExplainResult:
    """Search the nearest fix of the run's failures (a seeded sample within ``budget`` renders)
    and write the counterfactuals; resumable, its probes cached like any job.

    Raises:
        UserError: a budget below 1, no store (nothing made: explain extends a finished run), or a
            run that has not finished.
    """
    if budget is not None and budget < 1:
        raise UserError(f"--budget {budget}: give how many new configurations the search may render, 1 or more")
    seed = spec.experiment.seed if seed is None else seed
    store = Store(spec.store)
    if not spec.store.is_dir():  # before the lock would make the store's folder
        raise no_results(store, spec.name, spec.path)
    store.ensure_writable()
    with running(spec, executor=executor, wait=wait, console=console, store=store, keep_open=True) as runner:
        started = time.perf_counter()
        plan, failures = run_failures(spec, store)
        rule = read_rule(spec) if failures else Rule()
        model = ModelHandle.resolve(spec)
        axes = {scene: scene_axes(spec, scene)[1] for scene in plan.jobs.scenes()} if failures else {}
        own = {Config(job.scene, job.point) for job in plan.jobs + plan.out_of_frame}
        by_config = {Config(job.scene, job.point): job for job in failures}
        state = Progress(len(failures))
        stages = _Stages(spec, runner, model)
        fixes = explain(list(by_config), axes.__getitem__, stages.verdicts, budget=budget, seed=seed,
                        free=own.__contains__, resolution=resolution, concurrent=_together(budget, axes),
                        on_round=_reporter(console, budget, started, state, lambda: stages.rendered))
        fixes = [_marked(fix, stages, rule) for fix in fixes]
        fixes = _further(fixes, axes, stages, rule, own, budget, state, resolution, console)
        rows = _rows(spec, plan, stages, fixes, by_config, seed, budget, rule, resolution)
        write_counterfactuals(store, spec.name, rows)
        path = store.table_dir(COUNTERFACTUALS)
        _write_images(spec, store, stages, [by_config[f.failure].image_key for f in fixes])
        return ExplainResult(fixes, len(failures), state.probes, state.charged, stages.rendered,
                             time.perf_counter() - started, path, rows, rule.threshold, resolution)


def _marked(fix: Fix, stages: _Stages, rule: Rule) -> Fix:
    """A fix with its margin and whether the stability check's rule calls it fragile."""
    if fix.fix is None:
        return fix
    judged = stages.judge(fix.fix, rule)
    return dataclasses.replace(fix, margin=judged.margin, fragile=judged.fragile)


def _further(fixes: list[Fix], axes: dict[tuple[str, str], list[Axis]], stages: _Stages, rule: Rule,
             own: set[Config], budget: int | None, state: Progress, resolution: float,
             console: Console | None) -> list[Fix]:
    """Search past each fragile fix (:mod:`.further`) within what the budget has left; a probe the
    run or the search already made costs nothing."""
    fragile = sum(needs_further(f) for f in fixes)
    if not fragile:
        return fixes
    if console is not None:
        console.print(f"[bold]explain[/] {fragile} of {sum(f.fix is not None for f in fixes)} fixes are fragile "
                      f"(|margin| < {rule.threshold:.3g}, the stability check's threshold, or flipped in the check): "
                      "searching further along their changes", highlight=False, soft_wrap=True)
    left = None if budget is None else max(budget - state.charged, 0)
    asked = len(stages.seen)
    done = search_further(fixes, axes.__getitem__, stages.judged(rule), budget=left,
                          free=lambda c: c in own or c in stages.seen, resolution=resolution)
    state.probes += len(stages.seen) - asked  # those the search had not asked already
    state.charged += done.charged
    return done.fixes


def _together(budget: int | None, axes: dict[tuple[str, str], list[Axis]]) -> int:
    """How many failures to search at once: 16 (bigger batches render faster), fewer under a budget
    that could not finish them all (about a dozen probes per range, one per other list option)."""
    if budget is None or not axes:
        return CONCURRENT
    cost = max(sum(12 if a.kind == "range" else a.size - 1 for a in scene) for scene in axes.values())
    return max(1, min(CONCURRENT, budget // max(cost, 1)))


def _reporter(console: Console | None, budget: int | None, started: float, state: Progress,
              rendered: Callable[[], int]):
    """A line per round: failures searched and fixed, probes (how many rendered, the rest found in
    the store), configurations charged to the budget, and the rate."""
    def report(now: Progress) -> None:
        state.__dict__.update(now.__dict__)  # the counts, for the result
        if console is None:
            return
        seconds = max(time.perf_counter() - started, 1e-9)
        of = f" of {budget}" if budget is not None else ""
        console.print(f"[bold]explain[/] round {now.rounds}: {now.finished}/{now.failures} failures done "
                      f"({now.found} fixed, {now.started - now.finished} searching), {now.probes} probes "
                      f"({rendered()} rendered, the rest cached), "
                      f"{now.charged}{of} new configurations, {now.probes / seconds:.2f} probes/s",
                      highlight=False, soft_wrap=True)
    return report


def _rows(spec: LoadedSpec, plan: Plan, stages: _Stages, fixes: list[Fix], by_config: dict[Config, Job],
          seed: int, budget: int | None, rule: Rule, resolution: float) -> list[dict[str, Any]]:
    """One counterfactuals row per failure searched, with its sentence."""
    fix_jobs = _fix_jobs(stages, fixes)
    failure_verdicts = read_verdicts(plan, stages.store, [by_config[f.failure] for f in fixes])
    fix_verdicts = read_verdicts(stages.fix_plan or plan, stages.store, list(fix_jobs.values()))
    rows = []
    for fix in fixes:
        job = by_config[fix.failure]
        space, _ = scene_axes(spec, job.scene)
        before = _verdict_columns("failure", failure_verdicts.get(job.pred_key))
        fixed = fix_jobs.get(fix.fix) if fix.fix is not None else None
        after = _verdict_columns("fix", fix_verdicts.get(fixed.pred_key) if fixed else None)
        changes = _changes(space, fix) if fix.fix is not None else []
        nearest = _changes(space, fix.nearest) if fix.nearest is not None else []
        row = {
            "experiment": spec.name, "model": plan.model or spec.model.label, "failure_job": job.index,
            "object": job.object, "environment": job.environment,
            "true_labels": ", ".join(map(str, spec.labels.get(job.object, ()))),
            "failure_pred_key": job.pred_key, "failure_image_key": job.image_key, **before,
            "found": fix.fix is not None, "complete": fix.complete, "probes": fix.probes,
            "fix_render_key": fixed.render_key if fixed else None, "fix_image_key": fixed.image_key if fixed else None,
            "fix_pred_key": fixed.pred_key if fixed else None, **after,
            "parameters": [c[0] for c in changes], "from_values": [c[1] for c in changes],
            "to_values": [c[2] for c in changes], "deltas": [c[3] for c in changes],
            "shares": [c[4] for c in changes], "n_changed": len(changes),
            "distance": fix.distance if fix.fix is not None else None,
            "change": "; ".join(_written(c) for c in changes) if changes else None,
            "seed": seed, "budget": budget,
            "fix_fragile": fix.fragile, "fragile_threshold": rule.threshold, "further_probes": fix.further,
            "nearest_distance": fix.nearest.distance if fix.nearest else None,
            "nearest_margin": fix.nearest.margin if fix.nearest else None,
            "nearest_change": " and ".join(move_words(*c[:4]) for c in nearest) if nearest else None,
            "resolution": resolution, "resolutions": _resolutions(space, fix, changes, resolution),
        }
        row["sentence"] = fix_sentence(row)
        rows.append(row)
    return rows


def _fix_jobs(stages: _Stages, fixes: list[Fix]) -> dict[Config, Job]:
    """The job of each fix, planned once more together (the same keys as when it was probed)."""
    configs = [f.fix for f in fixes if f.fix is not None]
    if not configs:
        return {}
    plan = stages.fix_plan = stages.plan(configs)
    return {Config(job.scene, job.point): job for job in plan.jobs}


def _verdict_columns(side: str, verdict: Verdict | None) -> dict[str, Any]:
    verdict = verdict or Verdict(False)
    return {f"{side}_label": verdict.label, f"{side}_correct": verdict.correct, f"{side}_loss": verdict.loss,
            f"{side}_probability": verdict.probability, f"{side}_margin": verdict.margin}


def _changes(space: SearchSpace, fix: Fix) -> list[tuple[str, str, str, float | None, float]]:
    """(column, from, to, delta in the parameter's units or None, signed share of its range) per move."""
    moved = {m.axis: m.share for m in fix.moves}
    before, after = space.values(fix.failure.point), space.values(fix.fix.point)
    out = []
    for dim in [*space.continuous, *space.discrete]:
        if dim.column not in moved:
            continue
        a, b = before[dim.control_id][dim.param], after[dim.control_id][dim.param]
        delta = None
        if isinstance(dim.space, Range) or (_number(a) and _number(b)):
            delta = float(b) - float(a)
            if dim.wraps and dim.period:  # the short way round: +20° across ±180°, not −340°
                delta = (delta + dim.period / 2) % dim.period - dim.period / 2
        out.append((dim.column, _text(a), _text(b), delta, moved[dim.column]))
    return out


def _resolutions(space: SearchSpace, fix: Fix, changes: list[tuple[str, str, str, float | None, float]],
                 resolution: float) -> list[float | None]:
    """Per parameter changed, the search's resolution in its own units: how far the fix may lie
    past where the model's answer changes (the last wrong probe is within ``resolution`` of the
    range before it); on a log range, that step at the fix; None for a list option."""
    ranges = {dim.column: (i, dim) for i, dim in enumerate(space.continuous)}
    out: list[float | None] = []
    for column, *_, share in changes:
        if column not in ranges:
            out.append(None)
            continue
        i, dim = ranges[column]
        if not dim.space.log:
            out.append(resolution * (dim.space.high - dim.space.low))
            continue
        u = fix.fix.point.unit[i]
        back = min(max(u - math.copysign(resolution, share), 0.0), 1.0)
        out.append(abs(float(dim.space.at(u)) - float(dim.space.at(back))))
    return out


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _text(value: Any) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def _written(change: tuple[str, str, str, float | None, float]) -> str:
    """``orientation_yaw +14 (3.9 % of its range)`` or ``environment_x studio → city``."""
    column, a, b, delta, share = change
    if delta is None:
        return f"{column} {a} → {b} ({abs(share):.0%} along its list)"
    return f"{column} {delta:+.3g} ({abs(share):.1%} of its range)"


def _write_images(spec: LoadedSpec, store: Store, stages: _Stages, failure_keys: list[str]) -> None:
    """The failures' and fixes' images as blobs (the report shows them side by side), where the
    run made them in memory only (``[postprocess] store = "none"``)."""
    from sweep3d.runner import write_plan_images, write_unstored_images

    if stages.post.store_images or not failure_keys:
        return
    write_unstored_images(spec, store, failure_keys)
    if stages.fix_plan is not None:
        write_plan_images(store, stages.fix_plan)


def print_explained(console: Console, result: ExplainResult, spec: Any = "SPEC") -> None:
    """The end of ``sweep3d explain``: what was found, the sentences of the nearest fixes (the first
    :data:`SHOWN`, and how many more), which are fragile, and where to read them (``spec``: its path)."""
    searched = len(result.fixes)
    complete = sum(f.complete for f in result.fixes)
    console.print(f"{result.found} of {searched} failures searched have a nearest fix ({result.failures} failures "
                  f"in the run; {complete} of them searched to the end); {result.probes} configurations probed, "
                  f"{result.rendered} rendered now, in {result.seconds:.1f} s", highlight=False, soft_wrap=True)
    for line in explained_lines(result.rows, result.threshold, result.resolution, spec):
        console.print(line, highlight=False, soft_wrap=True)
    if result.rows:
        console.print(f"[dim]read them: sweep3d query {escape(shlex.quote(str(spec)))} \"SELECT * FROM counterfactuals\" "
                      f"({escape(str(result.path))})[/]", highlight=False, soft_wrap=True)


def explained_lines(rows: Sequence[dict[str, Any]], threshold: float | None, resolution: float,
                    spec: Any = "SPEC", shown: int = SHOWN) -> list[str]:
    """The console's lines (rich markup, the data escaped) for the fixes of ``rows``: a sentence
    each for the nearest ``shown``, how many more and where, and how many are fragile."""
    found = sorted((r for r in rows if r.get("found")), key=lambda r: (r["distance"], r["failure_job"]))
    if not found:
        return []
    lines = [f"nearest fixes, nearest first (nearest to within {share_words(resolution)} of each range changed, "
             "the search's resolution):"]
    lines += [f"  {escape(str(r['object']))} · {escape(str(r['environment']))} · job {r['failure_job']}: "
              f"{escape(r.get('sentence') or fix_sentence(r) or '')}" for r in found[:shown]]
    if len(found) > shown:
        query = f"sweep3d query {shlex.quote(str(spec))} \"SELECT failure_job, sentence FROM counterfactuals WHERE found " \
                "ORDER BY distance\""
        lines.append(f"  … and {len(found) - shown} more: the report's Nearest fixes panel, or {escape(query)}")
    if threshold is None:
        lines.append("fragile: unknown, no stability check of the model yet (run `sweep3d stability "
                     f"{escape(shlex.quote(str(spec)))}`, then explain again: it marks the fragile fixes and "
                     "searches past them, re-rendering nothing it has)")
        return lines
    fragile = sum(r.get("fix_fragile") is True for r in found)
    sturdier = sum(r.get("nearest_distance") is not None for r in found)
    past = (f"; {sturdier} fragile nearest {'fix was' if sturdier == 1 else 'fixes were'} replaced by a sturdier "
            "one further along the same change" if sturdier else "")
    lines.append(f"fragile: {fragile} of {len(found)} fixes (|margin| < {threshold:.3g}, the stability check's "
                 f"threshold, or flipped in the check){past}")
    return lines
