"""The stability check: re-infer a seeded sample of a run's images under changes no eye sees
(:mod:`sweep3d.followups.stability.changes`) and record, per image and change, whether the verdict flipped;
each round also re-renders its images' scene neighbours (:mod:`sweep3d.followups.stability.scene`).

The sample is stratified by ``|margin|`` (the bins of ``results.fragile.MARGIN_EDGES``): bins take
turns, lowest first, each giving its next image in a seeded order, so the near-ties that decide
the fragile threshold are all checked when there are few of them, and every bin gets a share.

Each (image, model, change) is one row of the store's ``stability`` table under its
``stability_key`` (the prediction key, the change, the check's version, and the seed for a random
change), appended every few seconds as the check goes, so a second check recomputes nothing, a
larger sample adds only what is new, and a killed one resumes where it was stopped. The check
holds the store's writer lock from its start (``--wait`` waits for another command's). The
baseline is inferred again beside the changed images, by torch with the model's own
preprocessing, so a flip compares two answers of one computation.

The check hands the runner (:mod:`sweep3d.runner`) a plan of the sampled jobs, in sample order,
through the postprocess stage and its own :class:`StabilityStage`: the runner holds the lock,
shows progress and writes the rows, and the stage takes each image where inference takes it
(made in this process, else its blob, else made again from its render).
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from sweep3d.cache import Store, digest, utc_now
from sweep3d.core import UserError
from sweep3d.followups.stability.changes import CHANGES, RANDOM_CHANGES, changed, margins
from sweep3d.followups.stability.scene import SceneCheck
from sweep3d.followups.stability.sequential import Rounds, allot, run_rounds, threshold_range
from sweep3d.followups.stability.stored import SCHEMA  # the table's columns, declared once
from sweep3d.spec import LoadedSpec

#: Bumped when the check gives other rows for the same inputs.
STABILITY_VERSION = 1
DEFAULT_SAMPLE = 64


@dataclass
class Checked:
    """What one model's check did and found."""

    model: str
    sampled: int
    computed: int
    cached: int
    skipped: list[str]  # changes that do not apply (and why)
    bins: list[dict[str, Any]]  # stability_bins rows of the model
    changes: list[dict[str, Any]]  # stability_changes rows with n > 0
    threshold: float
    failures: int
    fragile_failures: int
    rounds: Rounds | None = None  # the sequential design's looks and decisions
    scene: Any = None  # the scene neighbours' SceneCheck (None: not checked)
    neighbourhood: list[dict[str, Any]] = dataclasses.field(default_factory=list)  # neighbourhood_accuracy rows
    fragile_range: tuple[int, int] = (0, 0)  # fragile failures as the undecided bins may yet fall
    threshold_range: tuple[float, float] = (0.0, 0.0)  # the threshold likewise


def stability_key(pred_key: str, change: str, seed: int) -> str:
    """The key of one change's row for one prediction; a deterministic change is the same under any seed."""
    value: dict[str, Any] = {"stage": "stability", "v": STABILITY_VERSION, "pred": pred_key, "change": change}
    if change in RANDOM_CHANGES:
        value["seed"] = seed
    return digest(value)


def ordered_bins(rows: list[tuple[str, float]], seed: int) -> list[list[str]]:
    """The prediction keys of ``rows`` ((pred_key, margin), distinct keys) per bin of ``|margin|``,
    each bin in an order seeded by ``seed``."""
    from sweep3d.results import MARGIN_EDGES

    bins: list[list[str]] = [[] for _ in MARGIN_EDGES]
    for key, margin in rows:
        index = next((i for i, edge in enumerate(MARGIN_EDGES[:-1]) if abs(margin) < edge), len(MARGIN_EDGES) - 1)
        bins[index].append(key)
    for keys in bins:
        keys.sort(key=lambda k: hashlib.sha256(f"{seed}\0{k}".encode()).digest())
    return bins


def interleaved(bins: list[list[str]], start: list[int], stop: list[int]) -> list[str]:
    """The keys ``bins[b][start[b]:stop[b]]`` of every bin, the bins taking turns, lowest first."""
    out: list[str] = []
    depth = 0
    while any(start[b] + depth < stop[b] for b in range(len(bins))):
        out += [bins[b][start[b] + depth] for b in range(len(bins)) if start[b] + depth < stop[b]]
        depth += 1
    return out


def stratified_sample(rows: list[tuple[str, float]], n: int, seed: int) -> list[str]:
    """``n`` prediction keys of ``rows`` ((pred_key, margin), distinct keys): bins of ``|margin|``
    take turns, lowest first, each giving its next key in an order seeded by ``seed``."""
    bins = ordered_bins(rows, seed)
    return interleaved(bins, [0] * len(bins), allot([0] * len(bins), [len(b) for b in bins], set(range(len(bins))), n))


def check_stability(spec: LoadedSpec, sample: int = DEFAULT_SAMPLE, seed: int = 0, console: Any = None,
                    wait: float = 0.0, executor: Any = None, max_sample: int | None = None,
                    scene: bool | None = None) -> list[Checked]:
    """Run the stability check of ``spec``'s results (every model of it); returns what each found.

    ``sample`` images first; with ``max_sample`` above it, rounds follow that give the margin bins
    still undecided against the fragile rule more images, the sample doubling up to ``max_sample``
    (:mod:`~sweep3d.followups.stability.sequential`). None: one round of ``sample``.

    It holds the store's writer lock from before it computes anything (``wait``: seconds to wait
    for another command holding it), and appends its rows every few seconds: a kill loses one
    batch, and the next check starts from what was stored. ``executor``: the runner's (local
    by default; on Ray, in its session). ``scene``: re-render each sampled job's scene neighbours too
    (:mod:`~sweep3d.followups.stability.scene`; None: the spec's ``[stability] scene``).

    Raises:
        UserError: no results yet, or an evaluator that does not rank classes.
        StoreBusyError: another command held the store's lock longer than ``wait``.
    """
    from sweep3d.results import no_results
    from sweep3d.runner import running
    from sweep3d.stages.render import LOCAL

    if spec.evaluator.kind != "classification":
        raise UserError(f"stability: [evaluator] kind = {spec.evaluator.kind!r}; the check reads the margin of "
                        "a classification verdict (kind = \"classification\")")
    store = Store(spec.store)
    if not spec.store.is_dir():  # before the lock would make the store's folder
        raise no_results(store, spec.name, spec.path)
    cap = sample if max_sample is None else max(sample, max_sample)
    scene = spec.spec.stability.scene if scene is None else scene
    with running(spec, executor=executor or LOCAL, wait=wait, console=console, store=store, leftovers=False) as runner:
        return [_check_model(spec, runner, settings, sample, seed, cap, scene) for settings in spec.spec.all_models]


def _check_model(spec: LoadedSpec, runner: Any, settings: Any, sample: int, seed: int, cap: int,
                 scene: bool = False) -> Checked:
    """The check of one model of ``spec`` (``settings``), the runner holding the store's lock: rounds
    of images until every margin bin is decided or ``cap`` images are checked."""
    from sweep3d.results import results_store
    from sweep3d.runner import plan_spec
    from sweep3d.stages.infer import ModelHandle

    handle = ModelHandle.resolve(spec, settings)
    model = settings.label if len(spec.spec.all_models) > 1 else None
    with results_store(spec) as reading:
        rows = _sampled_results(reading, spec, model)
    bins = ordered_bins(rows, seed)
    plan = plan_spec(spec, handle)
    by_key = {job.pred_key: job for job in plan.jobs}
    todo_changes = _applicable(handle, plan)
    wanted: dict[tuple[str, str], str] = {}
    stage = StabilityStage(handle, todo_changes, seed, wanted, runner.post, settings.batch_size, spec.path)
    taken = [0] * len(bins)
    cached = 0
    neighbours = SceneCheck.of(spec, runner, handle) if scene else None

    def observe(now: list[int]) -> list[tuple[int, int]]:
        nonlocal taken, cached
        keys = interleaved(bins, taken, now)
        missing = [k for k in keys if k not in by_key]
        if missing:
            raise UserError(f"{spec.path}: {len(missing)} sampled results are not in the spec's plan any more (the "
                            "spec changed since the run): `sweep3d run` it, then check again")
        wanted.update({(key, change): stability_key(key, change, seed) for key in keys for change in todo_changes})
        have = runner.store.key_set("stability")
        jobs = [by_key[k] for k in keys]
        todo = [job for job in jobs if stage.todo(job, have)]
        cached += len(jobs) - len(todo)
        # one stage after the other: the check infers in this thread, as it always did (torch's
        # answers depend on its threads), and a stop keeps every batch recorded before it
        runner.run(dataclasses.replace(plan, jobs=jobs, out_of_frame=[]), stages=("postprocess",), extra=(stage,),
                   overlap=False)  # in sample order
        left = [job for job in todo if stage.key(job) not in stage.done]
        if left:  # its input is not stored: nothing to re-infer
            stage.missing(left[0])
        if neighbours is not None:  # the same round's images, re-rendered one invisible step away
            neighbours.add(jobs)
        taken = list(now)
        return [(int(row["n"]), int(row["flips"])) for row in _read(spec, settings.label)[0]]

    rounds = run_rounds([len(b) for b in bins], sample, cap, observe)
    skipped = [f"{c}: {why}" for c, why in _inapplicable(handle, plan).items()]
    found = _found(spec, settings.label, rounds, len(stage.done), cached, skipped)
    found.scene = neighbours
    return found


def _sampled_results(store: Store, spec: LoadedSpec, model: str | None) -> list[tuple[str, float]]:
    """(pred_key, margin) of the counted results with a margin, one per prediction key."""
    from sweep3d.results import connect, no_results

    con = connect(store, spec.name, model=model, views="results")
    try:
        have = {row[0] for row in con.execute("DESCRIBE results").fetchall()} \
            if con.execute("SELECT count(*) FROM duckdb_views() WHERE view_name = 'results'").fetchone()[0] else set()
        if "margin" not in have:
            raise no_results(store, spec.name, spec.path)
        counted = "coalesce(counted_with_fragile, counted)" if "counted_with_fragile" in have else "counted"
        rows = con.execute(f"SELECT pred_key, any_value(margin) FROM results WHERE {counted} AND margin IS NOT NULL "
                           "GROUP BY pred_key ORDER BY pred_key").fetchall()
    finally:
        con.close()
    if not rows:
        raise no_results(store, spec.name, spec.path)
    return [(key, float(margin)) for key, margin in rows]


def _inapplicable(handle: Any, plan: Any) -> dict[str, str]:
    """Changes that cannot change this model's answers, and why."""
    from sweep3d.stages.infer import Preprocess

    view = handle.view
    if view is None:
        return {"resize": "the model's preprocessing is not sweep3d's Preprocess"}
    side = handle.framing.crop or handle.framing.size
    scale = view.resize / side
    if handle.framing.model or max(view.crop, round(side * scale)) == side:
        return {"resize": "the model does not resize these images (they are its input)"}
    assert isinstance(view, Preprocess)
    return {}


def _applicable(handle: Any, plan: Any) -> list[str]:
    skip = _inapplicable(handle, plan)
    return [c for c in CHANGES if c not in skip]


class StabilityStage:
    """The check's own stage, after postprocess: it re-infers each sampled image, and its changed
    copies, and records one row per change (:attr:`Computed.rows`). A job's key is its first
    change's row's; a job with that row but not every other is computed again (:meth:`incomplete`),
    its stored rows left as they are."""

    name = "stability"
    table = "stability"
    owns_blobs = False
    side_tables: dict[str, pa.Schema] = {}

    def __init__(self, handle: Any, changes: list[str], seed: int, wanted: dict[tuple[str, str], str],
                 post: Any, batch_size: int = 32, spec_path: Any = "SPEC") -> None:
        self.handle, self.changes, self.seed, self.wanted = handle, changes, seed, wanted
        self.spec_path = spec_path
        self.handoff = post.handoff
        #: as the infer stage's: an image that is not stored is made again from its render
        self.blob_inputs = ("renders", "images") if post.store_images else ("renders",)
        self.batch = max(1, batch_size // (1 + len(changes)))  # this model's batch, shared by the changed copies
        self.done: set[str] = set()  # the keys computed

    def schema(self, plan: Any) -> pa.Schema:
        return SCHEMA

    def key(self, job: Any) -> str:
        return self.wanted[(job.pred_key, self.changes[0])]

    def upstream(self, job: Any) -> tuple[str, str]:
        return ("renders" if job.image_key == job.render_key else "images", job.image_key)

    def todo(self, job: Any, have: set[str]) -> bool:
        """Whether a row of ``job``'s changes is missing from ``have`` (the stored keys)."""
        return any(self.wanted[(job.pred_key, c)] not in have for c in self.changes)

    def incomplete(self, plan: Any, store: Store, cached: set[str]) -> set[str]:
        have = store.key_set("stability")
        return {self.key(job) for job in plan.jobs if self.key(job) in cached and self.todo(job, have)}

    def missing(self, job: Any) -> None:
        """Raise: ``job``'s image can be neither read nor made again."""
        raise UserError(f"stability: the image of job {job.index} is missing from the store "
                        f"(render key {job.render_key}); run `sweep3d run {self.spec_path}` first")

    def compute(self, todo: Any, plan: Any, store: Store) -> Any:
        """Infer the baseline and each change of ``todo``'s images, batch by batch."""
        from sweep3d.stages.infer import ModelInputs, object_class_ids

        model = self.handle.classifier()
        other = _other_arithmetic(model)
        truths = object_class_ids(plan, model.label_map(), self.handle.name)
        images = ModelInputs(store, plan, todo, self.handoff)
        have = store.key_set("stability")
        name, changes, seed, wanted = self.handle.name, self.changes, self.seed, self.wanted
        part: list = []
        for job in todo:
            part.append(job)
            if len(part) < self.batch:
                continue
            yield from self._batch(part, images, model, other, truths, have, name, changes, seed, wanted)
            part = []
        if part:
            yield from self._batch(part, images, model, other, truths, have, name, changes, seed, wanted)

    def _batch(self, part: list, images: Any, model: Any, other: Any, truths: dict, have: set[str], name: str,
               changes: list[str], seed: int, wanted: dict[tuple[str, str], str]) -> Any:
        from sweep3d.core import from_uint8
        from sweep3d.driver import Computed
        from sweep3d.stages.infer import predict

        pixels = [images.pixels(job) for job in part]
        for job, image in zip(part, pixels):
            if isinstance(image, tuple):
                self.missing(job)
        ids = [truths[job.object] for job in part]
        base = predict(model, from_uint8(np.stack(pixels)), name)
        answers = {}
        for change in [c for c in changes if any(wanted[(job.pred_key, c)] not in have for job in part)]:
            if change == "resize":
                answers[change] = predict(other, from_uint8(np.stack(pixels)), name)
            else:
                moved = [changed(p, change, seed, job.image_key) for p, job in zip(pixels, part)]
                answers[change] = predict(model, from_uint8(np.stack(moved)), name)
        by_job: dict[str, list[dict[str, Any]]] = {job.pred_key: [] for job in part}
        for row in _rows(part, ids, base, answers, seed, wanted):
            if row["stability_key"] not in have:
                by_job[row["pred_key"]].append(row)
        for job in part:
            self.done.add(self.key(job))
            yield Computed(self.key(job), rows=by_job[job.pred_key])


def _other_arithmetic(model: Any) -> Any:
    """The model with its resize computed in the other arithmetic (8-bit against float)."""
    preprocess = model.preprocess
    if not hasattr(preprocess, "arithmetic"):
        return model
    flipped = "float" if preprocess.arithmetic == "uint8" else "uint8"
    return dataclasses.replace(model, preprocess=dataclasses.replace(preprocess, arithmetic=flipped))


def _rows(jobs: list, ids: list, base: np.ndarray, answers: dict[str, np.ndarray], seed: int,
          wanted: dict[tuple[str, str], str]) -> list[dict[str, Any]]:
    """The table rows of one batch: per job and change, the baseline's and the change's verdicts;
    an image whose logits are not finite (either side) gives no row (it is not counted anyway)."""
    base_margin = margins(base, ids)
    base_correct = base.argmax(axis=1)
    now = utc_now()
    out = []
    for change, logits in answers.items():
        margin = margins(logits, ids)
        top = logits.argmax(axis=1)
        for i, job in enumerate(jobs):
            if not (np.isfinite(base_margin[i]) and np.isfinite(margin[i])):
                continue
            right, was = bool(int(top[i]) in ids[i]), bool(int(base_correct[i]) in ids[i])
            out.append({"stability_key": wanted[(job.pred_key, change)], "pred_key": job.pred_key,
                        "image_key": job.image_key, "change": change,
                        "seed": seed if change in RANDOM_CHANGES else None, "base_correct": was,
                        "base_margin": float(base_margin[i]), "correct": right, "margin": float(margin[i]),
                        "flipped": right != was, "created_at": now})
    return out


def _found(spec: LoadedSpec, model: str, rounds: Rounds, computed: int, cached: int, skipped: list[str]) -> Checked:
    """What the views say of ``model`` once its rows are stored, with the fragile count as the
    undecided bins may yet fall."""
    from sweep3d.results import MARGIN_EDGES

    decisions = rounds.decisions
    low, high = threshold_range(MARGIN_EDGES, decisions) if decisions else (0.0, 0.0)
    bins, changes, threshold, failures, fragile, (at_least, at_most) = _read(spec, model, (low, high))
    return Checked(model, rounds.sample, computed, cached, skipped, bins, changes, threshold, failures, fragile,
                   rounds=rounds, fragile_range=(at_least, at_most), threshold_range=(low, high),
                   neighbourhood=_neighbourhood(spec, model))


def _read(spec: LoadedSpec, model: str, thresholds: tuple[float, ...] = ()) -> tuple:
    """``model``'s stability_bins rows, stability_changes rows, threshold, failures, fragile
    failures, and the fragile failures under each of ``thresholds`` (``|margin|`` below it, or
    flipped in the check)."""
    from sweep3d.results import connect, literal, results_store

    several = len(spec.spec.all_models) > 1
    with results_store(spec) as reading:
        con = connect(reading, spec.name, model=model if several else None, views="results")
        try:
            have = {row[0] for row in con.execute("DESCRIBE results").fetchall()}
            shown = con.execute("SELECT any_value(model) FROM results").fetchone()[0] if "model" in have else None
            where = f"model IS NOT DISTINCT FROM {'NULL' if shown is None else literal(shown)}"
            bins = _dicts(con, f"SELECT * FROM stability_bins WHERE {where} ORDER BY bin")
            changes = _dicts(con, f"SELECT * FROM stability_changes WHERE {where} AND n > 0 ORDER BY change, bin")
            threshold = con.execute(f"SELECT threshold FROM fragile_threshold WHERE {where}").fetchone()
            counted = "coalesce(counted_with_fragile, counted)" if "counted_with_fragile" in have else "counted"
            failures, fragile = con.execute(f"SELECT count(*) FILTER (WHERE {counted} AND NOT correct), count(*) "
                                            f"FILTER (WHERE {counted} AND NOT correct AND fragile) FROM results").fetchone()
            under = [con.execute(
                f"SELECT count(*) FROM results r LEFT JOIN (SELECT pred_key, flipped FROM stability_images WHERE {where}) "
                f"i USING (pred_key) WHERE {counted} AND NOT r.correct AND r.margin IS NOT NULL "
                f"AND (abs(r.margin) < {float(t)!r}::DOUBLE OR coalesce(i.flipped, false))").fetchone()[0]
                for t in thresholds]
        finally:
            con.close()
    return (bins, changes, float(threshold[0]) if threshold else 0.0, int(failures), int(fragile or 0),
            tuple(int(u) for u in under))


def _neighbourhood(spec: LoadedSpec, model: str) -> list[dict[str, Any]]:
    """``model``'s ``neighbourhood_accuracy`` rows (none before a scene check)."""
    from sweep3d.results import connect, literal, results_store

    several = len(spec.spec.all_models) > 1
    with results_store(spec) as reading:
        con = connect(reading, spec.name, model=model if several else None, views="results")
        try:
            where = f"model = {literal(model)}" if several else "true"
            return _dicts(con, f"SELECT * FROM neighbourhood_accuracy WHERE {where}")
        finally:
            con.close()


def _dicts(con: Any, sql: str) -> list[dict[str, Any]]:
    cursor = con.execute(sql)
    names = [d[0] for d in cursor.description]
    return [dict(zip(names, row)) for row in cursor.fetchall()]
