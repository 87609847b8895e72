"""The stability check in the scene: re-render each sampled job's neighbours
(:mod:`~sweep3d.followups.stability.neighbours`) and record, per neighbour, whether its verdict
differs from its job's.

The neighbours are explicit jobs of a second experiment, ``<name>-stability`` (per model when the
spec has several: ``<name>-stability-<model>``), planned through the ``table`` policy with its rows
given in memory and run by the check's runner through the standard stages: the same keys and
cache as any run, so a second check renders nothing, a killed one resumes from what its renders
and predictions stored, and it runs on whatever executor the check was given. Each round of the
sequential design adds the neighbours of its new images; the experiment's jobs are every
neighbour planned so far.

A neighbour's verdict is compared with its base job's as the run stored them (the same model and
backend: one computation on two scenes). Each comparison is one row of the ``stability`` table
under the base job's prediction key, its change named ``yaw+1°`` and so on, keyed by the
neighbour's prediction key too (``neighbour_key``), so the views count a flip under a neighbour
as they count one under an image change. A neighbour out of frame, hidden, or without a valid
prediction (nor a base without one) gives no row: it has no verdict to compare.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from sweep3d.cache import Store, digest, utc_now
from sweep3d.followups.stability.neighbours import Move, neighbours, plan_moves
from sweep3d.spec import Choice, LoadedSpec, PolicySpec, Range

#: Bumped when the scene rows change for the same inputs.
SCENE_VERSION = 1
SUFFIX = "-stability"


def scene_key(pred_key: str, change: str, neighbour_key: str) -> str:
    """The key of one neighbour's row: the base prediction, the change and the neighbour's prediction."""
    return digest({"stage": "stability", "scene": SCENE_VERSION, "pred": pred_key, "change": change,
                   "neighbour": neighbour_key})


def variant_name(loaded: LoadedSpec, model: Any) -> str:
    """The neighbours' experiment: ``<name>-stability``, and the model's id after it when there are several."""
    several = len(loaded.spec.all_models) > 1
    return loaded.name + SUFFIX + (f"-{model.label}" if several else "")


def sizes_of(loaded: LoadedSpec) -> dict[str, float]:
    """The ``[stability]`` step sizes of ``loaded``."""
    settings = loaded.spec.stability
    return {"angle": settings.angle, "distance": settings.distance, "light": settings.light,
            "hdri_rotation": settings.hdri_rotation}


def neighbours_per_image(loaded: LoadedSpec) -> int:
    """The most scene neighbours one sampled image gets (two per moved parameter): what a check
    of n images renders at most, n times this."""
    moves, _ = plan_moves(loaded.controls, sizes_of(loaded))
    return 2 * len(moves)


@dataclass
class Neighbour:
    """One neighbour of a sampled job, as planned."""

    base: Any  # the run's Job
    change: str
    row: dict[str, Any]  # object, environment and each open parameter's value


def neighbour_rows(loaded: LoadedSpec, job: Any, moves: list[Move]) -> list[Neighbour]:
    """``job``'s neighbours as design rows: its open values with one moved."""
    open_params = [(inst.id, param) for inst in loaded.controls if inst.applies_to(job.object, job.environment)
                   for param, space in inst.spaces.items() if isinstance(space, (Choice, Range))]
    values = job.values
    base = {"object": job.object, "environment": job.environment,
            **{f"{cid}_{param}": values[cid][param] for cid, param in open_params}}
    return [Neighbour(job, change, {**base, move.column: value}) for change, move, value in neighbours(values, moves)]


def variant(loaded: LoadedSpec, model: Any, rows: list[dict[str, Any]], moves: list[Move]) -> LoadedSpec:
    """``loaded`` as the neighbours' experiment whose jobs are ``rows`` (``model`` only). A moved
    list takes its neighbours' values as options of its own (they are points beside its points)."""
    from sweep3d.stages.plan import TablePolicy, rows_by_scene

    extra: dict[tuple[str, str], list[Any]] = {}
    for move in moves:
        if isinstance(move.space, Choice):
            seen = set(move.space.options)
            values = [r[move.column] for r in rows if move.column in r and r[move.column] not in seen]
            extra[(move.control_id, move.param)] = sorted(set(values))
    controls = [dataclasses.replace(inst, spaces={
        param: Choice((*space.options, *extra[(inst.id, param)])) if extra.get((inst.id, param)) else space
        for param, space in inst.spaces.items()}) for inst in loaded.controls]
    columns = {f"{inst.id}_{param}": (inst.id, param) for inst in controls for param, space in inst.spaces.items()
               if isinstance(space, (Choice, Range))}
    what = "(the neighbours of sweep3d stability)"
    policy = TablePolicy(TablePolicy.Params(file=what))
    policy.rows = rows_by_scene(rows, columns)
    experiment = loaded.spec.experiment.model_copy(update={"name": variant_name(loaded, model)})
    update: dict[str, Any] = {"experiment": experiment, "policy": PolicySpec(type="table", file=what)}
    if loaded.spec.models:
        update["models"] = [model]
    return dataclasses.replace(loaded, spec=loaded.spec.model_copy(update=update), policy=policy, controls=controls)


def scene_order(loaded: LoadedSpec, rows: list[dict[str, Any]]) -> list[int]:
    """Each row's job index in a plan of ``rows``: scenes in spec order, a scene's rows as given."""
    from sweep3d.stages.plan import design_order

    return design_order([o.name for o in loaded.objects], [e.name for e in loaded.environments], rows)


@dataclass
class SceneCheck:
    """The neighbours of one model's check, round after round (see the module)."""

    loaded: LoadedSpec
    runner: Any
    handle: Any  # the model's ModelHandle
    moves: list[Move]
    skipped: dict[str, str]
    several: bool = False
    planned: list[Neighbour] = field(default_factory=list)
    rendered: int = 0  # renders made by this check
    cached: int = 0  # neighbours whose rows were stored before this check
    computed: int = 0  # neighbours compared now
    out_of_frame: int = 0
    no_verdict: int = 0  # in frame, but a side without a counted verdict
    failed: int = 0  # stage failures (renders that failed twice)
    done: set[str] = field(default_factory=set)  # the rows' keys this check found or wrote
    outside: set[tuple[str, str]] = field(default_factory=set)  # (base prediction, change) out of frame

    @classmethod
    def of(cls, loaded: LoadedSpec, runner: Any, handle: Any) -> SceneCheck:
        moves, skipped = plan_moves(loaded.controls, sizes_of(loaded))
        return cls(loaded, runner, handle, moves, skipped, several=len(loaded.spec.all_models) > 1)

    @property
    def name(self) -> str:
        return variant_name(self.loaded, self.handle.settings)

    def add(self, jobs: list[Any]) -> None:
        """Plan, render and compare the neighbours of ``jobs`` (the round's new images)."""
        from sweep3d.runner import plan_spec, write_jobs

        for job in jobs:
            self.planned += neighbour_rows(self.loaded, job, self.moves)
        if not self.planned:
            return
        spec = variant(self.loaded, self.handle.settings, [n.row for n in self.planned], self.moves)
        plan = plan_spec(spec, self.handle)
        placed = {j.index: j for j in plan.jobs}
        indexes = scene_order(self.loaded, [n.row for n in self.planned])
        store: Store = self.runner.store
        have = store.key_set("stability")
        pending: list[tuple[Neighbour, Any]] = []
        for n, index in zip(self.planned, indexes):
            job = placed.get(index)
            if job is None:
                if (n.base.pred_key, n.change) not in self.outside:
                    self.outside.add((n.base.pred_key, n.change))
                    self.out_of_frame += 1
                continue
            key = scene_key(n.base.pred_key, n.change, job.pred_key)
            if key in have:
                if key not in self.done:
                    self.cached += 1
                    self.done.add(key)
                continue
            if key not in self.done:
                pending.append((n, job))
        if not pending:
            return
        wanted = dataclasses.replace(plan, jobs=[job for _, job in pending], out_of_frame=[])
        outcomes = self.runner.run(wanted, self.handle, several=self.several)
        render = next((o for o in outcomes if o.stage.split(" ", 1)[0] == "render"), None)
        self.rendered += render.computed if render else 0
        self.failed += sum(o.failed for o in outcomes)
        write_jobs(plan, store)
        rows = self._rows(spec, pending)
        store.append("stability", rows, schema=_schema())
        for n, job in pending:
            self.done.add(scene_key(n.base.pred_key, n.change, job.pred_key))

    def _rows(self, spec: LoadedSpec, pending: list[tuple[Neighbour, Any]]) -> list[dict[str, Any]]:
        """The ``stability`` rows of ``pending`` (neighbour, its planned job) with a verdict on both sides."""
        label = self.handle.settings.label if self.several else None
        bases = _verdicts(self.runner.store, self.loaded.name, label, {n.base.pred_key for n, _ in pending})
        theirs = _verdicts(self.runner.store, spec.name, None, {job.pred_key for _, job in pending})
        now = utc_now()
        rows = []
        for n, job in pending:
            base, other = bases.get(n.base.pred_key), theirs.get(job.pred_key)
            if base is None or other is None:
                self.no_verdict += 1
                continue
            self.computed += 1
            rows.append({"stability_key": scene_key(n.base.pred_key, n.change, job.pred_key),
                         "pred_key": n.base.pred_key, "image_key": n.base.image_key, "change": n.change,
                         "seed": None, "base_correct": base[0], "base_margin": base[1], "correct": other[0],
                         "margin": other[1], "flipped": base[0] != other[0], "created_at": now,
                         "neighbour_key": job.pred_key})
        return rows

    def skipped_lines(self) -> list[str]:
        """The varied parameters the neighbours do not move, each with its reason."""
        return [f"{column}: {why}" for column, why in self.skipped.items()]


def _schema() -> Any:
    from sweep3d.followups.stability.stored import SCHEMA

    return SCHEMA


def _verdicts(store: Store, experiment: str, model: str | None, keys: set[str]) -> dict[str, tuple[bool, float]]:
    """pred_key → (correct, margin) of ``experiment``'s counted results with a margin among ``keys``."""
    from sweep3d.results import connect, has_view

    con = connect(store, experiment, model=model, views="results")
    try:
        if not has_view(con, "results"):
            return {}
        have = {row[0] for row in con.execute("DESCRIBE results").fetchall()}
        counted = "coalesce(counted_with_fragile, counted)" if "counted_with_fragile" in have else "counted"
        rows = con.execute(f"SELECT pred_key, any_value(correct), any_value(margin) FROM results WHERE {counted} "
                           "AND margin IS NOT NULL AND pred_key IN (SELECT unnest(?)) GROUP BY pred_key",
                           [sorted(keys)]).fetchall()
    finally:
        con.close()
    return {key: (bool(correct), float(margin)) for key, correct, margin in rows}
