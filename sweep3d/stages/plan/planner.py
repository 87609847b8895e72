"""Expand a spec into jobs, each with the cache keys of the stages it passes through.

Each stage owns its key recipe (``render.keys``, ``postprocess.keys``, ``infer.keys``); the
planner only coordinates them: it hashes what is fixed per scene once, asks the policy for
points, maps them to control values and derives each job's keys. It needs neither Blender nor
the model: the Blender version and the model's digest are inputs.
"""

from __future__ import annotations

from typing import Any, Callable

from sweep3d.cache.keys import digest, file_digest
from sweep3d.errors import SpecError, UserError
from sweep3d.spec.assets import mesh_digest
from sweep3d.spec.framing import Framing
from sweep3d.spec.loader import ControlInstance, LoadedSpec
from sweep3d.spec.sniff import unreadable
from sweep3d.spec.space import Point, SearchSpace
from sweep3d.stages.infer.keys import infer_base, pred_key
from sweep3d.stages.jobs import Job, Plan
from sweep3d.stages.plan.policies import Outcome
from sweep3d.stages.postprocess.keys import image_key
from sweep3d.stages.render.keys import parts_key, render_key, scene_key
from sweep3d.stages.render.state import SceneState, in_frame

#: What an adaptive policy learns per scene: the outcome of each point already evaluated.
History = dict[tuple[str, str], dict[Point, Outcome]]


def make_plan(spec: LoadedSpec, *, framing: Framing, model_digest: str, blender: str,
              history: History | None = None) -> Plan:
    """Expand ``spec`` into jobs, sorted by scene so workers reload as little as possible.

    Args:
        framing: the resolved frame (see ``infer.ModelHandle``).
        model_digest: the model's digest for that framing.
        blender: the Blender version renders are made with (part of every render key).
        history: for adaptive policies, the outcomes so far per (object, environment); the
            policy then proposes its next round on top of the points already evaluated.
    """
    check_size(spec)
    rendered = sorted((c for c in spec.controls if c.control.stage == "render"),
                      key=lambda c: (c.control.order, spec.controls.index(c)))
    post = [c for c in spec.controls if c.control.stage == "post"]
    settings = spec.render.key_part(framing.key_part())
    base = infer_base(model_digest, {"kind": spec.evaluator.kind, "top_k": spec.evaluator.top_k},
                      spec.model.backend)
    jobs: list[Job] = []
    out_of_frame: list[Job] = []
    hdri_digests = _hdri_digests(spec)
    for i, obj in enumerate(spec.objects):
        object_digest = _asset_digest(spec, f"objects[{i}].mesh", mesh_digest, spec.meshes[obj.name], spec.store)
        truth = list(spec.labels[obj.name])
        for env in spec.environments:
            scene = scene_key(blender, settings, object_digest,
                              {"hdri": hdri_digests[env.name],
                               "color": list(env.color) if env.color else None, "strength": env.strength})
            scene_controls = [c for c in spec.controls if c.applies_to(obj.name, env.name)]
            space = SearchSpace(scene_controls)
            seed = int(digest([spec.experiment.seed, obj.name, env.name])[:15], 16)
            points = spec.policy.points(space.shape, seed, (history or {}).get((obj.name, env.name), {}))
            if len(jobs) + len(out_of_frame) + len(points) > spec.experiment.max_jobs:  # a policy that cannot count
                raise _too_many(spec, f"more than {spec.experiment.max_jobs:,}")
            for point in points:
                values = space.values(point)
                models = {c.id: c.control.params(values[c.id]) for c in scene_controls}
                params = {key: model.model_dump() for key, model in models.items()}
                render = render_key(scene, _key_parts(rendered, params))
                image = image_key(render, _key_parts(post, params), _post_seed(spec, post, params))
                job = Job(len(jobs) + len(out_of_frame), obj.name, env.name, params, render, image,
                          pred_key(base, image, truth), point,
                          parts_key(render) if spec.report.part_visibility else None)
                (jobs if _in_frame(rendered, models) else out_of_frame).append(job)
    return Plan(spec, jobs, model_digest, out_of_frame, framing)


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
                per_space[applying] = spec.policy.count(SearchSpace([spec.controls[i] for i in applying]).shape)
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


def _too_many(spec: LoadedSpec, jobs: str) -> SpecError:
    kind = spec.spec.policy.type
    knob = ("policy.samples_per_dim or the number of listed values" if kind == "grid" else
            "policy.samples" if kind in ("random", "sobol", "adaptive") else "the policy's parameters")
    return spec.fail("policy", f"the spec expands to {jobs} jobs, over the limit of {spec.experiment.max_jobs:,}; "
                               f"lower {knob} (or the objects and environments), or raise [experiment] max_jobs")


def _post_seed(spec: LoadedSpec, post: list[ControlInstance], params: dict[str, dict[str, Any]]) -> int | None:
    """The experiment's seed when an effective post control draws random numbers, else None."""
    stochastic = any(getattr(c.control, "stochastic", False) for c in post
                     if c.id in params and not c.control.is_identity(params[c.id]))
    return spec.experiment.seed if stochastic else None


def _in_frame(rendered: list[ControlInstance], models: dict[str, Any]) -> bool:
    """Whether the job's object can appear in its image, from geometry alone (no rendering)."""
    state = SceneState()
    for inst in rendered:
        if inst.id in models:
            inst.control.apply(state, models[inst.id])
    return in_frame(state)


def _key_parts(controls: list[ControlInstance], params: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Key parts of the controls that apply to this job and change its image, in application order."""
    parts = []
    for inst in controls:
        if inst.id in params and not inst.control.is_identity(params[inst.id]):
            parts.append(inst.control.key_part(params[inst.id]))
    return parts
