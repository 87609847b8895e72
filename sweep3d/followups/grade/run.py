"""``sweep3d grade``: every finding of a run graded by checks sized to decide, under one budget.

The grading is three plans for the one runner, in order, each through the same cached stages:

1. the stability check (:mod:`sweep3d.followups.stability`), sequential over margin bins: the
   fragile threshold the fragility check reads (classification only);
2. ``confirm``'s twins for every finding fresh twins can test, the budget's renders allotted where
   they decide most (:func:`~sweep3d.followups.confirm.allotted`), judged in one look;
3. the replicated findings' twins again with the second renderer (Mitsuba under a Cycles spec,
   Cycles under a Mitsuba one), as many pairs as the budget has left, in looks within them.

Then :mod:`.decide` grades each finding and the grades become the listing's rows of the
``finding_grades`` table (the ``findings`` view). The budget counts the distinct renders the checks
use, cached or not (by default two thirds of what the run itself rendered, so that the grades
take less time than the run), so a second call with the same budget and seed renders nothing and
writes the same grades; a larger budget reuses what a smaller one rendered. The findings' twins
share renders (a blur claim's twin is the blur boundary's, see
:func:`~sweep3d.followups.confirm.draw.draw_pairs`), so a render counts once.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from typing import Any

from rich.console import Console

from sweep3d.cache import Store
from sweep3d.core import UserError
from sweep3d.followups.grade.decide import Evidence, evidence_of, grade, second_opinion
from sweep3d.results import (
    CONFIRMED,
    INCONCLUSIVE_GRADE,
    Finding,
    first_look,
    grade_row,
    listed_findings,
    numeric_scales,
    pairs_to_confirm,
    record_listing,
    stored_rows,
    stored_summary,
)
from sweep3d.spec import LoadedSpec
from sweep3d.stages.render import LOCAL, Executor

#: The default budget as a share of the renders the run made: two thirds, so that grading
#: takes less time than the run did (a render of the checks costs what one of the run does).
DEFAULT_SHARE = 2 / 3
#: The budget's shares: the stability check's scene neighbours first; of what they leave, the
#: replication's; the second renderer gets the rest (the findings' twins first, then at most
#: 1/IMAGE_SHARE of the budget for the sampled failure images).
STABILITY_SHARE = 0.25
REPLICATION_SHARE = 2 / 3
MAX_PAIRS = 128  # a finding's twin pairs at most, however large the budget
MIN_IMAGES = 16  # the stability check's least sample within a grade
IMAGE_SHARE = 16  # 1/16 of the budget is kept for the sampled failure images on the second renderer
REPLICATION_FIRST = 16  # candidate pairs drawn per finding at least (more where the budget could give more)
ENGINE_FIRST = 8  # the second renderer's first look, in pairs
ENGINE_SUFFIX = "-confirm-"  # the second renderer's experiment: <name>-confirm-<engine>


@dataclass
class Graded:
    """What one grading did and decided."""

    findings: list[Finding]
    grades: list[tuple[str, str]]  # (grade, evidence) per finding
    budget: int  # renders
    used: int  # distinct renders the checks used (cached or not)
    rendered: int  # renders this call made
    seconds: float
    engine: str
    stability: Any = None  # the stability check's Checked (first model), None when not made
    listing: str = ""
    #: the least budget whose share renders the scene neighbours, where this one checked the image
    #: changes alone (None: the neighbours were rendered, or the spec moves nothing they would move)
    scene_budget: int | None = None
    replaced: int | None = None  # the larger budget of the earlier grades these replaced (same seed)
    #: the least budget that could give every inconclusive finding the pairs that could confirm it
    #: (two renders a pair, at the replication's share; 0: none is short of them)
    wanted: int = 0


def grade_findings(loaded: LoadedSpec, budget: int | None = None, seed: int | None = None,
                   console: Console | None = None, wait: float = 0.0, executor: Executor = LOCAL) -> Graded:
    """Grade every finding of ``loaded``'s last run (its first model) within ``budget`` renders
    (None: :data:`DEFAULT_SHARE` of the renders the run made)."""
    from sweep3d.results import no_results

    if budget is not None and budget < 0:
        raise UserError(f"--budget {budget}: the renders the checks may use is 0 or more")
    started = time.perf_counter()
    seed = loaded.experiment.seed if seed is None else seed
    store = Store(loaded.store, warn=False)
    if not loaded.store.is_dir():
        raise no_results(store, loaded.name, loaded.path)
    from sweep3d.runner import session

    with store.lock(wait), session(loaded, executor=executor, console=console):  # warm workers, one model load
        return _graded(loaded, store, budget, seed, console, executor, started)


def _graded(loaded: LoadedSpec, store: Store, budget: int | None, seed: int, console: Console | None,
            executor: Executor, started: float) -> Graded:
    from sweep3d.followups.confirm import claims_of, confirm, evidence_rate, space_of
    from sweep3d.runner import plans_as_run

    plan = plans_as_run(loaded, store)[0]
    summary = stored_summary(store, loaded.name, plan.columns, scales=numeric_scales(loaded.controls))
    if summary.accuracy is None:
        raise UserError(f"{loaded.path}: no results to grade yet; run: sweep3d run {loaded.path}")
    findings = listed_findings(summary)
    if budget is None:
        budget = max(2, math.ceil(DEFAULT_SHARE * len({job.render_key for job in plan.jobs})))
    model = plan.model
    listing = record_listing(store, loaded.name, model, findings, loaded.path)
    space = space_of(loaded)
    claims = claims_of(loaded, store, summary, space)
    testable = [c for c in claims.values() if not isinstance(c, str)]
    checked, used, scene_budget = _stability(loaded, seed, console, executor, int(budget * STABILITY_SHARE))
    stability_used, replication_used = used, 0
    threshold = checked.threshold if checked is not None else None
    rendered = checked.scene.rendered if checked is not None and checked.scene is not None else 0
    evidence: dict[str, Evidence] = {}
    engine = other_engine(loaded)
    if testable and budget >= 2:
        result = confirm(loaded, 2 * REPLICATION_FIRST, seed, console, claims=testable, executor=executor,
                         max_renders=2 * MAX_PAIRS, render_budget=int((budget - used) * REPLICATION_SHARE),
                         found=(plan, summary),
                         weights={f.key: evidence_rate(f.run_difference) for f in findings})
        rendered += result.rendered
        used += result.renders_used
        replication_used = result.renders_used
        verdicts = {x.claim.key: x.verdict for x in result.confirmations}
        replicated = [k for k, v in verdicts.items() if v.status == CONFIRMED]
        engine_verdicts, engine_rendered, engine_used = _second_renderer(
            loaded, store, space, result, replicated, budget - used - budget // IMAGE_SHARE, engine, console,
            executor)
        rendered += engine_rendered
        used += engine_used
        candidates = {x.claim.key: x.candidates for x in result.confirmations}
        for key, verdict in verdicts.items():
            evidence[key] = evidence_of(verdict, result.outcomes.get(key, []), engine_verdicts.get(key), engine,
                                        threshold, candidates[key])
    images, image_rendered = _image_grades(loaded, store, space, model, checked, max(0, budget - used), engine,
                                           console, executor)
    used += images
    rendered += image_rendered
    grades = []
    for finding in findings:
        claim = claims.get(finding.key)
        if isinstance(claim, str):
            grades.append(grade(Evidence(untested=f"fresh twins cannot test it: {claim}")))
        elif finding.key in evidence:
            grades.append(grade(evidence[finding.key]))
        elif budget < 2:
            grades.append(grade(Evidence(untested=f"--budget {budget} gives no fresh pair")))
        else:
            grades.append(grade(Evidence()))
    replaced = larger_budget(stored_rows(store, loaded.name, model), listing, budget, seed)
    _record(store, loaded, model, listing, findings, grades, evidence, budget, seed)
    short = [evidence[f.key].replication for f, (g, _) in zip(findings, grades)
             if g == INCONCLUSIVE_GRADE and f.key in evidence and evidence[f.key].replication is not None]
    return Graded(findings, grades, budget, used, rendered, time.perf_counter() - started, engine, checked, listing,
                  scene_budget, replaced, wanted_budget(short, stability_used, replication_used))


def wanted_budget(short: list[Any], stability_used: int, replication_used: int) -> int:
    """The least budget at which the replication could give each of the ``short`` findings'
    verdicts the pairs that could confirm it: the renders it used, two more for each pair missing
    (twins share renders, so this is at most what it takes), over its share of what the stability
    check leaves. 0 when none is short."""
    missing = sum(max(0, pairs_to_confirm(verdict) - verdict.pairs) for verdict in short)
    if not missing:
        return 0
    return stability_used + math.ceil((replication_used + 2 * missing) / REPLICATION_SHARE)


def other_engine(loaded: LoadedSpec) -> str:
    """The second renderer of ``loaded``: Mitsuba under Cycles, Cycles under anything else."""
    return "mitsuba" if loaded.spec.render.engine == "cycles" else "cycles"


def _stability(loaded: LoadedSpec, seed: int, console: Console | None, executor: Executor,
               share: int) -> tuple[Any, int, int | None]:
    """The stability check of the first model (sequential), or None where it does not apply; the
    renders its scene neighbours used; and the least budget that would render them, where
    ``share`` did not. The images are as many as ``share`` renders of neighbours allow (the image
    changes cost no render): see :func:`stability_sample`."""
    from sweep3d.followups.stability import DEFAULT_SAMPLE, check_stability, neighbours_per_image

    if loaded.evaluator.kind != "classification":
        return None, 0, None
    each = neighbours_per_image(loaded) if loaded.spec.stability.scene else 0
    scene, cap = stability_sample(share, each, DEFAULT_SAMPLE)
    checked = check_stability(loaded, min(DEFAULT_SAMPLE, cap), seed, console, executor=executor, max_sample=cap,
                              scene=None if scene else False)[0]
    wanted = math.ceil(each * MIN_IMAGES / STABILITY_SHARE) if each and not scene else None
    return checked, len(checked.scene.planned) if checked.scene is not None else 0, wanted


def stability_sample(share: int, each: int, sample: int) -> tuple[bool, int]:
    """(whether the scene neighbours are rendered, the most images) for ``share`` renders at
    ``each`` neighbours an image: as many images as the share renders the neighbours of, between
    :data:`MIN_IMAGES` and four default samples. A share that cannot render the neighbours of the
    least sample (the default budget of a run of a few hundred renders, ``--budget 0``) checks the
    image changes only, on one default sample, which renders nothing (their inference is what
    they cost): neighbours of a sample too small to set a threshold would take renders the
    replication decides with. Without scene neighbours the check is that one sample too."""
    if each and share >= each * MIN_IMAGES:
        return True, max(MIN_IMAGES, min(4 * sample, share // each))
    return False, sample


def _second_renderer(loaded: LoadedSpec, store: Store, space: Any, result: Any, replicated: list[str], left: int,
                     engine: str, console: Console | None, executor: Executor) -> tuple[dict, int, int]:
    """The replicated findings' twins rendered by ``engine`` in looks (:func:`second_opinion`), each
    finding's pairs at most its replication's, as many as ``left`` renders allow (the twins'
    renders shared as in the replication): (key → verdict, renders made, renders used)."""
    from sweep3d.followups.confirm import allotted, distinct_renders, render_twins
    from sweep3d.stages.render import cycles_only_defaults

    keys = {k: result.render_keys[k] for k in replicated}
    caps = allotted([keys[k] for k in replicated], max(0, left))
    if not replicated or max(caps, default=0) < 1:
        return {}, 0, 0
    settings = {"engine": engine, **cycles_only_defaults(engine)}
    taken = [0] * len(replicated)
    rendered = 0

    def fetch(asked: Any) -> dict[int, list]:
        nonlocal rendered
        for i, n in asked.items():
            taken[i] = min(n, caps[i])
        groups = [result.pairs[k][:taken[i]] for i, k in enumerate(replicated)]
        run_result, outcomes = render_twins(loaded, store=store, space=space, pairs=groups, console=console,
                                            executor=executor, suffix=ENGINE_SUFFIX + engine, render=settings)
        render = next((o for o in run_result.outcomes if o.stage == "render"), None) if run_result else None
        rendered += render.computed if render else 0
        return {i: [(a[1], b[1]) for a, b in outcomes[i] if a and b and a[0] and b[0]] for i in asked}

    verdicts = second_opinion(len(replicated), first_look(max(caps), ENGINE_FIRST), max(caps), fetch, caps)
    checked = {k: v for k, v, n in zip(replicated, verdicts, caps) if n}  # no pair within the budget: not checked
    return checked, rendered, distinct_renders(keys[k][:n] for k, n in zip(replicated, taken))


def _image_grades(loaded: LoadedSpec, store: Store, space: Any, model: str, checked: Any, left: int, engine: str,
                  console: Console | None, executor: Executor) -> tuple[int, int]:
    """Grade the failure images the stability check sampled: fragile where a change no eye sees
    flipped it or its margin is within the threshold of a tie; else rendered again by ``engine``
    (as many as ``left`` allows, in job order): renderer-sensitive where that gets it right, solid
    where it fails too, inconclusive where the budget left it unrendered. Returns (jobs used, renders made)."""
    from sweep3d.followups.confirm import render_rows
    from sweep3d.results import IMAGE_SCHEMA, IMAGES_TABLE, connect, image_grade_row, literal
    from sweep3d.stages.render import cycles_only_defaults

    if checked is None:
        return 0, 0
    columns = [p.column for p in space.parameters]
    con = connect(store, loaded.name, views="results")
    try:
        select = ", ".join(f"r.{c}" for c in ["object", "environment", *columns])
        found = con.execute(
            f"SELECT r.pred_key, r.margin, i.flipped, {select} FROM results r JOIN stability_images i "
            f"ON i.pred_key = r.pred_key AND i.model IS NOT DISTINCT FROM {literal(checked.model)} "
            "WHERE r.counted AND NOT r.correct ORDER BY r.job").fetchall()
    finally:
        con.close()
    threshold = checked.threshold
    rows, fragile = [], {}
    for pred_key, margin, flipped, *values in found:
        if flipped:
            fragile[pred_key] = "a change no eye sees flips it (stability check)"
        elif margin is not None and abs(margin) < threshold:
            fragile[pred_key] = f"|margin| {abs(margin):.3g} is within the fragile threshold {threshold:.3g} of a tie"
        else:
            rows.append((pred_key, dict(zip(["object", "environment", *columns], values))))
    taken = rows[:left]
    settings = {"engine": engine, **cycles_only_defaults(engine)}
    result, outcomes = render_rows(loaded, space, store, [r for _, r in taken], console, executor,
                                   f"-grade-{engine}", settings)
    out = [image_grade_row(loaded.name, model, k, "fragile", why) for k, why in fragile.items()]
    for (pred_key, _), outcome in zip(taken, outcomes):
        if outcome is None or not outcome[0]:
            out.append(image_grade_row(loaded.name, model, pred_key, "inconclusive",
                                       f"{engine} gave no counted verdict of it (out of frame or invalid)"))
        elif outcome[1]:
            out.append(image_grade_row(loaded.name, model, pred_key, "renderer-sensitive",
                                       f"steady under changes no eye sees, but {engine} gets it right"))
        else:
            out.append(image_grade_row(loaded.name, model, pred_key, "solid",
                                       f"steady under changes no eye sees, and {engine} fails it too"))
    for pred_key, _ in rows[len(taken):]:
        out.append(image_grade_row(loaded.name, model, pred_key, "inconclusive",
                                   f"steady under changes no eye sees; the budget ended before {engine} rendered it"))
    if out:
        store.append(IMAGES_TABLE, out, IMAGE_SCHEMA)
    render = next((o for o in result.outcomes if o.stage == "render"), None) if result else None
    return len(taken), render.computed if render else 0


def larger_budget(rows: list[dict[str, Any]], listing: str, budget: int, seed: int) -> int | None:
    """The budget of the grading these grades replace (``rows``: the stored ones, newest per
    finding), when it was larger than ``budget`` with the same seed: a smaller budget's grades
    replace a larger one's, however many renders that one had; None otherwise."""
    earlier = []
    for row in rows:
        if row.get("listing") != listing or not row.get("details"):
            continue
        try:
            details = json.loads(row["details"])
        except ValueError:
            continue
        if isinstance(details, dict) and details.get("seed") == seed and isinstance(details.get("budget"), int):
            earlier.append(details["budget"])
    return max(earlier) if earlier and max(earlier) > budget else None


def _record(store: Store, loaded: LoadedSpec, model: str, listing: str, findings: list[Finding],
            grades: list[tuple[str, str]], evidence: dict[str, Evidence], budget: int, seed: int) -> None:
    """The listing's rows with their grades (newer than its untested ones)."""
    from sweep3d.cache import utc_now
    from sweep3d.results import FINDINGS_SCHEMA, FINDINGS_TABLE

    now = utc_now()
    rows = []
    for finding, (grade_name, sentence) in zip(findings, grades):
        e = evidence.get(finding.key)
        r, g = (e.replication, e.engine) if e else (None, None)
        details = {"replication": r.as_dict() if r else None, "engine": g.as_dict() if g else None,
                   "steady": e.steady.as_dict() if e and e.steady else None,
                   "threshold": e.threshold if e else None, "budget": budget, "seed": seed}
        rows.append(grade_row(
            loaded.name, model, listing, now, finding, grade_name, sentence,
            pairs=r.pairs if r else None, effect=_finite(r.difference) if r else None,
            effect_low=_finite(r.difference_low) if r else None, effect_high=_finite(r.difference_high) if r else None,
            engine=e.engine_name if g else None, engine_pairs=g.pairs if g else None,
            engine_effect=_finite(g.difference) if g else None, fragile_set_aside=e.set_aside if e and e.steady else None,
            details=json.dumps(details, sort_keys=True, allow_nan=False, default=str)))
    if rows:
        store.append(FINDINGS_TABLE, rows, FINDINGS_SCHEMA)


def _finite(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None
