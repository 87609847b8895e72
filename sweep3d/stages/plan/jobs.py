"""Jobs and their cache keys.

Each key hashes exactly what changes its stage's output (see DESIGN.md §2):

* ``render_key``: renderer settings, Blender version, the mesh's and HDRI's *content*, and the
  rendered controls that apply to the scene and are not at their neutral values;
* ``image_key``: the render key plus the effective post controls (plus the seed if one of them
  is random); equal to the render key when no post control changes the image;
* ``pred_key``: the image key plus the model's digest, the evaluator and the ground truth;
* ``parts_key`` (only when the part-visibility panel is asked for): the render key plus the
  parts layout. Extra render passes leave the RGB image as it is, so they are not part of the
  render key: switching the panel on re-renders for the UV pass and re-infers nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sweep3d.cache.keys import digest, file_digest
from sweep3d.parts import PARTS_LAYOUT
from sweep3d.spec.framing import Framing, resolve_framing
from sweep3d.spec.loader import ControlInstance, LoadedSpec
from sweep3d.spec.space import Point, SearchSpace
from sweep3d.stages.plan.policies import Outcome

if TYPE_CHECKING:
    from sweep3d.stages.render.protocol import RenderSettings

RENDER_STAGE_VERSION = 1
POST_STAGE_VERSION = 1
INFER_STAGE_VERSION = 1


@dataclass(frozen=True)
class Job:
    index: int
    object: str
    environment: str
    values: dict[str, dict[str, Any]]  # control id -> parameter -> value, for controls that apply
    render_key: str
    image_key: str
    pred_key: str
    point: Point | None = None  # where the policy put it (for policies that learn from results)
    parts_key: str | None = None  # the UV pass's visible parts, when the report asks for them

    @property
    def scene(self) -> tuple[str, str]:
        return (self.object, self.environment)


@dataclass
class Plan:
    spec: LoadedSpec
    jobs: list[Job]
    model_digest: str
    columns: list[str] = field(default_factory=list)  # one column per control parameter
    #: Jobs whose object is wholly outside the frame: flagged, never rendered or evaluated.
    out_of_frame: list[Job] = field(default_factory=list)
    #: The resolved frame (``resolution = "model"`` becomes the model's resize and crop sizes).
    framing: Framing | None = None

    def render_settings(self) -> RenderSettings:
        """The [render] settings with the resolved frame and the passes to write, as render
        workers need them (the UV pass only for the report's part-visibility panel)."""
        # imported here, not above: the render package imports this module
        from sweep3d.stages.render.protocol import RenderSettings

        framing = self.framing or resolve_framing(self.spec)
        passes = ("uv",) if self.spec.spec.report.part_visibility else ()
        return RenderSettings.from_spec(self.spec.spec.render, framing, passes)

    def rows(self) -> list[dict[str, Any]]:
        """The jobs table: one row per job with its scene, control values, keys and ``in_frame``."""
        out = []
        flagged = {id(j) for j in self.out_of_frame}
        for job in sorted(self.jobs + self.out_of_frame, key=lambda j: j.index):
            row: dict[str, Any] = {"experiment": self.spec.name, "job": job.index,
                                   "object": job.object, "environment": job.environment}
            for column in self.columns:
                row[column] = None
            for control_id, values in job.values.items():
                for param, value in values.items():
                    row[f"{control_id}_{param}"] = value
            row.update(render_key=job.render_key, image_key=job.image_key, pred_key=job.pred_key,
                       parts_key=job.parts_key, in_frame=id(job) not in flagged)
            out.append(row)
        return out


#: What an adaptive policy learns per scene: the outcome of each point already evaluated.
History = dict[tuple[str, str], dict[Point, Outcome]]


def make_plan(spec: LoadedSpec, model_digest: str | None = None, history: History | None = None,
              framing: Framing | None = None) -> Plan:
    """Expand ``spec`` into jobs, sorted by scene so workers reload as little as possible.

    Args:
        model_digest: the model's digest for the spec's framing, if already known.
        history: for adaptive policies, the outcomes so far per (object, environment); the
            policy then proposes its next round on top of the points already evaluated.
        framing: the resolved frame, if already known (resolving may load a user's model).
    """
    from sweep3d.stages.infer.models import model_digest as compute_model_digest
    from sweep3d.stages.render.assets import blender_version, mesh_digest

    framing = framing or resolve_framing(spec)
    model_digest = model_digest or compute_model_digest(spec.spec.model.name, framing.model)
    s = spec.spec
    render_base = {"stage": "render", "v": RENDER_STAGE_VERSION, "blender": blender_version(),
                   "settings": s.render.key_part(framing.key_part()),
                   "passes": []}  # the RGB image's; extra passes leave it alone and are keyed apart
    infer_base = {"stage": "infer", "v": INFER_STAGE_VERSION, "model": model_digest,
                  "evaluator": {"kind": s.evaluator.kind, "top_k": s.evaluator.top_k}}
    if s.model.backend != "torch":  # another backend may differ in the last bits: its own answers
        infer_base["backend"] = s.model.backend
    rendered = sorted((c for c in spec.controls if c.control.stage == "render"),
                      key=lambda c: (c.control.order, spec.controls.index(c)))
    post = [c for c in spec.controls if c.control.stage == "post"]
    columns = [f"{c.id}_{p}" for c in spec.controls for p in c.spaces]

    jobs: list[Job] = []
    out_of_frame: list[Job] = []
    index = 0
    for obj in s.objects:
        object_digest = mesh_digest(spec.meshes[obj.name], spec.store)
        truth = list(spec.labels[obj.name])
        for env in s.environments:
            hdri = spec.hdris[env.name]
            env_part = {"hdri": file_digest(hdri) if hdri else None,
                        "color": list(env.color) if env.color else None, "strength": env.strength}
            # Everything of the render key that is fixed for the scene, hashed once.
            scene_key = digest({**render_base, "object": object_digest, "environment": env_part})
            scene_controls = [c for c in spec.controls if c.applies_to(obj.name, env.name)]
            space = SearchSpace(scene_controls)
            seed = int(digest([s.experiment.seed, obj.name, env.name])[:15], 16)
            if spec.policy.adaptive:
                points = spec.policy.points(space.shape, seed, (history or {}).get((obj.name, env.name), {}))
            else:
                points = spec.policy.points(space.shape, seed)
            for point in points:
                values = space.values(point)
                models = {c.id: c.control.params(values[c.id]) for c in scene_controls}
                params = {key: model.model_dump() for key, model in models.items()}
                render_key = digest({"scene": scene_key, "controls": _key_parts(rendered, params)})
                post_parts = _key_parts(post, params)
                image_key = render_key
                if post_parts:
                    stochastic = any(getattr(c.control, "stochastic", False) for c in post
                                     if c.id in params and not c.control.is_identity(params[c.id]))
                    image_key = digest({"stage": "post", "v": POST_STAGE_VERSION, "render": render_key,
                                        "controls": post_parts, "seed": s.experiment.seed if stochastic else None})
                pred_key = digest({**infer_base, "image": image_key, "truth": truth})
                parts_key = (digest({"stage": "parts", "layout": PARTS_LAYOUT, "render": render_key})
                             if s.report.part_visibility else None)
                job = Job(index, obj.name, env.name, params, render_key, image_key, pred_key, point, parts_key)
                index += 1
                (jobs if _in_frame(rendered, models) else out_of_frame).append(job)
    return Plan(spec, jobs, model_digest, columns, out_of_frame, framing)


def _in_frame(rendered: list[ControlInstance], models: dict[str, Any]) -> bool:
    """Whether the job's object can appear in its image, from geometry alone (no rendering)."""
    from sweep3d.stages.render.state import (  # the render package imports this one
        SceneState,
        in_frame,
    )

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

