"""What a plan will cost before anything runs: per stage, the distinct keys needed, those already
cached, those to compute and an estimate of the time, for every model of the spec.

``Experiment.plan()`` returns it and ``sweep3d plan`` prints it (``cli/output.py``): the numbers are
the runner's, the command line only draws them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sweep3d.cache import Store
from sweep3d.driver import Plan, plugin_changes, stage_counts, truth_passes
from sweep3d.runner.pipeline import plan_spec
from sweep3d.runner.runner import Runner
from sweep3d.spec import LoadedSpec
from sweep3d.stages.infer import ModelHandle
from sweep3d.stages.render import estimate_render_seconds

#: Rendered controls that may hide part of the object (its mask pass then renders twice).
HIDING_CONTROLS = {"occlusion", "position", "camera", "scale"}

#: Seconds per image on a 2-core CPU, post-processing (a blur) and inference (EfficientNet-Lite0 on ONNX
#: Runtime): the image path measured in benchmarks/RESULTS.md (render costs: stages/render/estimate.py).
POST_SECONDS, INFER_SECONDS = 0.003, 0.009


@dataclass(frozen=True)
class StageStatus:
    """One row of the plan's table: a stage (per distinct framing for render and postprocess, per
    model for infer), its distinct keys, those cached, and the estimated seconds for the rest."""

    stage: str
    needed: int
    cached: int
    crop: int
    seconds: float

    @property
    def to_compute(self) -> int:
        return self.needed - self.cached


@dataclass(frozen=True)
class PlanStatus:
    """The plans of a spec's models and what each stage has cached and will compute.

    Attributes the first model's :class:`~sweep3d.stages.plan.Plan` has (``jobs``, ``table()``,
    ``out_of_frame``, ``columns``) read through from it: ``exp.plan().jobs`` is that plan's jobs.
    """

    spec: LoadedSpec
    plans: list[Plan]
    models: list[ModelHandle]
    stages: list[StageStatus]
    changed: list[str]  # one line per user plug-in changed since the last run (driver/plugin_code.py: explain)
    passes: list[str]  # the truth passes the renders carry

    @property
    def plan(self) -> Plan:
        """The first model's plan."""
        return self.plans[0]

    @property
    def seconds(self) -> float:
        """The estimated seconds of everything to compute."""
        return sum(s.seconds for s in self.stages)

    @property
    def to_render(self) -> int:
        """Renders to make, over every framing."""
        return sum(s.to_compute for s in self.stages if s.stage.startswith("render"))

    @property
    def crop(self) -> int:
        """The largest frame side any model renders at."""
        return max(p.framing.crop for p in self.plans)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or name not in _PLAN_ATTRIBUTES:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return getattr(self.plans[0], name)


_PLAN_ATTRIBUTES = {"jobs", "table", "out_of_frame", "columns", "framing", "model", "protocol"}


def plan_status(spec: LoadedSpec, store: Store | None = None) -> PlanStatus:
    """Plan ``spec`` for each of its models and count, per stage, what the store holds and what is left."""
    store = store or Store(spec.store)
    models = [ModelHandle.resolve(spec, settings) for settings in spec.models]
    plans = [plan_spec(spec, model) for model in models]
    passes = truth_passes(spec)
    hidden = any(c.control.type_name in HIDING_CONTROLS for c in spec.controls)
    stages = []
    for stage, needed, cached, crop in _models_status(plans, models, store):
        per_item = {"render": estimate_render_seconds(spec.render, crop, bool(passes), hidden),
                    "postprocess": POST_SECONDS}.get(stage.split(" ")[0], INFER_SECONDS)
        stages.append(StageStatus(stage, needed, cached, crop, (needed - cached) * per_item))
    return PlanStatus(spec, plans, models, stages, plugin_changes(plans[0], store), list(passes))


def cache_status(plan: Plan, store: Store, model: ModelHandle, several: bool = False) -> list[tuple[str, int, int]]:
    """(stage, distinct keys needed, keys already stored) for render, postprocess and infer (the
    runner's stages, counted: nothing runs)."""
    return [(getattr(stage, "title", stage.name), *stage_counts(stage, plan, store))
            for stage in Runner(plan.spec, store).stages(model, several=several)]


def _models_status(plans: list[Plan], models: list[ModelHandle], store: Store) -> list[tuple[str, int, int, int]]:
    """(stage, needed, cached, frame side): render and postprocess once per distinct framing (models
    framed alike share them), then infer once per model."""
    several = len(models) > 1
    framed: dict[object, list[tuple[str, int, int, int]]] = {}
    infers = []
    for plan, model in zip(plans, models):
        rows = [(*row, plan.framing.crop) for row in cache_status(plan, store, model, several)]
        framed.setdefault(plan.framing, rows[:2])
        infers.append(rows[2])
    if len(framed) > 1:  # say whose frame each render row is
        framed = {f: [(f"{stage} ({f.crop}²)", *rest) for stage, *rest in rows] for f, rows in framed.items()}
    return [row for rows in framed.values() for row in rows] + infers
