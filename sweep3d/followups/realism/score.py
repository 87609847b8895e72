"""``sweep3d realism score``: the spec's models on another source of images of the picked jobs,
stored as verdicts beside the renders' (the store's ``verdicts`` table, read by the ``agreement``
view: :mod:`sweep3d.results.agreement`).

Two sources, one path to the verdicts:

- ``photo``: photographs of the picked scenes (:mod:`sweep3d.followups.realism.photos` matches and frames
  them), classified here by the run's own model code: the model handle the infer stage resolves,
  its task's call (``model_outputs``) and the spec's evaluator (``evaluate_checked``), batches
  padded as the infer stage pads them. Nothing about classification is done here.
- ``engine:<name>``: the picked configurations rendered by another renderer. The kit's
  ``design.csv`` is replayed by a spec written in it (``engines/<name>.toml``: the spec
  included, ``[policy] type = "table"``, ``[render] engine = "<name>"``, its own experiment
  name), run through the whole pipeline, and its results are matched back to the picked jobs
  by their configuration. Nothing here knows an engine: whatever ``[render] engine`` accepts
  is a source.
"""

from __future__ import annotations

import hashlib
import io
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from sweep3d.cache import Store, atomic_write, utc_now
from sweep3d.core import UserError
from sweep3d.followups.realism.photos import PREPROCESS, Photo, PhotoProblems, framed, match_photos, too_small, upright
from sweep3d.followups.realism.pick import DESIGN, RENDERS, default_kit, read_kit
from sweep3d.results import VERDICT_SCHEMA, VERDICTS, photo_path, verdict_key
from sweep3d.spec import LoadedSpec

PHOTO = "photo"
#: The kit's subfolder holding the specs that replay its design with another engine.
ENGINES = "engines"
THUMB_SIDE = 256


@dataclass(frozen=True)
class Scored:
    """What ``score`` stored: the source, its verdicts per model and how they agree with the runs'."""

    source: str
    verdicts: int
    models: list[str]
    agree: dict[str, tuple[int, int]]  # model → (jobs agreeing, jobs)
    #: Why no agreement could be read (the ``agreement`` view was not made), else None.
    missing: str | None = None

    def lines(self) -> list[str]:
        out = [f"stored {self.verdicts} verdicts of source {self.source!r} ({', '.join(self.models)})"]
        if self.missing is not None:
            return [*out, self.missing]
        for model, (same, n) in self.agree.items():
            out.append(f"{model}: the {self.source} verdict agrees with the render's on {same} of {n} jobs")
        return out


def find_kit(spec: LoadedSpec, photos: Path | None, kit: Path | None) -> Path:
    """The kit's folder: ``kit`` when given, else ``photos`` when it holds one, else the default."""
    if kit is not None:
        return kit
    if photos is not None and (photos / "kit.json").is_file():
        return photos
    return default_kit(spec)


def score_photos(spec: LoadedSpec, photos: Path, match: Path | None = None, kit: Path | None = None,
                 wait: float = 0.0) -> Scored:
    """Classify the photographs in ``photos`` with each of ``spec``'s models and store them as source ``photo``.

    Raises:
        PhotoProblems: a photograph matches no job, a job has none, a file is not a readable image
            (every such line at once; nothing is stored).
        UserError: no kit, no results of the run.
    """
    from sweep3d.stages.infer import ModelHandle

    folder = find_kit(spec, photos, kit)
    document = read_kit(folder)
    if document.get("experiment") != spec.name:
        raise UserError(f"{folder / 'kit.json'}: is the kit of experiment {document.get('experiment')!r}, not "
                        f"{spec.name!r}; give this spec's kit with --kit")
    jobs = [int(j) for j in document["jobs"]]
    matched = match_photos(photos, jobs, match)
    sizes = _render_sizes(folder, jobs)
    photos = _framed_photos(matched, sizes)
    frames = post_processed(spec, photos)  # what the model sees; the kept thumbnail is the photo as taken
    digests = {p.job: hashlib.sha256(p.path.read_bytes()).hexdigest() for p in matched}
    store = Store(spec.store)
    rows: list[dict[str, Any]] = []
    with store.lock(wait):  # before the models run: another command's hold is waited for or refused now, not after
        for settings in spec.models:
            handle = ModelHandle.resolve(spec, settings)
            verdicts = classify(spec, settings, [frames[j] for j in jobs],
                                _truth_rows(spec, store, jobs, settings.label), handle)
            words = model_preprocess(handle)
            for job, verdict in zip(jobs, verdicts):
                h, w = sizes[job]
                photo = next(p for p in matched if p.job == job)
                rows.append(_row(PHOTO, spec.name, job, settings.label, verdict, photo=photo.path.name,
                                 photo_sha256=digests[job], preprocess=PREPROCESS.format(width=w, height=h,
                                                                                         model=words)))
        for job, pixels in photos.items():
            _keep_thumb(store, digests[job], pixels)
        store.append(VERDICTS, rows, VERDICT_SCHEMA)
    return _scored(PHOTO, spec, store, rows)


def _framed_photos(matched: Sequence[Photo], sizes: dict[int, tuple[int, int]]) -> dict[int, np.ndarray]:
    """Each photograph read upright and framed as its job's render (one at a time: only the framed
    ones are kept).

    Raises:
        PhotoProblems: photographs smaller than their render (framing never enlarges one).
    """
    out, problems = {}, []
    for photo in matched:
        pixels = upright(photo.path)
        small = too_small(pixels.shape[:2], sizes[photo.job])
        if small:
            problems.append(f"{photo.path}: {small}")
            continue
        out[photo.job] = framed(pixels, *sizes[photo.job])
    if problems:
        raise PhotoProblems(problems)
    return out


def post_processed(spec: LoadedSpec, frames: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """Each framed photograph (8-bit) with its job's 2D controls applied as they were to its render
    (blur, noise, ...: part of the job's configuration, so the photo is judged as the render was),
    seeded by the job's image key as the postprocess stage does.

    Raises:
        PhotoProblems: a job's control reads the render's passes (depth, mask), which a photograph has not.
    """
    from sweep3d.core import from_uint8, to_uint8
    from sweep3d.runner import plan_spec
    from sweep3d.stages.postprocess import apply_post, post_controls

    plan = plan_spec(spec)
    post = post_controls(plan)
    if not post:
        return frames
    planned = {job.index: job for job in plan.jobs}  # by job number: the plan lists in-frame jobs only
    out, problems = {}, []
    for job_id, pixels in frames.items():
        job = planned.get(job_id)
        if job is None:
            problems.append(f"job {job_id}: the spec no longer plans it; pick the kit again (`sweep3d realism pick`)")
            continue
        needs = [inst.id for inst in post if getattr(inst.control, "passes", ()) and inst.id in job.values
                 and not inst.control.is_identity(job.values[inst.id])]
        if needs:
            problems.append(f"job {job_id}: control {needs[0]!r} reads the render's passes, which a photograph "
                            "has not; leave the job out (its row in kit.json) or the control out of the spec")
            continue
        out[job_id] = to_uint8(apply_post(from_uint8(pixels), post, job.values, job.image_key))
    if problems:
        raise PhotoProblems(problems)
    return out


def classify(spec: LoadedSpec, settings: Any, images: Sequence[np.ndarray], truths: Sequence[dict[str, Any]],
             handle: Any = None) -> list[dict[str, Any]]:
    """The spec's evaluator's rows for 8-bit ``images`` (each the size of its job's render), by
    the model ``settings`` names, through the infer stage's own code (its handle, task call,
    evaluator and batch padding). ``truths``: per image its ``object`` and ``truth_key``;
    ``handle``: the model's, when the caller resolved it already (a user's factory runs once)."""
    from sweep3d.cache import load_pass
    from sweep3d.core import from_uint8
    from sweep3d.stages.infer import (
        EVALUATORS,
        ModelHandle,
        Truth,
        check_task,
        evaluate_checked,
        first_rows,
        model_outputs,
        object_class_ids,
        padded,
    )

    handle = handle if handle is not None else ModelHandle.resolve(spec, settings)
    model = handle.classifier()
    labels = model.label_map()
    evaluator = EVALUATORS.get(spec.evaluator.kind).from_settings(spec.evaluator)
    check_task(model, evaluator.task, handle.name)
    ids = object_class_ids(types.SimpleNamespace(spec=spec), labels, handle.name)
    store = Store(spec.store)
    size = settings.batch_size
    out: list[dict[str, Any] | None] = [None] * len(images)
    by_shape: dict[tuple[int, ...], list[int]] = {}
    for i, image in enumerate(images):  # images of one size share a batch, as renders of a run do
        by_shape.setdefault(image.shape, []).append(i)
    for indices in by_shape.values():
        for start in range(0, len(indices), size):
            chosen = indices[start:start + size]
            stacked = padded(np.stack([from_uint8(images[i]) for i in chosen]), size)
            outputs = first_rows(model_outputs(model, stacked, evaluator.task, handle.name), len(chosen))
            truth = []
            for i in chosen:
                t = truths[i]
                arrays = {name: load_pass(store, t["truth_key"], name) if t.get("truth_key") else None
                          for name in evaluator.passes}
                truth.append(Truth(ids[t["object"]], **arrays))
            for i, row in zip(chosen, evaluate_checked(evaluator, spec.evaluator.kind, outputs, truth, labels)):
                out[i] = row
    return [row for row in out if row is not None]


def model_preprocess(handle: Any) -> str:
    """What the model ``handle`` resolves does to an image, in words with its normalisation's
    numbers (:meth:`Preprocess.describe`), as the infer stage applies it in the run's framing."""
    from sweep3d.stages.infer import Preprocess

    applied = handle.applied
    if not isinstance(applied, Preprocess):
        return f"a {type(applied).__name__} of the model's factory, whose normalisation sweep3d cannot read"
    return applied.describe()


def _render_sizes(folder: Path, jobs: Sequence[int]) -> dict[int, tuple[int, int]]:
    """(height, width) of each job's render in the kit (what its photograph is framed to)."""
    from PIL import Image

    sizes, problems = {}, []
    for job in jobs:
        path = folder / RENDERS / f"{job}.png"
        try:
            with Image.open(path) as im:
                sizes[job] = (im.height, im.width)
        except OSError:
            problems.append(f"{path}: the kit's render of job {job} is missing or unreadable; run "
                            "`sweep3d realism pick` again")
    if problems:
        raise PhotoProblems(problems)
    return sizes


def _truth_rows(spec: LoadedSpec, store: Store, jobs: Sequence[int], model: str) -> list[dict[str, Any]]:
    """Per job (in ``jobs``' order) its object and truth key, from the run's results."""
    from sweep3d.results import results_connection

    several = len(spec.models) > 1
    with results_connection(spec, model if several else None) as con:
        columns = {name for name, *_ in con.execute("DESCRIBE results").fetchall()}
        truth = "truth_key" if "truth_key" in columns else "NULL AS truth_key"
        found = {row[0]: {"object": row[1], "truth_key": row[2]} for row in con.execute(
            f"SELECT job, object, {truth} FROM results WHERE job IN (SELECT unnest(?))", [list(jobs)]).fetchall()}
    missing = [j for j in jobs if j not in found]
    if missing:
        raise UserError(f"jobs {', '.join(map(str, missing[:8]))} of the kit have no result of model {model} in "
                        f"{spec.name}: run `sweep3d run {spec.path}`, then `sweep3d realism pick` again")
    return [found[j] for j in jobs]


def _row(source: str, experiment: str, job: int, model: str, verdict: dict[str, Any], **extra: Any) -> dict[str, Any]:
    row = {name: None for name in VERDICT_SCHEMA.names}
    row.update(verdict_key=verdict_key(source, experiment, job, model), source=source, experiment=experiment,
               job=job, model=model, valid=bool(verdict.get("valid")),
               correct=verdict.get("correct"), top1_label=verdict.get("top1_label"),
               label_prob=verdict.get("label_prob"), created_at=utc_now(), **extra)
    return row


def _keep_thumb(store: Store, sha256: str, pixels: np.ndarray) -> None:
    from PIL import Image

    image = Image.fromarray(pixels)
    image.thumbnail((THUMB_SIDE, THUMB_SIDE))
    buffer = io.BytesIO()
    image.save(buffer, format="JPEG", quality=85)
    path = photo_path(store, sha256)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, buffer.getvalue(), durable=False)


def _scored(source: str, spec: LoadedSpec, store: Store, rows: list[dict[str, Any]]) -> Scored:
    """What was stored, with each model's agreement read back through the ``agreement`` view (a
    line saying why instead, where the view was not made: the verdicts are stored all the same)."""
    from sweep3d.results import has_view, results_connection

    agree = {}
    with results_connection(spec, store=store) as con:
        if not has_view(con, "agreement"):
            return Scored(source, len(rows), [m.label for m in spec.models], {}, _no_agreement(con, spec))
        for model, same, n in con.execute(
                "SELECT model, n_agree, n FROM agreement WHERE source = ? AND overall ORDER BY model", [source]).fetchall():
            agree[model] = (same, n)
    return Scored(source, len(rows), [m.label for m in spec.models], agree)


def _no_agreement(con: Any, spec: LoadedSpec) -> str:
    """The one line saying why ``con`` has no ``agreement`` view (what
    :func:`~sweep3d.results.agreement.register_agreement_views` needs and did not find)."""
    from sweep3d.results import has_view

    if has_view(con, "results_all"):
        columns = {name for name, *_ in con.execute("DESCRIBE results_all").fetchall()}
        lacking = [c for c in ("job", "object", "correct", "counted") if c not in columns]
        if lacking:
            return (f"no agreement to show: the results of {spec.name} lack the column(s) {', '.join(lacking)} "
                    f"(stored by an older version); run `sweep3d run {spec.path}` to bring them up to date")
    return (f"no agreement to show: the store holds no readable verdict of experiment {spec.name} "
            f"(score the kit's photographs or --engine first), or no results of it (run `sweep3d run {spec.path}`)")


# -- another renderer as a source ------------------------------------------------------------
ENGINE_SPEC = """\
# Written by `sweep3d realism score --engine {engine}`: the picked jobs of {name!r}, rendered by {engine}.
include = [{spec}]

[experiment]
name = {experiment}

[policy]
type = "table"
file = {design}

[render]
engine = {engine_value}
{neutral}"""


def engine_spec(spec: LoadedSpec, kit: Path, engine: str) -> Path:
    """Write the spec that replays the kit's ``design.csv`` with ``[render] engine = engine``."""
    import json

    from sweep3d.stages.render import cycles_only_defaults

    path = kit / ENGINES / f"{engine}.toml"
    path.parent.mkdir(exist_ok=True)
    # the included spec's Cycles-only settings mean nothing to another engine, which refuses them
    # away from their defaults: set back, as this spec renders the same configurations elsewhere
    neutral = "".join(f"{name} = {json.dumps(value)}\n" for name, value in cycles_only_defaults(engine).items())
    text = ENGINE_SPEC.format(engine=engine, name=spec.name, spec=json.dumps(str(spec.path.resolve())),
                              experiment=json.dumps(f"{spec.name}.engine-{engine}"),
                              design=json.dumps(str((kit / DESIGN).resolve())), engine_value=json.dumps(engine),
                              neutral=neutral)
    path.write_text(text, encoding="utf-8")
    return path


def _run(spec: LoadedSpec, console: Any, wait: float, executor: Any = None) -> None:
    """Run ``spec`` like ``sweep3d run`` (what renders the other engine's images), on ``executor``
    (default: local workers)."""
    from sweep3d.runner import run
    from sweep3d.stages.render import LOCAL

    run(spec, console, wait=wait, executor=executor or LOCAL)


def score_engine(spec: LoadedSpec, engine: str, kit: Path | None = None, console: Any = None,
                 wait: float = 0.0, executor: Any = None) -> Scored:
    """Render the kit's picked configurations with ``engine`` (through the whole pipeline, cached
    like any run) and store the verdicts as source ``engine:<engine>``.

    Raises:
        UserError: no kit; the spec loader refusing the engine or a control it cannot express.
    """
    from sweep3d.runner import builtin_catalogue, write_unstored_images
    from sweep3d.spec import ENGINES, read_spec

    if engine not in ENGINES:  # before anything is written into the kit
        raise UserError(f"--engine {engine!r}: use one of {', '.join(ENGINES)}")
    folder = find_kit(spec, None, kit)
    document = read_kit(folder)
    jobs = [int(j) for j in document["jobs"]]
    other = read_spec(engine_spec(spec, folder, engine), builtin_catalogue(), None)
    store = Store(spec.store)
    with store.lock(wait):  # from the start: the run within takes it again in this thread, a no-op
        _run(other, console, wait, executor)
        rows = _engine_rows(spec, other, store, engine, jobs)
        # the other engine's images the report's pairs show: a run keeps its post-processed images
        # in memory only ([postprocess] store = "none", the default), and the report makes again
        # only its own experiment's, so they are written here, as `pick` writes the renders'
        write_unstored_images(other, store, [r["image_key"] for r in rows])
        store.append(VERDICTS, rows, VERDICT_SCHEMA)
    return _scored(f"engine:{engine}", spec, store, rows)


def _engine_rows(spec: LoadedSpec, other: LoadedSpec, store: Store, engine: str, jobs: Sequence[int]) -> list[dict]:
    """The verdict rows of the kit's ``jobs`` rendered by ``engine`` (the spec ``other``'s results),
    by model and job."""
    from sweep3d.results import results_connection, stored_parameters
    from sweep3d.stages.infer import ModelHandle

    parameters = stored_parameters(store.jobs_path(spec.name)) or list(spec.parameter_columns)
    source, rows = f"engine:{engine}", []
    for settings in spec.models:
        words = model_preprocess(ModelHandle.resolve(other, settings))
        several = len(spec.models) > 1
        with results_connection(spec, settings.label if several else None) as con:
            wanted = _configurations(con, jobs, parameters)
        with results_connection(other, settings.label if several else None) as con:
            theirs = _configurations(con, None, parameters, verdicts=True)
        for config, same in wanted.items():  # jobs of one configuration pair up in job order
            made = theirs.get(config, [])
            if len(made) < len(same):
                raise UserError(f"job {same[0]}: {engine} made no result for its configuration; run `sweep3d "
                                f"realism score --engine {engine}` again")
            for job, verdict in zip(same, made):
                rows.append(_row(source, spec.name, job, settings.label, verdict, image_key=verdict["image_key"],
                                 preprocess=f"rendered by {engine}; the model's own preprocessing, as for the "
                                            f"render: {words}"))
    rows.sort(key=lambda r: (r["model"], r["job"]))
    return rows


def _configurations(con: Any, jobs: Sequence[int] | None, parameters: Sequence[str],
                    verdicts: bool = False) -> dict[tuple, list[Any]]:
    """Results by configuration (object, environment, each parameter's value), in job order:
    their jobs, or (``verdicts``) the rows' verdict columns; ``jobs``: only those."""
    from sweep3d.results import identifier

    columns = {name for name, *_ in con.execute("DESCRIBE results").fetchall()}
    named = [c for c in ("object", "environment", *parameters) if c in columns]
    extra = [c for c in ("valid", "correct", "top1_label", "label_prob", "image_key") if c in columns]
    where = " WHERE job IN (SELECT unnest(?))" if jobs is not None else ""
    cursor = con.execute(f"SELECT job, {', '.join(map(identifier, named + extra))} FROM results{where} ORDER BY job",
                         [list(jobs)] if jobs is not None else [])
    out: dict[tuple, list[Any]] = {}
    for job, *values in cursor.fetchall():
        config = tuple(values[:len(named)])
        out.setdefault(config, []).append(dict(zip(extra, values[len(named):])) if verdicts else job)
    return out


__all__ = ["PHOTO", "Photo", "Scored", "classify", "engine_spec", "find_kit", "score_engine",
           "score_photos"]
