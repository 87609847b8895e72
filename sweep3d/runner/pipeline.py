"""Run a spec through plan → render → postprocess → infer, resumable at any point.

The process holding the store's lock is its single writer. Each stage computes only the keys
the store lacks, and flushes rows every few seconds, so a killed run resumes where it stopped.
The stages overlap (``driver.loop``): images are postprocessed and inferred in this process
while the Blender workers render the next ones.

Before anything is rendered the model is loaded and tried on a blank image (when anything
needs inferring), so a broken model fails in seconds. The experiment's jobs table is written
once its stages have run, so a run that stops on a user error leaves the store's tables as they
were.
"""

from __future__ import annotations

import hashlib
import json
import time
import uuid
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Iterable

import pyarrow as pa
from rich.console import Console
from rich.markup import escape

from sweep3d.assets import blender_version
from sweep3d.cache import MIN_JOBS as SNAPSHOT_MIN_JOBS
from sweep3d.cache import (
    TABLES,
    Store,
    atomic_write,
    compact_table,
    remember_written,
    remove_killed_writers_temp_files,
    utc_now,
    written_from,
)
from sweep3d.core import RenderError, SpecError, UserError, encode_png8
from sweep3d.driver import (
    PLUGINS_METADATA,
    SPEC_METADATA,
    Found,
    Plan,
    StageOutcome,
    add_outcomes,
    merge_outcomes,
    rows_and_cached,
    spec_identity,
    stage_counts,
    unique_jobs,
)
from sweep3d.driver import metadata as plugins_metadata
from sweep3d.runner import settled
from sweep3d.runner.runner import Runner, running
from sweep3d.spec import CLASS_NAMES_METADATA, MODELS_METADATA, PROTOCOL_METADATA, LoadedSpec
from sweep3d.stages.infer import ModelHandle
from sweep3d.stages.plan import History, Outcome, make_plan
from sweep3d.stages.postprocess import PostprocessStage, make_image, post_controls, truth_digests
from sweep3d.stages.render import (
    LOCAL,
    Executor,
    RenderStage,
    device_note,
    remove_stale_scratch,
    scratch_root,
    slow_render_warning,
    variant_note,
)

AUTO_COMPACT_SEGMENTS = 64  # a run ends by merging a table's segments beyond this many


@dataclass
class RunResult:
    """What a run did. ``plan`` is its first model's plan; ``plans`` has one per model."""

    run_id: str
    plan: Plan
    plans: list[Plan] = field(default_factory=list)
    outcomes: list[StageOutcome] = field(default_factory=list)
    seconds: float = 0.0
    store: Store | None = None  # the run's store object (what it read stays checked for the findings)

    @property
    def failed(self) -> int:
        return sum(o.failed for o in self.outcomes)

    def outcome(self, stage: str, model: str | None = None) -> StageOutcome:
        """What ``stage`` did (``"render"``, ``"postprocess"``, ``"infer"``). A run of several
        models has an infer stage per model, ``"infer <model>"``: name it, or give ``model=``.

        Raises:
            UserError: for a stage the run did not have, listing those it had.
        """
        titles = [stage] if model is None else [f"{stage} {model}"]
        found = [o for o in self.outcomes if o.stage in titles]
        if model is None and not found:  # "infer" on a run of one model named by its id
            found = [o for o in self.outcomes if o.stage.split(" ", 1)[0] == stage]
        if len(found) == 1:
            return found[0]
        names = ", ".join(repr(o.stage) for o in self.outcomes)
        asked = repr(titles[0])
        if found:
            raise UserError(f"stage {asked} ran once per model: ask for one of {names} (or give model=)")
        raise UserError(f"no stage {asked} in this run; its stages: {names}")

    def __repr__(self) -> str:
        stages = ", ".join(f"{o.stage}: {o.computed} computed, {o.cached} cached, {o.failed} failed"
                           for o in self.outcomes)
        return (f"RunResult({self.run_id!r}, jobs={len(self.plan.jobs)}, models={[p.model for p in self.plans]}, "
                f"failed={self.failed}, seconds={self.seconds:.1f}, stages=[{stages}])")


def plan_spec(spec: LoadedSpec, model: ModelHandle | None = None, history: History | None = None,
              remember: Store | None = None) -> Plan:
    """The plan of ``spec`` for this machine's Blender and one of its models (default: the first,
    resolved if not given); ``remember``: a store whose lock the caller holds, where an unchanged
    plan's keys are read back instead of hashed again (``stages.plan.keys_memo``)."""
    model = model or ModelHandle.resolve(spec)
    return make_plan(spec, framing=model.framing, model_digest=model.digest, blender=blender_version(),
                     history=history, model=model.settings, classes=model.label_map(),
                     view=(model.view.resize, model.view.crop) if model.view is not None else None,
                     remember=remember)


def outcomes_by_scene(plan: Plan, store: Store) -> History:
    """What the model did on each job of ``plan``, per scene, for adaptive policies.

    A job with no valid prediction (its render failed, or the model gave NaN), or whose object
    is hidden (its visible fraction below ``[evaluator] min_visible``), counts as not failed
    with zero loss, so the search moves on instead of searching around what is not a model
    mistake. Tasks without a loss (detection, segmentation) use 1 - IoU.
    """
    con = store.connect()
    rows: dict[str, tuple] = {}
    if store.segments("predictions"):
        keys = list({j.pred_key for j in plan.jobs})
        roles = plan.evaluator_record().roles  # the run's evaluator, whatever else the store holds
        loss = f'"{roles.loss}"' if roles.loss else f'1 - coalesce("{roles.iou}", 0)' if roles.iou else "0.0"
        rows = {r[0]: r[1:] for r in con.execute(
            f'SELECT pred_key, "{roles.valid}", "{roles.correct}", {loss} FROM predictions '
            "WHERE pred_key IN (SELECT unnest(?))", [keys]
        ).fetchall()}
    hidden = _hidden_truths(plan, store, con)
    history: History = {}
    for job in plan.jobs + plan.out_of_frame:
        valid, correct, loss = rows.get(job.pred_key, (False, None, None))
        valid = valid and job.truth_key not in hidden
        outcome = Outcome(failed=bool(valid and not correct), loss=float(loss) if valid and loss is not None else 0.0)
        history.setdefault(job.scene, {})[job.point] = outcome
    return history


def _hidden_truths(plan: Plan, store: Store, con) -> set[str]:
    """Truth keys of the plan whose object shows less than ``min_visible`` of itself."""
    keys = [j.truth_key for j in plan.jobs if j.truth_key is not None]
    if not keys or not store.segments("truths"):
        return set()
    return {r[0] for r in con.execute(
        "SELECT truth_key FROM truths WHERE truth_key IN (SELECT unnest(?)) "
        "AND coalesce(visible_fraction, 0) < ?", [keys, plan.spec.evaluator.min_visible]).fetchall()}


def write_jobs(plans: Plan | list[Plan], store: Store, digest: str | None = None) -> None:
    """Record the plans (one per model) as the experiment's jobs table (what ``results`` joins
    against); an unchanged table leaves the file as it is.

    A plan's digest (:func:`jobs_digest`; ``digest``: the caller's, made from the same plans) is
    remembered with the file it was written to (:mod:`sweep3d.cache.written`): a rerun of the
    same plan compares digests instead of building and encoding 10⁶ rows again, unless the file
    changed since.
    """
    plans = [plans] if isinstance(plans, Plan) else plans
    path = store.jobs_path(plans[0].spec.name)
    recorded = _recorded(plans)
    digest = digest or jobs_digest(plans, recorded)
    if digest is not None and written_from(store, path) == digest:
        return
    store.write_table_file(path, jobs_table(plans, recorded), keep_same=True)
    if digest is not None:
        remember_written(store, path, digest)


def jobs_digest(plans: list[Plan], recorded: dict[bytes, bytes] | None = None) -> str | None:
    """A digest of the jobs file ``plans`` make (:meth:`Plan.fingerprint`, what the run records
    beside them, :func:`_jobs_format`) without building it; None where a plan has none."""
    recorded = _recorded(plans) if recorded is None else recorded
    prints, salt = [plan.fingerprint() for plan in plans], _jobs_format()
    if None in prints or salt is None:
        return None
    return hashlib.sha256(b"\n".join([salt, *map(str.encode, prints), *recorded.values()])).hexdigest()  # type: ignore[arg-type]


def jobs_table(plans: list[Plan], recorded: dict[bytes, bytes] | None = None) -> pa.Table:
    """The experiment's jobs table of ``plans`` (one per model), with the metadata the views read
    and what the run recorded (``recorded``: :func:`_recorded` of the plans, when known)."""
    tables = [plan.table() for plan in plans]
    table = tables[0] if len(tables) == 1 else pa.concat_tables(tables, promote_options="default")
    per_model = {key: json.dumps({k: v for t in tables for k, v in json.loads(t.schema.metadata[key]).items()}).encode()
                 for key in (CLASS_NAMES_METADATA, PROTOCOL_METADATA)}  # each plan's entry under its model
    return table.replace_schema_metadata({**(tables[0].schema.metadata or {}), **per_model,
                                          **(recorded or _recorded(plans))})


def _recorded(plans: list[Plan]) -> dict[bytes, bytes]:
    """What the jobs table records of the run besides its plans: the models, the user plug-ins'
    code, and the identity of the spec (which tells a reader whether they are its jobs)."""
    spec = plans[0].spec
    return {MODELS_METADATA: json.dumps([plan.model for plan in plans]).encode(),
            PLUGINS_METADATA: plugins_metadata(spec), SPEC_METADATA: spec_identity(spec).encode()}


def plans_as_run(spec: LoadedSpec, store: Store) -> list[Plan]:
    """The plans (one per model) a run of ``spec`` would record as its jobs, from what ``store``
    holds: an adaptive policy's rounds are planned again from the stored outcomes, as the run
    planned them, until a round adds no job."""
    models = [ModelHandle.resolve(spec, settings) for settings in spec.models]
    plans = [plan_spec(spec, model) for model in models]
    while spec.policy.adaptive:
        history = outcomes_by_scene(plans[0], store)
        later = [plan_spec(spec, model, history) for model in models]
        if len(later[0].jobs) <= len(plans[0].jobs):
            return later
        plans = later
    return plans


@lru_cache(maxsize=1)
def _jobs_format() -> bytes | None:
    """What makes the jobs file's bytes besides the plan: the code that builds its table, its
    metadata and the store's writer, and pyarrow's version (a change to any of them writes the
    file again); None where the code cannot be read (installed in a zip: the file is compared)."""
    import importlib.util

    modules = ("sweep3d.driver.jobs", "sweep3d.cache.store", "sweep3d.spec.columns", "sweep3d.driver.plugin_code", __name__)
    try:
        code = b"".join(Path(importlib.util.find_spec(m).origin).read_bytes()  # type: ignore[union-attr, arg-type]
                        for m in modules)
    except (OSError, TypeError, AttributeError):
        return None
    return f"jobs file 1, pyarrow {pa.__version__}, code {hashlib.sha256(code).hexdigest()}".encode()


def _writable(spec: LoadedSpec, store: Store) -> None:
    try:
        store.ensure_writable()
    except UserError as exc:
        raise SpecError(str(spec.path), "experiment.store", str(exc)) from None


def run(spec: LoadedSpec, console: Console | None = None, wait: float = 0.0, executor: Executor = LOCAL,
        overlap: bool = True) -> RunResult:
    """Run every stage of ``spec`` and return what each did (renders on ``executor``).

    Args:
        overlap: postprocess and infer while Blender renders (else one stage after the other:
            the same results, for comparison).
    """
    store = Store(spec.store)
    _writable(spec, store)
    # the runner holds the lock and the executor's session; planning comes before the leftovers' removal
    with running(spec, executor=executor, wait=wait, console=console, store=store, leftovers=False) as runner:
        return _run_locked(spec, store, console, runner, overlap)


def _run_locked(spec: LoadedSpec, store: Store, console: Console | None, runner: Runner, overlap: bool) -> RunResult:
    started = time.perf_counter()  # time spent waiting for the lock is not the run's
    started_at = utc_now()
    store.snapshot_states()  # every blob's listing and state, taken on the other core while this one plans
    models = [ModelHandle.resolve(spec, settings) for settings in spec.models]
    plans = [plan_spec(spec, model, remember=store) for model in models]
    if max(len(plan.jobs) for plan in plans) < SNAPSHOT_MIN_JOBS:
        store.forget_states()  # few blobs to check: waiting for the child's look at every blob costs more
    remove_leftovers(store)  # before anything is written (planning reads no blob folder)
    result = RunResult(uuid.uuid4().hex[:12], plans[0], plans=plans, store=store)
    jobs = jobs_digest(plans) if store.state_snapshot is not None else None
    before = settled.fingerprint(store, spec, jobs)  # what the passes would read, as it is now
    remembered = settled.recall(store, spec, before)
    if remembered is not None:  # the same run found everything complete, and nothing it reads has changed
        store.forget_states()
        write_jobs(plans, store, jobs)
        result.outcomes = remembered
    else:
        tables = settled.table_states(store) if before is not None else None
        missing, found = _missing_renders(plans, store, runner.executor)
        _note_device(plans, missing, console)
        _warn_if_slow(plans, store, runner.executor, console, missing)
        if any(missing.values()):
            runner.render.warm_up(plans[0])  # Blender starts while the model is checked (both take seconds)
        _run_passes(spec, store, overlap, models, runner, result, found)
        if before is not None and tables == settled.table_states(store):  # the passes wrote no table
            settled.remember(store, spec, before, result.outcomes)
        elif not result.failed and max(len(plan.jobs) for plan in result.plans) >= SNAPSHOT_MIN_JOBS:
            _look_again(spec, store, overlap, models, runner, result, jobs)  # a cold run's too: it took no snapshot
    result.seconds = time.perf_counter() - started
    store.append("runs", [{
        "run_id": result.run_id, "experiment": spec.name, "spec_path": str(spec.path),
        "spec": spec.text(), "jobs": len(result.plan.jobs),
        "started_at": started_at, "created_at": utc_now(), "seconds": result.seconds,
        **{f"{o.stage}_{k}": v for o in result.outcomes for k, v in o.as_row().items() if k != "stage"},
    }])
    compact_crowded_tables(store)
    return result


def _look_again(spec: LoadedSpec, store: Store, overlap: bool, models: list[ModelHandle], runner: Runner,
                result: RunResult, jobs: str | None) -> None:
    """After a large run that computed something (a cold one included), look at the store once
    more as its next run would, and record what that finds when it is settled (:mod:`.settled`):
    the first rerun then reads its outcomes back instead of looking key by key. At 10⁶ jobs the
    look costs seconds after hours of rendering; anything it finds to do it does, as the next run
    would. ``jobs``: the plans' jobs digest, when the run made it already."""
    if spec.policy.adaptive:  # each round planned from the outcomes: its reruns always look
        return
    store.snapshot_states()
    if store.state_snapshot is None:  # few blobs: the next run looks key by key anyway (and cheaply)
        return
    digest = settled.fingerprint(store, spec, jobs or jobs_digest(result.plans))
    tables = settled.table_states(store)
    look = RunResult(result.run_id, result.plan, plans=result.plans, store=store)
    _run_passes(spec, store, overlap, models, runner, look, [None] * len(result.plans))  # type: ignore[list-item]
    store.forget_states()
    if tables == settled.table_states(store):
        settled.remember(store, spec, digest, look.outcomes)


def _run_passes(spec: LoadedSpec, store: Store, overlap: bool, models: list[ModelHandle], runner: Runner,
                result: RunResult, found: list[Found]) -> None:
    """Check the models, then run the stages pass after pass (one per round for adaptive
    policies) into ``result``, starting from its plans (``found``: what their render stage found
    stored, one per plan, for the first round)."""
    plans = result.plans
    several = len(models) > 1
    for plan, model in zip(plans, models):
        runner.prepare(plan, runner.stages(model, ("infer",), several=several))  # a broken model fails now
    history: History = {}
    while True:  # one pass for fixed policies; one per round for adaptive ones
        if history:
            plans = [plan_spec(spec, model, history) for model in models]
        try:
            # Models share renders (same framing: the later passes find them cached) and
            # the first model's outcomes steer adaptive policies.
            outcomes: list[StageOutcome] = []
            for i, (plan, model) in enumerate(zip(plans, models)):
                first = {runner.render.table: found[i]} if not history and i == 0 else None  # later: written since
                now = runner.run(plan, model, several=several, overlap=overlap, found=first)
                shared = any(p.framing == plan.framing for p in plans[:i])  # the same renders again
                both = merge_outcomes if shared else add_outcomes
                outcomes = both(outcomes[:2], now[:2]) + outcomes[2:] + now[2:]
        except KeyboardInterrupt:
            write_jobs(plans, store)  # what finished is stored: let query and report show it
            raise
        except RenderError as exc:  # a worker died while starting: Blender or the machine
            write_jobs(plans, store)
            raise RenderError(f"{exc}; what finished is stored: run again to resume") from None
        write_jobs(plans, store)
        result.outcomes = merge_outcomes(result.outcomes, outcomes)
        grown = len(plans[0].jobs) > len(result.plan.jobs) or not history
        result.plan, result.plans = plans[0], plans
        if not spec.policy.adaptive or not grown:
            break
        history = outcomes_by_scene(plans[0], store)


def write_unstored_images(spec: LoadedSpec, store: Store, keys: Iterable[str]) -> int:
    """Write the blobs of post-processed images that runs made in memory only (``[postprocess]
    store = "none"``), for what looks at them (the report's thumbnails, ``export``): each made
    again from its stored render, as inference made it. Keys with a blob, with no images row, or
    that no plan of ``spec`` holds (another spec's) are left alone. Returns how many were written.
    """
    wanted = {k for k in keys if k and not store.has_blob(k)} & store.key_set("images")
    written = 0
    for plan in plans_as_run(spec, store) if wanted else ():
        made, held = write_plan_images(store, plan, wanted)
        written, wanted = written + made, wanted - held
        if not wanted:
            break
    return written


def write_plan_images(store: Store, plan: Plan, keys: set[str] | None = None) -> tuple[int, set[str]]:
    """Write the blobs of ``plan``'s post-processed images among ``keys`` (None: all of the plan's)
    that have none, each made again from its stored render. Returns (how many were written, the
    keys of ``keys`` the plan holds)."""
    jobs = unique_jobs(PostprocessStage(), plan.jobs)
    held = set(jobs) if keys is None else keys & jobs.keys()
    post, renders, passes = post_controls(plan), store.digests("renders"), truth_digests(store)
    written = 0
    for key in sorted(k for k in held if not store.blob_path(k).exists()):
        made = make_image(store, plan, jobs[key], post, renders.get(jobs[key].render_key), passes)
        if made.pixels is not None:
            atomic_write(store.blob_path(key), encode_png8(made.pixels), durable=False)
            written += 1
    return written, held


def _missing_renders(plans: list[Plan], store: Store, executor: Executor) -> tuple[dict[int, int], list[Found]]:
    """Renders to make, by frame side (models framed alike share them), and what each plan's
    render stage found stored (its first pass starts from it: at 10⁶ jobs, looking costs seconds)."""
    missing, found = {}, []
    stage = RenderStage(executor)
    for plan in plans:
        found.append(rows_and_cached(stage, plan, store))
        needed, cached = stage_counts(stage, plan, store, found[-1])
        missing[plan.framing.crop] = needed - cached
    return missing, found


def _note_device(plans: list[Plan], missing: dict[int, int], console: Console | None) -> None:
    """One line before a run that renders when ``device = "auto"`` found no GPU (it renders on the
    CPU), or when the driver must compile Cycles' kernels for this GPU first (minutes, once)."""
    render = plans[0].spec.render
    for note in (device_note(render, plans[0].device), variant_note(render.engine)):
        if note and any(missing.values()) and console is not None:
            console.print(f"[dim]note: {escape(note)}[/]", highlight=False, soft_wrap=True)


def _warn_if_slow(plans: list[Plan], store: Store, executor: Executor, console: Console | None,
                  missing: dict[int, int] | None = None) -> None:
    """One warning line before a run whose renders would take hours at the spec's settings on the
    CPU (the estimate's costs are CPU costs: nothing is said for a GPU)."""
    if plans[0].device != "cpu":
        return
    missing = _missing_renders(plans, store, executor)[0] if missing is None else missing
    line = slow_render_warning(plans[0].spec.render, max(missing), sum(missing.values()))
    if line and console is not None:
        console.print(f"[bold yellow]warning:[/] {escape(line)}", highlight=False, soft_wrap=True)


def remove_leftovers(store: Store) -> None:
    """Remove what killed runs left (call it holding the lock, before writing): their temp files,
    segments an earlier compaction merged (past their grace), and workers' scratch folders, which
    SIGKILL keeps from cleaning up and which no pool would remove on a run that renders nothing."""
    remove_killed_writers_temp_files(store.root, store)
    for table in TABLES:
        store.sweep_superseded(table)
    remove_stale_scratch(scratch_root())


def compact_crowded_tables(store: Store, limit: int = AUTO_COMPACT_SEGMENTS) -> list[str]:
    """Merge the segments of tables that have more than ``limit`` (call it holding the lock).

    Every run adds a few segments per table; readers bind each file, so a store grown over
    hundreds of runs would take seconds to open. Returns the tables merged.
    """
    crowded = [t for t in TABLES if len(store.segments(t)) > limit and len(store.readable_segments(t)) > limit]
    for table in crowded:
        compact_table(store, table)
    return crowded
