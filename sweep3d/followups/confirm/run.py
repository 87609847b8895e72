"""``sweep3d confirm``: draw, render and judge fresh twins for each significant finding of a run.

The fresh configurations are explicit jobs of a second experiment, ``<name>-confirm``, planned
through the ``table`` policy (its rows given in memory) and run by :func:`sweep3d.runner.pipeline.run`:
the same stages, keys and cache as any run, so a second ``confirm`` with the same spec, findings,
``--renders`` and ``--seed`` draws the same pairs and renders nothing. A candidate pair is kept
only when both twins are in frame and neither image is one the discovery run made (nor one an
earlier pair of the confirmation made): a finding is never confirmed on the images it was found
on. Twins whose prediction is invalid or whose object is hidden are dropped with their pair.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

from rich.console import Console
from rich.markup import escape

from sweep3d.cache import Store
from sweep3d.core import UserError
from sweep3d.followups.confirm.claims import Claim, boundary_claim, rule_claim, value_claim
from sweep3d.followups.confirm.draw import Row, Space, draw_pairs, scene_order, space_of
from sweep3d.followups.confirm.record import write_verdicts
from sweep3d.results import (
    ALPHA,
    DEFAULT_RENDERS,
    Summary,
    Verdict,
    connect,
    has_view,
    numeric_scales,
    sequential,
    stored_summary,
    tally,
)
from sweep3d.spec import LoadedSpec, PolicySpec
from sweep3d.stages.render import LOCAL, Executor

#: Candidate pairs drawn per pair wanted: room for those dropped (out of frame, a discovery image).
OVERDRAW = 3
SUFFIX = "-confirm"


#: One twin's result: counted, correct, and its margin (None without one).
Twin = tuple[bool, bool, "float | None"]


@dataclass
class Confirmation:
    """One finding's claim, its fresh pairs and its verdict."""

    claim: Claim
    drawn: int  # pairs kept for rendering
    verdict: Verdict
    candidates: int = 0  # fresh pairs that could be drawn for it (a budget's allotment may take fewer)


@dataclass
class ConfirmResult:
    experiment: str  # the fresh jobs' experiment
    confirmations: list[Confirmation]
    jobs: int  # fresh jobs (two per pair; twins that differ only in a post control share a render)
    rendered: int  # renders this call made
    cached: int  # renders it found in the store
    failed: int
    renders: int = DEFAULT_RENDERS  # fresh renders asked for per finding (--renders)
    #: claim key → its judged twin pairs (rows as drawn) and each twin's (counted, correct, margin)
    pairs: dict[str, list[tuple[Row, Row]]] = dataclasses.field(default_factory=dict)
    outcomes: dict[str, list[tuple[Twin, Twin]]] = dataclasses.field(default_factory=dict)
    #: claim key → each pair's two render keys (with ``pairs``): what the pairs cost in renders
    render_keys: dict[str, list[tuple[str, str]]] = dataclasses.field(default_factory=dict)
    renders_used: int = 0  # distinct renders the judged pairs use, cached or not


def confirm(loaded: LoadedSpec, renders: int = DEFAULT_RENDERS, seed: int | None = None,
            console: Console | None = None, claims: list[Claim] | None = None, wait: float = 0.0,
            executor: Executor = LOCAL, max_renders: int | None = None,
            render_budget: int | None = None, found: tuple[Any, Summary] | None = None,
            weights: dict[str, float] | None = None) -> ConfirmResult:
    """Confirm every significant finding of ``loaded``'s last run on ``renders`` fresh renders each
    (``renders // 2`` twin pairs), drawn with ``seed`` (default: the spec's); ``claims``: these
    instead of the run's findings. With ``max_renders`` above ``renders``, the findings neither
    confirmed nor bounded get more pairs in looks, doubling up to ``max_renders // 2``
    (:func:`sweep3d.results.confirmation.sequential`; None: one look). ``render_budget``: the most
    distinct renders the pairs may use, cached or not, allotted to the claims where they are worth
    the most (claims share renders, see :func:`allotted`; ``weights``: claim key → the expected z
    of its evidence per root pair, :func:`evidence_rate`), judged in one look. ``found``: the
    run's plan and summary when the caller has them (read again otherwise). It holds the store's
    writer lock from its start to its end (``wait``: seconds to wait for another command holding
    it), its renders' run within it, by the runner on ``executor``."""
    from sweep3d.results import no_results

    if renders < 2:
        raise UserError(f"--renders {renders}: a finding needs at least 2 fresh renders (one twin pair)")
    seed = loaded.experiment.seed if seed is None else seed
    store = Store(loaded.store, warn=False)  # a file it cannot read refuses the findings, with no warning first
    if not loaded.store.is_dir():  # before the lock would make the store's folder
        raise no_results(store, loaded.name, loaded.path)
    cap = renders if max_renders is None else max(renders, max_renders)
    with store.lock(wait):
        return _confirmed(loaded, store, renders, seed, console, claims, executor, cap, render_budget, found,
                          weights)


def _confirmed(loaded: LoadedSpec, store: Store, renders: int, seed: int, console: Console | None,
               claims: list[Claim] | None, executor: Executor = LOCAL, cap: int | None = None,
               render_budget: int | None = None, found: tuple[Any, Summary] | None = None,
               weights: dict[str, float] | None = None) -> ConfirmResult:
    """:func:`confirm`, holding the store's lock."""
    from sweep3d.runner import plans_as_run, run

    if found is None:
        discovery = plans_as_run(loaded, store)[0]
        summary = stored_summary(store, loaded.name, discovery.columns, scales=numeric_scales(loaded.controls))
    else:
        discovery, summary = found
    seen = {job.image_key for job in list(discovery.jobs) + list(discovery.out_of_frame)}
    store.require_readable(loaded.path)  # findings of the rows that read would not be the run's
    if summary.accuracy is None:
        raise UserError(f"{loaded.path}: no results to confirm yet; run: sweep3d run {loaded.path}")
    space = space_of(loaded)
    if claims is None:
        claims = findings_claims(loaded, store, summary, space)
    first = max(1, renders // 2)
    wanted = max(first, (renders if cap is None else cap) // 2)
    if render_budget is not None and claims:  # no claim gets four even shares' worth of pairs: draw no more
        wanted = min(wanted, max(first, 4 * render_budget // len(claims)))
    candidates = {c.key: draw_pairs(space, c, OVERDRAW * wanted, seed) for c in claims}
    rows = [row for c in claims for pair in candidates[c.key] for row in pair]
    chosen: dict[str, list[tuple[Row, Row]]] = {c.key: [] for c in claims}
    chosen_keys: dict[str, list[tuple[str, str]]] = {c.key: [] for c in claims}
    if rows:
        probe = _variant(loaded, space, rows)
        jobs = _jobs_by_index(plans_as_run(probe, store)[0])
        order = iter(scene_order(space, rows))
        for c in claims:
            used = set(seen)  # the run's images and this claim's own twins: never another claim's choice,
            for pair in candidates[c.key]:  # so a claim's pairs do not depend on the claims beside it
                twins = [jobs.get(next(order)), jobs.get(next(order))]
                keys = [j.image_key if j is not None and j.in_frame else None for j in twins]
                if len(chosen[c.key]) < wanted and None not in keys and not (set(keys) & used) and keys[0] != keys[1]:
                    chosen[c.key].append(pair)
                    chosen_keys[c.key].append((twins[0].render_key, twins[1].render_key))
                    used.update(keys)
    available = {c.key: len(chosen[c.key]) for c in claims}
    if render_budget is not None:  # one look, each claim's pairs as many as the budget's renders allot it
        counts = allotted([chosen_keys[c.key] for c in claims], render_budget,
                          None if weights is None else [weights.get(c.key, evidence_rate(None)) for c in claims])
        chosen = {c.key: chosen[c.key][:n] for c, n in zip(claims, counts)}
        first = wanted = max([1, *counts])
    taken = {c.key: 0 for c in claims}
    totals = {"rendered": 0, "cached": 0, "failed": 0, "jobs": 0}
    judged: dict[str, list[tuple[Twin, Twin]]] = {}

    def observe(asked: Any) -> dict[int, Any]:
        """Render and judge the first ``asked[i]`` pairs of each open claim (the others keep theirs)."""
        for i, n in asked.items():
            taken[claims[i].key] = max(taken[claims[i].key], min(n, len(chosen[claims[i].key])))
        fresh = [row for c in claims for pair in chosen[c.key][:taken[c.key]] for row in pair]
        outcomes: dict[int, Twin] = {}
        if fresh:
            variant = _variant(loaded, space, fresh)
            result = run(variant, console, executor=executor)
            render = next((o for o in result.outcomes if o.stage == "render"), None)
            before = totals["rendered"]  # made by an earlier look of this call: not found in the store
            totals["rendered"] += render.computed if render else 0
            totals["cached"] = max(0, (render.cached if render else 0) - before)
            totals["failed"] = result.failed
            totals["jobs"] = len(fresh)
            outcomes = _outcomes(store, variant.name)
        out = {}
        for (i, c), twins in zip(enumerate(claims), twin_outcomes(space, fresh, outcomes,
                                                                 [chosen[c.key][:taken[c.key]] for c in claims])):
            kept = [(a, b) for a, b in twins if a and b and a[0] and b[0]]
            judged[c.key] = kept
            out[i] = tally((a[1], b[1]) for a, b in kept)
        return out

    verdicts = sequential(len(claims), first, wanted, observe)
    confirmations = [Confirmation(c, taken[c.key], v, available[c.key]) for c, v in zip(claims, verdicts)]
    rendered, cached, failed = totals["rendered"], totals["cached"], totals["failed"]
    fresh_jobs = totals["jobs"]
    write_verdicts(store, loaded.name, {
        x.claim.key: {"text": x.claim.text, "verdict": x.verdict.as_dict(), "renders": renders, "seed": seed,
                      "drawn": x.drawn, "experiment": loaded.name + SUFFIX} for x in confirmations})
    keys = {c.key: chosen_keys[c.key][:taken[c.key]] for c in claims}
    return ConfirmResult(loaded.name + SUFFIX, confirmations, fresh_jobs, rendered, cached, failed, renders,
                         {c.key: chosen[c.key][:taken[c.key]] for c in claims}, judged, keys,
                         distinct_renders(keys.values()))


def distinct_renders(groups: Any) -> int:
    """The distinct renders of groups of twin pairs' render keys."""
    return len({key for group in groups for pair in group for key in pair})


def allotted(keys: list[list[tuple[str, str]]], budget: int, weights: list[float] | None = None) -> list[int]:
    """The pairs each claim gets (a prefix of its ``keys``, each pair's two render keys) within
    ``budget`` distinct renders, cached or not. Over and over, it buys the renders worth the most
    per render: a claim's next few pairs (up to :data:`LOOKAHEAD`), counted with every pair, of
    any claim, that those renders make free (a blur boundary's twin is one render, and the
    per-object and per-environment blur boundaries' and the object claims' twins in its scene are
    that render too), worth :func:`_worth`'s; until nothing left is worth a render
    (:data:`WORTH_A_RENDER`). Looking a few pairs ahead lets a claim that needs several pairs
    before any could confirm it be bought whole, not spread thin. ``weights``: each claim's
    expected z per root pair (:func:`evidence_rate`). It reads only the keys and the weights,
    never a fresh outcome: what a claim gets cannot depend on how its twins turn out."""
    critical = None if weights is None else _STANDARD.inv_cdf(1 - ALPHA / max(1, len(keys)))
    held: set[str] = set()

    def extended(counts: list[int], have: set[str]) -> list[int]:
        out = list(counts)
        for i, group in enumerate(keys):
            while out[i] < len(group) and have.issuperset(group[out[i]]):
                out[i] += 1
        return out

    taken = extended([0] * len(keys), held)
    while True:
        now = _worth(taken, weights, critical)
        best: tuple[float, set[str]] | None = None
        for i, group in enumerate(keys):
            new: set[str] = set()
            for k in range(taken[i], min(len(group), taken[i] + LOOKAHEAD)):
                new |= set(group[k]) - held
                if len(held) + len(new) > budget:
                    break
                gain = (_worth(extended(taken, held | new), weights, critical) - now) / len(new)
                if best is None or gain > best[0] + 1e-12:
                    best = (gain, set(new))
        if best is None or best[0] <= (1e-12 if weights is None else WORTH_A_RENDER):
            return taken
        held |= best[1]
        taken = extended(taken, held)


#: Pairs of one claim :func:`allotted` weighs buying together.
LOOKAHEAD = 16
#: The least gain a render must bring, in expected confirmations, to be bought (with weights).
WORTH_A_RENDER = 1e-3
_STANDARD = NormalDist()  # one standard normal for the allotment's inner loop


def _worth(counts: list[int], weights: list[float] | None = None, critical: float | None = None) -> float:
    """What claims' pair counts are worth to the decisions. Without ``weights``, each claim's square
    root (a finding's evidence grows as the root of its pairs): a render goes where it lifts a
    claim with few pairs before one with many. With them, the expected number of claims
    confirmed: each claim's chance that its z (weight × root of its pairs, on average) clears
    ``critical``, so a render goes where it moves a claim towards a decision, none to a claim
    already likely decided or out of reach."""
    if weights is None or critical is None:
        return sum(math.sqrt(n) for n in counts)
    return sum(_STANDARD.cdf(w * math.sqrt(n) - critical) if n else 0.0 for n, w in zip(counts, weights))


def evidence_rate(difference: float | None) -> float:
    """The expected z of a finding's fresh twins per root pair, from the run's accuracy difference
    inside less outside: McNemar's z is about ``|d| √n / √p`` with ``p`` the share of discordant
    pairs, at least ``|d|`` (taken as ``|d|`` + 0.1). An unknown difference counts as 0.3's. From
    the run's data alone, it decides where renders go, never a verdict."""
    d = 0.3 if difference is None or not math.isfinite(difference) else min(1.0, abs(difference))
    return d / math.sqrt(d + 0.1)


def twin_outcomes(space: Space, fresh: list[Row], outcomes: dict[int, Twin],
                  pairs: list[list[tuple[Row, Row]]]) -> list[list[tuple[Twin | None, Twin | None]]]:
    """Each group of ``pairs`` (whose rows, in order, are ``fresh``) as the results of its twins
    (``outcomes``: job → twin, the jobs of a plan of ``fresh``; None where a twin has none)."""
    index = iter(scene_order(space, fresh))
    return [[(outcomes.get(next(index)), outcomes.get(next(index))) for _ in group] for group in pairs]


def render_twins(loaded: LoadedSpec, space: Space, store: Store, pairs: list[list[tuple[Row, Row]]],
                 console: Console | None, executor: Executor, suffix: str,
                 render: dict[str, Any] | None = None) -> tuple[Any, list[list[tuple[Twin | None, Twin | None]]]]:
    """Render and judge ``pairs`` (groups of twin pairs) as the experiment ``<name><suffix>``, with
    ``render`` over the spec's ``[render]`` settings (another engine); returns the run's result and
    each group's twins' results (:func:`twin_outcomes`)."""
    fresh = [row for group in pairs for pair in group for row in pair]
    result, outcomes = render_rows(loaded, space, store, fresh, console, executor, suffix, render)
    found = iter(outcomes)
    return result, [[(next(found), next(found)) for _ in group] for group in pairs]


def render_rows(loaded: LoadedSpec, space: Space, store: Store, rows: list[Row], console: Console | None,
                executor: Executor, suffix: str, render: dict[str, Any] | None = None) -> tuple[Any, list[Twin | None]]:
    """Render and judge ``rows`` (configurations) as the experiment ``<name><suffix>``, with ``render``
    over the spec's ``[render]`` settings; returns the run's result (None without rows) and each
    row's result, in order (None where a job has none: out of frame, failed)."""
    from sweep3d.runner import run

    if not rows:
        return None, []
    variant = _variant(loaded, space, rows, suffix, render)
    if console is not None:  # names the progress lines that follow: one follow-up runs several of these
        console.print(f"{escape(variant.name)}: {len(rows)} fresh configurations on {variant.spec.render.engine}",
                      highlight=False, soft_wrap=True)
    result = run(variant, console, executor=executor)
    outcomes = _outcomes(store, variant.name)
    return result, [outcomes.get(i) for i in scene_order(space, rows)]


def findings_claims(loaded: LoadedSpec, store: Store, summary: Summary, space: Space) -> list[Claim]:
    """The claims of the findings the summary names (:func:`sweep3d.results.listed_findings`) that
    fresh twins can test; :func:`claims_of` says why each other one cannot."""
    return [c for c in claims_of(loaded, store, summary, space).values() if isinstance(c, Claim)]


def claims_of(loaded: LoadedSpec, store: Store, summary: Summary, space: Space) -> dict[str, Claim | str]:
    """Each listed finding's key → its claim, or why fresh twins cannot test it (never left out)."""
    from sweep3d.results import BOUNDARY, FAILURE_MODE, listed_findings

    names = {"object": [o.name for o in loaded.objects], "environment": [e.name for e in loaded.environments]}
    findings = listed_findings(summary)
    levels = {(p, label): (value, width) for p, label, value, width in summary.levels}
    spaces = {p.column: p.space for p in space.parameters}
    out: dict[str, Claim | str] = {}
    for finding in findings:
        row = finding.source
        claim: Claim | None
        if finding.kind == FAILURE_MODE:
            column, label = row["column"], row["label"]
            parameter = space.parameter(column)
            if parameter is None and column not in names:
                out[finding.key] = f"{column} is not a parameter the spec varies now"
                continue
            value, width = levels.get((column, label), (None, None))
            claim = value_claim(column, label, finding.text, None if parameter is None else parameter.space,
                                names.get(column, ()), value, width)
            why = f"{column} has no other value to compare {label} with"
        elif finding.kind == BOUNDARY:
            parameter = space.parameter(row["parameter"])
            if parameter is None:
                out[finding.key] = f"{row['parameter']} is not a parameter the spec varies now"
                continue
            claim = boundary_claim(row, finding.text, parameter.space)
            why = "the spec's range has no value on one side of the boundary"
        else:
            claim = rule_claim(row, spaces)
            why = ("its conditions name no control parameter the spec varies (a box of objects and environments "
                   "alone is tested as their failure modes)")
        out[finding.key] = claim if claim is not None else why
    return out


def _variant(loaded: LoadedSpec, space: Space, rows: list[Row], suffix: str = SUFFIX,
             render: dict[str, Any] | None = None) -> LoadedSpec:
    """``loaded`` as the experiment ``<name><suffix>`` whose jobs are ``rows`` (first model only),
    with ``render`` over its ``[render]`` settings."""
    from sweep3d.stages.plan import TablePolicy, rows_by_scene

    policy = TablePolicy(TablePolicy.Params(file="(drawn by sweep3d confirm)"))
    policy.rows = rows_by_scene(rows, {p.column: (p.control_id, p.param) for p in space.parameters})
    experiment = loaded.spec.experiment.model_copy(update={"name": loaded.name + suffix})
    update: dict[str, Any] = {
        "experiment": experiment, "policy": PolicySpec(type="table", file="(drawn by sweep3d confirm)"),
        "models": [loaded.models[0]] if len(loaded.models) > 1 else loaded.spec.models}
    if render:
        update["render"] = loaded.spec.render.model_copy(update=render)
    spec = loaded.spec.model_copy(update=update)
    return dataclasses.replace(loaded, spec=spec, policy=policy)


def _jobs_by_index(plan: Any) -> dict[int, Any]:
    jobs = {}
    for job in plan.jobs:
        jobs[job.index] = _Placed(job.image_key, job.render_key, True)
    for job in plan.out_of_frame:
        jobs[job.index] = _Placed(job.image_key, job.render_key, False)
    return jobs


@dataclass(frozen=True)
class _Placed:
    image_key: str
    render_key: str
    in_frame: bool


def _outcomes(store: Store, experiment: str) -> dict[int, Twin]:
    """Job → (counted, correct, margin) of the fresh jobs' results."""
    con = connect(store, experiment, views="results")
    try:
        if not has_view(con, "results"):
            return {}
        have = {row[0] for row in con.execute("DESCRIBE results").fetchall()}
        margin = "margin" if "margin" in have else "NULL::DOUBLE"
        return {int(job): (bool(counted), bool(correct), None if m is None else float(m)) for job, counted, correct, m
                in con.execute(f"SELECT job, counted, coalesce(correct, false), {margin} FROM results").fetchall()}
    finally:
        con.close()
