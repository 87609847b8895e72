"""Expand a spec into jobs, each with the cache keys of the stages it passes through.

Each stage owns its key recipe (``render.render_keys``, ``postprocess.image_keys``, ``infer.prediction_keys``); the
planner only coordinates them: it hashes what is fixed per scene once, asks the policy for
points, maps them to control values and derives each job's keys. It needs neither Blender nor
the model: the Blender version and the model's digest are inputs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from sweep3d.assets import mesh_digest, unreadable
from sweep3d.cache import Store, StoreWriteError, Template, digests, file_digest
from sweep3d.core import SpecError, UserError, blamed
from sweep3d.driver import JobList, Plan, PlanColumns, SceneBlock, truth_passes
from sweep3d.spec import (
    Column,
    ControlInstance,
    Framing,
    LoadedSpec,
    ModelSpec,
    NameClash,
    Point,
    SearchSpace,
    spec_class_names,
)
from sweep3d.stages.infer import LabelMap, builtin_labels, evaluator_key, infer_base, key_backend, pred_keys
from sweep3d.stages.plan import keys_memo
from sweep3d.stages.plan.batch import ControlBatch, control_batch, groups, keyed_texts
from sweep3d.stages.plan.checked import policy_count
from sweep3d.stages.plan.crossing import crossing
from sweep3d.stages.plan.memory import check_memory
from sweep3d.stages.plan.pairing import scene_points
from sweep3d.stages.plan.policies import Outcome
from sweep3d.stages.postprocess import image_template
from sweep3d.stages.render import (
    SceneState,
    check_engine,
    engine_key,
    frame_fields,
    in_frame,
    in_frame_many,
    parts_keys,
    plan_device,
    render_template,
    resolve_device,
    scene_key,
    truth_keys,
)

#: What an adaptive policy learns per scene: the outcome of each point already evaluated.
History = dict[tuple[str, str], dict[Point, Outcome]]
#: Jobs whose key texts are written at once: bounds the memory a big scene takes while planned.
KEY_CHUNK = 1 << 16


@dataclass
class _Keys:
    """Every job's keys, by job index, as the scenes are planned."""

    render: list[str] = field(default_factory=list)
    image: list[str] = field(default_factory=list)
    pred: list[str] = field(default_factory=list)
    parts: list[str] | None = None
    truth: list[str] | None = None
    truth_passes: tuple[str, ...] = ()
    in_frame: list[np.ndarray] = field(default_factory=list)


def make_plan(spec: LoadedSpec, *, framing: Framing, model_digest: str, blender: str,
              history: History | None = None, model: ModelSpec | None = None, device: str | None = None,
              classes: LabelMap | None = None, view: tuple[int, int] | None = None,
              remember: Store | None = None) -> Plan:
    """Expand ``spec`` into jobs, sorted by scene so workers reload as little as possible.

    Each scene's jobs are made as columns (see :mod:`sweep3d.stages.plan.batch`): values and
    key parts per control over arrays, keys hashed from canonical texts written per job, the
    in-frame test over arrays; the keys are those the per-job recipes in each stage's
    ``keys`` module give.

    Args:
        framing: the resolved frame (see ``infer.ModelHandle``).
        model_digest: the model's digest for that framing.
        blender: the Blender version renders are made with (part of every render key).
        history: for adaptive policies, the outcomes so far per (object, environment); the
            policy then proposes its next round on top of the points already evaluated.
        model: which of the spec's models the plan infers (default: the first).
        device: what renders ("cpu", "cuda", "optix"; a GPU is part of every render key);
            default: ``[render] device`` resolved here (see ``stages.render.device``).
        classes: the model's class names (a user's model's, once loaded); default: a built-in
            model's. The plan records the classes the spec names otherwise (see ``spec.class_names``).
        view: the model's own resize and crop, when known (the plan says what the model sees).
        remember: a store whose lock the caller holds, to remember the keys in (see
            :mod:`.keys_memo`): planned again unchanged, they are read back instead of hashed.
    """
    model = model or spec.model
    renamed = _renamed_classes(spec, classes if classes is not None else builtin_labels(model.name))
    check_engine(spec)
    device = plan_device(spec.render.engine, device or resolve_device(spec.render.device))
    engine = engine_key(spec.render.engine)
    check_size(spec)
    rendered = sorted((c for c in spec.controls if c.control.stage == "render"),
                      key=lambda c: (c.control.order, spec.controls.index(c)))
    post = [c for c in spec.controls if c.control.stage == "post"]
    settings = spec.render.key_part(framing.key_part(), device)
    base = infer_base(model_digest, evaluator_key(spec.evaluator), key_backend(spec, model))
    passes = truth_passes(spec)
    keys = _Keys(parts=[] if spec.report.part_visibility else None, truth=[] if passes else None, truth_passes=passes)
    blocks: list[SceneBlock] = []
    scenes: list[tuple[str, list[ControlBatch], list[ControlBatch], list[Any], int]] = []  # whose keys to make
    planned = 0
    hdri_digests = _hdri_digests(spec)
    for i, obj in enumerate(spec.objects):
        object_digest = _asset_digest(spec, f"objects[{i}].mesh", mesh_digest, spec.meshes[obj.name], spec.store)
        truth = list(spec.labels[obj.name])
        for env in spec.environments:
            scene = scene_key(blender, settings, object_digest, env.key_part(hdri_digests[env.name]), obj.look_key(),
                              engine)
            scene_controls = [c for c in spec.controls if c.applies_to(obj.name, env.name)]
            space = SearchSpace(scene_controls)
            listing = getattr(spec.policy, "listed", None)  # a user's policy may not subclass Policy
            listed = listing(space, obj.name, env.name) if listing else None
            if listed is None:
                crossed = crossing(space, spec.spec.policy.crossed)
                unit, choice = crossed.expand(*scene_points(
                    spec.policy, spec.spec.policy.paired, crossed.drawn, spec.experiment.seed, obj.name, env.name,
                    (history or {}).get((obj.name, env.name), {}), spec.spec.policy.type))
            else:
                unit, choice = listed.unit, listed.choice
            n = len(unit)
            if planned + n > spec.experiment.max_jobs:  # a policy that cannot count
                raise _too_many(spec, f"more than {spec.experiment.max_jobs:,}")
            if n == 0:
                continue
            columns = space.columns(unit, choice)
            for (control_id, param), numbers in (listed.exact.items() if listed else ()):
                columns[control_id][param] = Column(numbers=numbers)
            batches = {c.id: control_batch(c, columns[c.id], n) for c in scene_controls}
            blocks.append(SceneBlock(obj.name, env.name, planned, n,
                                     {cid: b.values for cid, b in batches.items()}, unit, choice))
            scenes.append((scene, [batches[c.id] for c in rendered if c.id in batches],
                           [batches[c.id] for c in post if c.id in batches], truth, n))
            planned += n
            keys.in_frame.append(_in_frame(rendered, batches, n))
    _all_keys(spec, keys, scenes, base, planned, remember if not history else None, model_digest)
    mask = np.concatenate(keys.in_frame) if keys.in_frame else np.zeros(0, bool)
    plan = PlanColumns(blocks, keys.render, keys.image, keys.pred, keys.parts, mask, keys.truth)
    return Plan(spec, JobList(plan, np.flatnonzero(mask)), model_digest, JobList(plan, np.flatnonzero(~mask)), framing,
                model.label, device, renamed, view)


def _renamed_classes(spec: LoadedSpec, classes: LabelMap | None) -> list[tuple[int, str, str, bool]]:
    """The classes the spec names otherwise than ``classes`` do (none when they are unknown).

    Raises:
        SpecError: two labels name one class differently (a built-in model's spec was refused
            at load; a user's model's classes are first known here).
    """
    if classes is None:
        return []
    try:
        names = spec_class_names([obj.labels for obj in spec.objects], classes)
    except NameClash as exc:
        raise SpecError(str(spec.path), exc.key, str(exc)) from None
    return classes.renamed(names)


def _all_keys(spec: LoadedSpec, keys: _Keys, scenes: list[tuple[str, list[ControlBatch], list[ControlBatch], list[Any], int]],
              base: dict[str, Any], planned: int, remember: Store | None, model_digest: str) -> None:
    """Append the keys of every job of ``scenes`` to ``keys``: read back from ``remember``'s memo
    when it holds them under the same fingerprint (:mod:`.keys_memo`), else written and hashed
    scene by scene (and remembered there)."""
    path = fingerprint = None
    if remember is not None and planned >= keys_memo.MIN_JOBS:
        prints = keys_memo.KeysPrint(base, spec.experiment.seed, keys.parts is not None, keys.truth_passes)
        for scene, rendered, post, truth, n in scenes:
            prints.scene(scene, truth, n, rendered, post)
        fingerprint = prints.hexdigest()
        path = keys_memo.memo_path(remember, spec.name, model_digest)
        known = keys_memo.read_keys(path, fingerprint, planned)
        if known is not None and (known["parts"] is None) == (keys.parts is None) \
                and (known["truth"] is None) == (keys.truth is None):
            keys.render, keys.image, keys.pred = known["render"], known["image"], known["pred"]  # type: ignore[assignment]
            keys.parts, keys.truth = known["parts"], known["truth"]
            return
    for scene, rendered, post, truth, n in scenes:
        for lo in range(0, n, KEY_CHUNK):
            _scene_keys(spec, keys, scene, rendered, post, base, truth, lo, min(n, lo + KEY_CHUNK))
    if path is not None and fingerprint is not None and remember is not None:
        keys_memo.write_keys(remember, path, fingerprint, {"render": keys.render, "image": keys.image,
                                                          "pred": keys.pred, "parts": keys.parts, "truth": keys.truth})


def _scene_keys(spec: LoadedSpec, keys: _Keys, scene: str, rendered: list[ControlBatch], post: list[ControlBatch],
                base: dict[str, Any], truth: list[Any], lo: int, hi: int) -> None:
    """Append the keys of a scene's jobs ``lo`` .. ``hi - 1`` to ``keys``."""
    rows = np.arange(lo, hi)
    renders = _render_keys(scene, rendered, rows, repeats=bool(post))

    def image(effective: list[ControlBatch], parts: list[Any]) -> Template | None:
        random = any(getattr(b.inst.control, "stochastic", False) for b in effective)
        return image_template(parts, spec.experiment.seed if random else None) if parts else None

    texts = keyed_texts(post, rows, image, strings={"render": renders})
    changed = [i for i, text in enumerate(texts) if text is not None]
    images = list(renders)
    for i, key in zip(changed, digests(texts[i] for i in changed)):
        images[i] = key
    keys.render += renders
    keys.image += images
    keys.pred += pred_keys(base, images, truth)
    if keys.parts is not None:
        keys.parts += parts_keys(renders)
    if keys.truth is not None:
        keys.truth += _truth_keys(renders, keys.truth_passes, rendered, rows)


def _truth_keys(renders: list[str], passes: tuple[str, ...], rendered: list[ControlBatch],
                rows: np.ndarray) -> list[str]:
    """The truth keys of the jobs of ``rows``: those a control's ``edit`` acts on (not at its
    neutral values) are keyed as edited, the others as before (see ``truth.EDITED_TRUTH_VERSION``)."""
    edited = np.zeros(len(rows), dtype=bool)
    for batch in rendered:
        if batch.inst.control.edits_scene:
            edited |= ~batch.identity[rows]
    if not edited.any():
        return truth_keys(renders, passes)
    out = [""] * len(renders)
    for flag in (False, True):
        at = np.flatnonzero(edited == flag).tolist()
        for i, key in zip(at, truth_keys([renders[i] for i in at], passes, flag)):
            out[i] = key
    return out


def _render_keys(scene: str, rendered: list[ControlBatch], rows: np.ndarray, repeats: bool) -> list[str]:
    """The render keys of the jobs of ``rows``; with ``repeats`` (jobs that differ only after
    rendering share a render), each distinct render is written and hashed once."""
    make = lambda effective, parts: render_template(scene, parts)  # noqa: E731
    if not repeats:
        return digests(keyed_texts(rendered, rows, make))
    first, inverse = groups([code for b in rendered for code in b.codes(rows)], len(rows))
    once = np.array(digests(keyed_texts(rendered, rows[first], make)), dtype=object)
    return once[inverse].tolist()


def _in_frame(rendered: list[ControlInstance], batches: dict[str, ControlBatch], n: int) -> np.ndarray:
    """Per job, whether its object can appear in its image, from geometry alone (no rendering):
    over arrays when every rendered control says which geometry it sets, else job by job."""
    applying = [c for c in rendered if c.id in batches]
    known = [frame_fields(c.control) for c in applying]
    if any(f is None for f in known):
        return np.array([_in_frame_one(applying, batches, r) for r in range(n)], dtype=bool)
    fields: dict[str, np.ndarray] = {}
    for inst, mapping in zip(applying, known):
        values = batches[inst.id].values
        for param, name in mapping.items():  # type: ignore[union-attr]
            if param in values.numbers or param in values.dumps[0]:  # else left out: the state's default
                fields[name] = values.floats(param)
    if not fields:  # nothing moves the object or the camera: one answer for every job
        return np.full(n, _in_frame_one(applying, batches, 0), dtype=bool)
    inside, unsure = in_frame_many(fields, n)
    for r in np.flatnonzero(unsure).tolist():
        inside[r] = _in_frame_one(applying, batches, r)
    return inside


def _in_frame_one(applying: list[ControlInstance], batches: dict[str, ControlBatch], row: int) -> bool:
    """The in-frame test of one job through a :class:`SceneState` its controls edit (a user's
    control that raises or exits here is named, as in the render worker)."""
    state = SceneState()
    for inst in applying:
        with blamed(inst.control, "apply()"):
            inst.control.apply(state, inst.control.params(batches[inst.id].raw(row)))
    return in_frame(state)


def _hdri_digests(spec: LoadedSpec) -> dict[str, str | None]:
    """Each environment's HDRI content digest (None for a plain colour)."""
    out: dict[str, str | None] = {}
    for i, env in enumerate(spec.environments):
        hdri = spec.hdris[env.name]
        out[env.name] = _asset_digest(spec, f"environments[{i}].hdri", file_digest, hdri) if hdri else None
    return out


def _asset_digest(spec: LoadedSpec, key: str, compute: Callable[..., str], *args: Any) -> str:
    """``compute(*args)``, with a file that cannot be read (since the spec was loaded) as one line naming ``key``."""
    try:
        return compute(*args)
    except StoreWriteError:
        raise  # the store's disk, not the spec's file: its line names the disk
    except UserError as exc:
        raise spec.fail(key, str(exc)) from None
    except OSError as exc:
        raise spec.fail(key, str(unreadable(exc, "file"))) from None


def count_jobs(spec: LoadedSpec) -> int | None:
    """How many jobs ``spec`` expands to (out-of-frame ones included), from the policy and each
    scene's space alone, without making any; None when the policy cannot count its points."""
    per_space: dict[tuple[int, ...], int | None] = {}  # scenes share a space when the same controls apply
    total = 0
    for obj in spec.objects:
        for env in spec.environments:
            applying = tuple(i for i, c in enumerate(spec.controls) if c.applies_to(obj.name, env.name))
            if applying not in per_space:
                crossed = crossing(SearchSpace([spec.controls[i] for i in applying]), spec.spec.policy.crossed)
                draws = policy_count(spec.policy, spec.spec.policy.type, crossed.drawn.shape)
                per_space[applying] = None if draws is None else crossed.count(draws)
            if per_space[applying] is None:
                return None
            total += per_space[applying]
    return total


def check_size(spec: LoadedSpec) -> None:
    """Refuse a spec that expands to more than ``[experiment] max_jobs`` jobs, before anything is made.

    Raises:
        SpecError: naming the count, the limit and what to lower.
    """
    jobs = count_jobs(spec)
    if jobs is not None and jobs > spec.experiment.max_jobs:
        raise _too_many(spec, f"{jobs:,}")
    if jobs is not None:
        check_memory(spec, jobs, _knob(spec))


def _too_many(spec: LoadedSpec, jobs: str) -> SpecError:
    return spec.fail("policy", f"the spec expands to {jobs} jobs, over the limit of {spec.experiment.max_jobs:,}; "
                               f"lower {_knob(spec)} (or the objects and environments), or raise [experiment] "
                               "max_jobs")


def _knob(spec: LoadedSpec) -> str:
    """The policy's setting that sets how many jobs a scene has."""
    kind = spec.spec.policy.type
    return ("policy.samples_per_dim or the number of listed values" if kind == "grid" else
            "policy.samples" if kind in ("random", "sobol", "adaptive", "boundary") else "the policy's parameters")
