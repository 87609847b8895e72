"""What ``plan`` and ``run`` print: per-stage counts of needed, cached and computed keys."""

from __future__ import annotations

import os

import duckdb
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from sweep3d.cache import Store
from sweep3d.core import UserError
from sweep3d.driver import JobList, Plan
from sweep3d.results import (
    GRADES,
    HIDDEN,
    Region,
    Summary,
    boundary_phrase,
    connect,
    control_number,
    has_view,
    named_rules,
    nearest_miss_region,
    numeric_scales,
    results_store,
    rules_left_out,
    stored_summary,
    weakest_regions,
    wilson_interval,
)
from sweep3d.runner import PlanStatus, RunResult
from sweep3d.spec import LoadedSpec
from sweep3d.stages.infer import ModelHandle, measure_of
from sweep3d.stages.render import duration, missing_gpu_warning, slow_render_warning


def print_plan(console: Console, status: PlanStatus, jobs: int = 0) -> None:
    """What ``sweep3d plan`` prints of ``status`` (the runner's :func:`~sweep3d.runner.status.plan_status`):
    the counts per stage, cached and to compute, the estimate, and with ``jobs`` the first that many
    jobs of the first model's plan."""
    spec, plans, plan = status.spec, status.plans, status.plan
    store = Store(spec.store)
    scenes = len(plan.jobs.scenes() if isinstance(plan.jobs, JobList) else {j.scene for j in plan.jobs})
    console.print(f"[bold]{escape(spec.name)}[/]: {len(plan.jobs) + len(plan.out_of_frame)} jobs over {scenes} scenes "
                  f"({len(spec.objects)} objects × {len(spec.environments)} environments), "
                  f"policy {spec.spec.policy.type}{_pairing(spec)}; store {escape(str(spec.store))}")
    table = Table("stage", "needed", "cached", "to compute", "estimate")
    for row in status.stages:
        table.add_row(row.stage, str(row.needed), str(row.cached), str(row.to_compute), duration(row.seconds))
    console.print(table)
    for line in status.changed:
        console.print(escape(line), highlight=False)
    print_protocol(console, plans)
    if len(status.models) > 1:
        console.print(_sharing(status.models))
    if plan.out_of_frame:
        console.print(f"{len(plan.out_of_frame)} jobs put the object wholly out of frame: flagged, not rendered")
    if spec.report.part_visibility:
        console.print("renders carry a UV pass (the report's part-visibility panel); a render cached "
                      "without it is rendered again for the pass only")
    if status.passes:
        console.print(f"renders carry the {' and '.join(status.passes)} passes (ground truth for the evaluator); "
                      "a render cached without them is rendered again for the passes only")
    if spec.policy.adaptive:
        console.print(f"adaptive policy: this is its first round; it proposes up to "
                      f"{spec.policy.params.samples} jobs per scene as results come in")
    console.print(f"estimated time: {duration(status.seconds)} (plus ~5 s start-up when anything needs rendering); "
                  f"{load_note()}")
    print_warning(console, slow_render_warning(spec.render, status.crop, status.to_render))
    print_warning(console, missing_gpu_warning(spec.render.device, status.to_render))
    if jobs:
        print_jobs(console, plan, store, jobs)


def load_note(cores: int | None = None, load: float | None = None) -> str:
    """What the estimate assumes of the machine, and how busy it is now: another process on the
    cores (a second run, a build) takes its share of them, so the run is slower by up to the load
    per core (measured: 10–40 % with one other run on 2 cores)."""
    cores = cores or os.cpu_count() or 1
    if load is None:
        try:
            load = os.getloadavg()[0]
        except OSError:  # no load average here: say only what is assumed
            return f"it assumes {cores} free CPU cores"
    busy = load / cores
    if busy < 0.25:
        return f"it assumes {cores} free CPU cores, as they are now"
    return (f"it assumes {cores} free CPU cores, but they are busy now (load {load:.1f} over the last minute): "
            f"expect up to {1 + busy:.1f}× as long")


def print_jobs(console: Console, plan: Plan, store: Store, n: int) -> None:
    """The first ``n`` jobs of ``plan``: scene, parameter values, and whether each stage has them
    (values print as text)."""
    from rich.table import Column
    from rich.text import Text

    rows = plan.table().slice(0, n).to_pylist()
    have = {"render": store.keys("renders"), "infer": store.keys("predictions")}
    headers = ["job", "object", "environment", *plan.columns, "rendered", "inferred"]
    table = Table(*(Column(header=Text(h), overflow="fold") for h in headers))  # wrapped, never cut
    for row in rows:
        cells = [row["job"], row["object"], row["environment"], *(row.get(c) for c in plan.columns)]
        cells += ["yes" if row["render_key"] in have["render"] else "no",
                  "yes" if row["pred_key"] in have["infer"] else "no"]
        table.add_row(*(Text("" if v is None else f"{v:.4g}" if isinstance(v, float) else str(v)) for v in cells))
    total = len(plan.jobs) + len(plan.out_of_frame)
    console.print(table)
    console.print(f"the first {len(rows)} of {total} jobs" + (" (out-of-frame jobs are not rendered)"
                                                              if plan.out_of_frame else ""))


def _pairing(spec: LoadedSpec) -> str:
    """What ``[policy] paired`` shares and ``cross`` crosses, for the plan's first line ("" when neither)."""
    paired = spec.spec.policy.paired
    parts = [] if not paired else ["paired across objects and environments" if paired == "all"
                                   else "paired across environments"]
    parts += [f"{name} crossed with {'every draw' if k is None else f'the first {k} draws'}"
              for name, k in spec.spec.policy.crossed.items()]
    return f" ({'; '.join(parts)})" if parts else ""


def _sharing(models: list[ModelHandle]) -> str:
    """One line on which models share renders."""
    sides = {m.framing: [] for m in models}
    for m in models:
        sides[m.framing].append(m.label)
    if len(sides) == 1:
        return f"{len(models)} models infer the same renders: {', '.join(escape(m.label) for m in models)}"
    return ("resolution = \"model\": each distinct model input is rendered apart ("
            + "; ".join(f"{f.crop}²: {', '.join(escape(n) for n in names)}" for f, names in sides.items()) + ")")


def print_run(console: Console, result) -> None:
    table = Table("stage", "needed", "cached", "computed", "failed", "skipped", "seconds")
    for o in result.outcomes:
        table.add_row(o.stage, str(o.total), str(o.cached), str(o.computed), str(o.failed), str(o.skipped),
                      f"{o.seconds:.1f}")
    console.print(table)
    for o in result.outcomes:
        for error in o.errors[:3]:
            console.print(f"[red]{escape(error.splitlines()[0])}[/]")
        if len(o.errors) > 3:
            console.print(f"[red]... and {len(o.errors) - 3} more {o.stage} errors[/]")
    skipped = len(result.plan.out_of_frame)
    console.print(f"{len(result.plan.jobs) + skipped} jobs in {result.seconds:.1f} s (run {result.run_id})"
                  + (f"; {skipped} out of frame, not rendered" if skipped else ""))
    print_protocol(console, result.plans or [result.plan])
    missing = unpredicted_jobs(result)
    print_findings(console, result.plan, result.store, missing)
    if result.failed:
        console.print(f"[red]{escape(failed_line(result, missing))}[/]")


def unpredicted_jobs(result: RunResult) -> int:
    """The jobs of the run's (first) plan left without a prediction: a stage failed for them, or
    for what they waited on. 0 when nothing failed (then every job has one)."""
    if not result.failed:
        return 0
    have = (result.store or Store(result.plan.spec.store)).key_set("predictions")
    return sum(1 for key in result.plan.jobs.key_column("pred_key") if key not in have)


def failed_line(result: RunResult, missing: int) -> str:
    """One line closing a run in which something failed: how many jobs are left out of the
    findings, and what failed at which stage (the first cause of each), never a clean summary."""
    stages = "; ".join(f"{o.stage}: {o.failed} failed ({_cause(o.errors[0]) if o.errors else 'no error given'})"
                       for o in result.outcomes if o.failed)
    jobs = len(result.plan.jobs)
    if missing and missing == jobs:  # nothing to report: the cause, not "run it", is what to fix
        return (f"error: all {jobs} jobs failed, so there are no findings and no report was written; {stages}; "
                "fix what it names, then run again")
    left = (f"{missing} of {jobs} jobs failed and are missing from the findings and the report" if missing
            else "every job has a prediction, but some of their keys failed to compute again")
    return f"error: {left}; {stages}"


def nothing_to_report(result: RunResult) -> bool:
    """Whether every job of the run's (first) plan failed: its report would have no result to show."""
    return bool(result.failed) and len(result.plan.jobs) > 0 and unpredicted_jobs(result) == len(result.plan.jobs)


def _cause(error: str) -> str:
    """An outcome's error without its ``<stage> <key>:`` prefix, first line only."""
    first = error.splitlines()[0] if error else ""
    head, sep, rest = first.partition(": ")
    return rest if sep and len(head.split()) == 2 else first


def print_protocol(console: Console, plans: list[Plan]) -> None:
    """What the model sees, one line (one per model when models see different things)."""
    lines = {plan.model: plan.protocol for plan in plans if plan.protocol}
    if len(set(lines.values())) == 1:
        console.print(escape(next(iter(lines.values()))), highlight=False, soft_wrap=True)
    else:
        for model, line in lines.items():
            console.print(f"{escape(model)}: {escape(line)}", highlight=False, soft_wrap=True)


def print_findings(console: Console, plan: Plan, store: Store | None = None, failed: int = 0) -> None:
    """The task's accuracy and where the model fails most: the control values significantly below the
    rest of their parameter, as the report's failure modes test them (never a value that merely
    looks low), or, when none is, the largest gap with its interval.

    Args:
        store: the run's store object (it has read the segments already), else a new one.
        failed: jobs the run failed to predict: said beside the accuracy, which leaves them out.
    """
    store = store if store is not None else Store(plan.spec.store)
    summary = stored_summary(store, plan.spec.name, plan.columns, scales=numeric_scales(plan.spec.controls))
    which = f"{escape(plan.model)}: " if len(plan.spec.models) > 1 else ""
    not_run = f"{failed} job{'s' * (failed != 1)} failed in the run and {'is' if failed == 1 else 'are'} not counted"
    if summary.accuracy is None:
        if summary.invalid:
            console.print(f"{which}no accuracy: {all_invalid_line(summary)}")
        elif failed:
            console.print(f"{which}no accuracy: {not_run}")
        return
    measure, rule = measure_of(plan.spec.evaluator)
    console.print(f"{which}{measure} {summary.accuracy:.1%} ({summary.correct} of {summary.counted}"
                  + (f"; {not_run}" if failed else "")
                  + (f"; {rule}" if measure != "top-1 accuracy" else "") + "); "
                  f"{summary.wrong} failures"
                  + (f", {summary.invalid} invalid predictions (NaN/inf outputs) excluded" if summary.invalid else "")
                  + (f"; {not_evaluable_line(summary)}" if summary.not_evaluable else ""))
    from sweep3d.results import fragile_sentence

    line = fragile_sentence(summary)
    if line:
        console.print(escape(line), highlight=False, soft_wrap=True)
    regions = weakest_regions(summary)
    rules = named_rules(summary)
    graded = grade_marks(store, plan, summary)
    marks = confirmation_marks(store, plan.spec.name, regions, summary.boundaries, rules)
    if graded is not None:  # a grade where one was given, else the confirmation's verdict, else untested
        keys = _printed_keys(regions, summary.boundaries, rules)
        marks = [graded[k] if graded.get(k, UNTESTED_MARK) != UNTESTED_MARK or m == UNCONFIRMED_MARK and k in graded
                 else m for k, m in zip(keys, marks)]
    unconfirmed = graded is None and UNCONFIRMED_MARK in marks
    untested = graded is not None and UNTESTED_MARK in marks
    if regions:
        console.print("fails most at: " + "; ".join(_marked(describe_region(r), marks.pop(0)) for r in regions)
                      + " (each against the rest of its parameter; false discovery rate 5%)")
    elif summary.wrong and summary.effects:
        gap = nearest_miss_region(summary)
        if gap is None:
            console.print("fails most at: no value is below the rest of its parameter")
        else:
            console.print(f"fails most at: no value is significantly below the rest of its parameter once adjusted "
                          f"for every region tested; the nearest, {describe_region(gap)}, q = {gap.q_value:.2f}, "
                          "does not rule out chance")
    if summary.boundaries:
        more = summary.boundaries_left_out
        console.print("fails beyond a boundary: " + "; ".join(_marked(describe_boundary(b), marks.pop(0))
                                                              for b in summary.boundaries)
                      + (f"; {more} more of single objects or environments in the report" if more else "")
                      + " (step fits with 95% profile-likelihood intervals; false discovery rate 5%)")
    if summary.no_boundaries:
        console.print("no significant boundary (q ≥ 0.05): "
                      + "; ".join(describe_flat(rows) for rows in by_parameter(summary.no_boundaries)))
    if rules:
        more = rules_left_out(summary)
        console.print("fails more in a box: " + "; ".join(_marked(escape(r["text"]), marks.pop(0)) for r in rules)
                      + (f"; {more} more in the findings view" if more else "")
                      + " (subgroup discovery over intervals; best of many boxes, so optimistic until confirmed)",
                      soft_wrap=True)
    if unconfirmed:
        console.print(f"unconfirmed: not yet tested on fresh renders (sweep3d confirm {escape(str(plan.spec.path))})",
                      soft_wrap=True)
    if untested:
        console.print(f"untested: sweep3d grade {escape(str(plan.spec.path))} grades every finding (fresh renders, "
                      "the second renderer, fragility)", soft_wrap=True)


UNTESTED_MARK = " [untested]"


def _marked(text: str, mark: str) -> str:
    """A finding (markup) with its mark: a grade leads it (``[solid] object = toaster: …``), a
    confirmation's verdict follows it."""
    if mark in GRADE_MARKS or mark == UNCONFIRMED_MARK:
        return f"{escape(mark.strip())} {text}"
    return text + escape(mark)


def grade_marks(store: Store, plan: Plan, summary: Summary) -> dict[str, str] | None:
    """Record the summary's findings as the latest listing (``run`` lists them untested; a grading
    of the same findings keeps its grades) and return each finding's key → its mark (`` [solid]``);
    None when the store cannot keep the listing."""
    from sweep3d.results import UNTESTED, listed_findings, record_listing, stored_rows

    findings = listed_findings(summary)
    try:
        listing = record_listing(store, plan.spec.name, plan.model, findings, plan.spec.path)
    except (OSError, UserError):
        return None
    rows = {r["finding"]: r["grade"] for r in stored_rows(store, plan.spec.name, plan.model) if r["listing"] == listing}
    return {f.key: UNTESTED_MARK if rows.get(f.key, UNTESTED) == UNTESTED else f" [{rows[f.key]}]" for f in findings}


#: The marks of the grades.
GRADE_MARKS = frozenset(f" [{g}]" for g in GRADES)


def _printed_keys(regions: list[Region], boundaries: list[dict], rules: list[dict]) -> list[str]:
    """The keys of the findings printed, in the order they are."""
    from sweep3d.results import boundary_key, region_key, rule_key

    return ([region_key(r.column, r.label) for r in regions] + [boundary_key(b) for b in boundaries]
            + [rule_key(r["key"]) for r in rules])


UNCONFIRMED_MARK = " [unconfirmed]"


def confirmation_marks(store: Store, experiment: str, regions: list[Region], boundaries: list[dict],
                       rules: list[dict] = ()) -> list[str]:
    """What follows each finding (regions, boundaries, then rules): its verdict on fresh renders, as
    ``sweep3d confirm`` recorded it (see :mod:`sweep3d.followups.confirm.record`), or `` [unconfirmed]``."""
    from sweep3d.followups.confirm import mark, read_verdicts

    verdicts = read_verdicts(store, experiment)
    return [mark(verdicts, key) if key in verdicts else UNCONFIRMED_MARK
            for key in _printed_keys(regions, boundaries, rules)]


def describe_region(region: Region) -> str:
    """``occluder = half: 17% of 24 against 67% of the other 24 (-50.0 pts, 95% CI -68.3 to -22.3)``."""
    return (f"{escape(region.column)} = {escape(region.label)}: {region.accuracy:.0%} of {region.count} against "
            f"{region.accuracy_rest:.0%} of the other {region.count_rest} ({_points(region.difference)}, "
            f"unadjusted 95% CI {_points(region.difference_low)} to {_points(region.difference_high)})")


def describe_boundary(row: dict) -> str:
    """``toaster: camera_elevation fails below 12.1 (95% interval 8.03–15.2), 61% of 40 → 18% of 12``:
    the accuracy on the side that passes, then (→) on the side that fails. With two values, the
    value it fails at against the other, and the accuracies in the order of those words
    (``fails at 5 against 35, 19% of 96 against 53% of 96``)."""
    who = row["object"] if row["scope"] == "object" else row["environment"] if row["scope"] == "environment" else None
    below = row["fails"] == "below"
    passing = (row["accuracy_above"], row["n_above"]) if below else (row["accuracy_below"], row["n_below"])
    failing = (row["accuracy_below"], row["n_below"]) if below else (row["accuracy_above"], row["n_above"])
    if row["values"] == 2:  # "at 5 against 35": the failing value's accuracy first, as its words go
        where, sides = "", f"{failing[0]:.0%} of {failing[1]} against {passing[0]:.0%} of {passing[1]}"
    else:
        where = f" (95% interval {control_number(row['boundary_low'])}–{control_number(row['boundary_high'])})"
        sides = f"{passing[0]:.0%} of {passing[1]} → {failing[0]:.0%} of {failing[1]}"
    return f"{escape(who) + ': ' if who else ''}{escape(row['parameter'])} {boundary_phrase(row)}{where}, {sides}"


#: Objects or environments a "no boundary" finding names per parameter.
FLAT_NAMES = 8


def by_parameter(rows: list[dict]) -> list[list[dict]]:
    """``rows`` grouped by their parameter, in the order each parameter first appears."""
    groups: dict[str, list[dict]] = {}
    for row in rows:
        groups.setdefault(row["parameter"], []).append(row)
    return list(groups.values())


def describe_flat(rows: list[dict]) -> str:
    """One parameter's fits without a significant boundary: over all results with its largest
    step (``camera_elevation: all results, largest step 70% of 240 → 75% of 240 at 20, q = 0.31``;
    ``always right`` where there is none), else for the objects and environments
    (``blur_sigma for objects soccer ball and environments studio``)."""
    overall = next((row for row in rows if row["scope"] == "all"), None)
    if overall is not None:
        below, above = overall["accuracy_below"], overall["accuracy_above"]
        if below == above and below in (0.0, 1.0):
            return f"{escape(overall['parameter'])}: all results, always {'right' if below else 'wrong'}"
        return (f"{escape(overall['parameter'])}: all results, largest step {below:.0%} of {overall['n_below']} → "
                f"{above:.0%} of {overall['n_above']} at {control_number(overall['estimate'])}, "
                f"q = {overall['q_value']:.2f}")
    parts = []
    for scope in ("object", "environment"):
        names = [escape(str(row[scope])) for row in rows if row["scope"] == scope]
        more = len(names) - FLAT_NAMES
        if names:
            parts.append(f"{scope}s " + ", ".join(names[:FLAT_NAMES]) + (f" and {more} more" if more > 0 else ""))
    return f"{escape(rows[0]['parameter'])} for " + " and ".join(parts)


def all_invalid_line(summary: Summary) -> str:
    """What a run whose every prediction is invalid found (nothing to count)."""
    return (f"all {summary.invalid} predictions are invalid (the model's outputs are NaN or infinite), so none is "
            "counted")


def check_some_valid(plan: Plan, store: Store | None = None) -> None:
    """Refuse to report a run whose model gave no valid prediction: its accuracy would be blank,
    not a finding. What was computed stays stored (a fixed model has another digest: it infers again).

    Raises:
        UserError: naming the model, how many predictions were invalid and what to fix.
    """
    store = store if store is not None else Store(plan.spec.store)
    summary = stored_summary(store, plan.spec.name, plan.columns, scales=numeric_scales(plan.spec.controls))
    if summary.accuracy is None and summary.invalid:
        raise UserError(f"{plan.spec.path}: model {plan.model!r}: {all_invalid_line(summary)}; no report was "
                        "written: fix the model (its weights, its preprocessing) and run again (the renders are kept)")


def not_evaluable_line(summary: Summary) -> str:
    """``12 jobs not evaluable, excluded: 8 out of frame, 4 hidden (< 10% visible)``."""
    reasons = ", ".join(
        f"{n} {reason}" + (f" (< {summary.min_visible:.0%} visible)" if reason == HIDDEN and summary.min_visible
                           is not None else "")
        for reason, n in summary.not_evaluable_reasons.items())
    return f"{summary.not_evaluable} jobs not evaluable, excluded: {reasons}"


def print_warning(console: Console, line: str | None) -> None:
    """A warning as one yellow line (nothing for None)."""
    if line:
        console.print(f"[bold yellow]warning:[/] {escape(line)}", highlight=False, soft_wrap=True)


def print_bench(console: Console, rows, best, current, agreement: float) -> None:
    """The bench table: one row per setting, fastest first, the references last; the rule as its
    caption and the recommendation with its measured speed-up below."""
    from sweep3d.bench import pareto, required_agreement

    front = {id(r) for r in pareto([r for r in rows if r.is_setting])}
    base = next((r for r in rows if r.setting == current and r.is_setting), None)
    target = required_agreement(rows, agreement)
    floor = next((r for r in rows if r.is_floor), None)
    n = rows[0].jobs
    caption = (f"{n} jobs. top-1 =: jobs whose top-1 class matches the reference's (95 % Wilson interval); "
               f"a setting passes when the interval reaches {target:.1%} (--agreement {agreement:.0%}"
               + (f", lowered to the noise floor: a second reference at another seed agrees on {floor.top1}/{n}"
                  if floor and target < agreement else "") + f"). With {n} jobs even full agreement only shows "
               f"≥ {_wilson_low(n)}. s/img: median steady-state render seconds per image, scene loads left "
               "out; load: mean seconds per scene load (mesh, world, BVH and importance map) × loads in this run. "
               "PSNR/SSIM: in the model's view, against the reference. speed-up: median "
               "s/img of the spec's setting over this one's, in this run.")
    table = Table(caption=caption, caption_justify="left")
    table.add_column("setting")
    for name in ("s/img", "load", "speed-up", "PSNR", "SSIM", "top-1 = (95 %)", "verdict ="):
        table.add_column(name, justify="right")
    table.add_column("note")
    for row in sorted(rows, key=lambda r: (not r.is_setting, r.is_floor, r.seconds)):
        low, high = row.interval()
        notes = [n for n, on in (("reference", row.is_reference), ("noise floor", row.is_floor), ("spec", row is base),
                                 ("recommended", row is best), ("passes", row.passes and row is not best),
                                 ("Pareto", id(row) in front)) if on]
        speed = f"{base.seconds / row.seconds:.2f}×" if base and row.seconds > 0 else ""
        interval = "" if row.is_reference else f" ({low:.0%}–{high:.0%})"
        table.add_row(row.setting.label(), f"{row.seconds:.3f}", _load(row), speed, _db(row.psnr), f"{row.ssim:.3f}",
                      f"{row.top1}/{row.jobs}{interval}", f"{row.verdicts}/{row.jobs}", ", ".join(notes))
    console.print(table)
    console.print(_load_line(rows), soft_wrap=True)
    if best is None:
        console.print("no setting reached the required agreement with the reference; keep the spec's")
    elif base is not None and best.setting == base.setting:
        console.print(f"recommended: [bold]{best.setting.label()}[/], the spec's own setting "
                      f"({best.seconds:.3f} s/image, top-1 agreement {best.top1}/{best.jobs})")
    else:
        gain = ""
        if base is not None:
            ratio = base.seconds / best.seconds
            gain = (f"; [bold]{ratio:.2f}× faster[/] than the spec's setting {base.setting.label()} "
                    f"({base.seconds:.3f} s/image, top-1 agreement {base.top1}/{base.jobs})" if ratio >= 1 else
                    f"; {1 / ratio:.2f}× slower than the spec's setting {base.setting.label()}, "
                    f"which does not pass (top-1 agreement {base.top1}/{base.jobs})")
        console.print(f"recommended: [bold]{best.setting.label()}[/] ({best.seconds:.3f} s/image, {_db(best.psnr)} dB, "
                      f"top-1 agreement {best.top1}/{best.jobs}{gain})")


def _load(row) -> str:
    """The load cell: mean seconds per scene load × loads; "cached" when nothing was rendered."""
    if row.timed == 0:
        return "cached"
    return "–" if row.load_seconds is None else f"{row.load_seconds:.3g} ×{row.loads}"


def _load_line(rows) -> str:
    """Scene loads against steady-state rendering over the whole bench, in one line."""
    timed = sum(r.timed for r in rows)
    if timed == 0:
        return "every render was cached: s/img are the times stored when they were made (scene loads included)"
    cached = sum(r.jobs for r in rows) - timed
    note = (f"; {cached} renders were cached (a setting with none made in this run shows their stored times, "
            "loads included)") if cached else ""
    return (f"scene loads: {sum(r.loads for r in rows)} of {timed} renders in this run switched scene first, "
            f"{sum(r.load_total for r in rows):.1f} s in all, beside {sum(r.render_total for r in rows):.1f} s of "
            f"steady-state rendering; s/img leaves the loads out{note}")


def _wilson_low(n: int) -> str:
    return f"{wilson_interval(n, n)[0]:.1%}"


def _db(psnr: float) -> str:
    return "∞" if psnr >= 100 else f"{psnr:.1f}"


def print_comparison(console: Console, spec: LoadedSpec, limit: int = 3) -> None:
    """One screen comparing the spec's models: each one's accuracy, then each later model against
    the first (McNemar, agreement) with the regions where it is significantly better or worse."""
    with results_store(spec) as store:
        con = connect(store, spec.name)
        try:
            _print_models(console, con, limit)
        finally:
            con.close()


def _print_models(console: Console, con: duckdb.DuckDBPyConnection, limit: int) -> None:
    """The comparison itself, from a connection over the spec's own results."""
    if not has_view(con, "model_agreement"):
        return
    models = con.execute("SELECT model, accuracy, wilson_low, wilson_high, n FROM model_accuracy").fetchall()
    console.print("models: " + " · ".join(
        f"{escape(m)} {_pct(acc)} [{_pct(lo)}–{_pct(hi)}] of {n}" for m, acc, lo, hi, n in models))
    first = models[0][0]
    for a, b, n, diff, fixed, broken, p, same, kappa in con.execute(
            "SELECT model_a, model_b, n, difference, fixed, broken, p_value, same_top1, kappa FROM model_agreement "
            "WHERE model_a = ?", [first]).fetchall():
        agreement = f"same top-1 {_pct(same)}, κ " + ("–" if kappa is None else f"{kappa:.2f}")
        console.print(f"[bold]{escape(b)}[/] against {escape(a)}: {_points(diff)} on {n} jobs both answered; "
                      f"{fixed} fixed, {broken} broken, McNemar p = {_p_text(p)}; {agreement}")
        for verdict in ("better", "worse"):
            rows = con.execute(
                "SELECT parameter_a, label_a, parameter_b, label_b, difference, p_holm, n FROM model_regions "
                "WHERE model_a = ? AND model_b = ? AND verdict = ? ORDER BY p_holm, abs(difference) DESC LIMIT ?",
                [a, b, verdict, limit]).fetchall()
            regions = "; ".join(
                " & ".join(f"{escape(p)} = {escape(str(v))}" for p, v in ((pa, la), (pb, lb)) if p is not None)
                + f" ({_points(d)}, p_holm {_p_text(ph)}, {count} jobs)" for pa, la, pb, lb, d, ph, count in rows)
            console.print(f"  significantly {verdict}: " + (regions or "nowhere, after Holm's correction"))


def _pct(value: float | None) -> str:
    return "–" if value is None else f"{value:.1%}"


def _points(value: float | None) -> str:
    return "–" if value is None else f"{value * 100:+.1f} pts"


def _p_text(value: float | None) -> str:
    return "–" if value is None else ("< 0.001" if value < 0.001 else f"{value:.3f}")
