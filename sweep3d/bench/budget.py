"""``sweep3d bench --budget MINUTES``: the most jobs whose bench is estimated to fit the minutes.

The estimate is made before anything renders, from the settings compared: each setting's render
cost (``stages/render/estimate.py``: per-sample and denoiser costs measured on 2 CPU cores, at
the pixels that setting renders) plus postprocessing and inference per job, and what does not
grow with the jobs: every setting's pass in each round starts a render worker and the inference
stage, and loads the scenes its jobs are in. Plain Python: no Blender, no torch.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from sweep3d.bench.measurement import ROUNDS, Setting
from sweep3d.core import UserError
from sweep3d.driver import Plan
from sweep3d.spec import LoadedSpec
from sweep3d.stages.render import duration, estimate_render_seconds

#: Per job and setting, besides the render: postprocessing and inference (2 CPU cores).
IMAGE_SECONDS = 0.055
#: Per setting and round: a render worker's start (process, ``import bpy``, its scene, the first
#: render's kernels) and the inference stage's set-up (the model's checks, its ONNX session). A
#: 1-job bench (19 such passes of 32² renders) took 3.0 min at a load average of 4-5 on 2 cores.
PASS_SECONDS = 8.0
#: Per scene a pass renders in: a mesh import, a world, Cycles' BVH and the HDRI's importance map.
SCENE_LOAD_SECONDS = 1.0


def check_budget(minutes: float) -> float:
    """``--budget``, refused unless a finite number of minutes > 0 (one line, exit code 2)."""
    if not (math.isfinite(minutes) and minutes > 0):
        raise UserError(f"--budget {minutes:g}: give the minutes the bench may take, a finite number > 0")
    return minutes


def bench_seconds(jobs: int, render_seconds: Sequence[float], scenes: int, rounds: int) -> float:
    """Estimated wall of a bench of ``jobs`` jobs drawn from ``scenes`` scenes, rendered in
    ``rounds`` rounds under settings whose renders cost ``render_seconds`` each (references
    included); nothing cached."""
    passes = min(rounds, jobs)  # a round with no job starts nothing
    per_pass = math.ceil(jobs / passes) if passes else 0
    loads = passes * min(per_pass, max(scenes, 1))  # a pass's jobs are spread over its scenes
    fixed = passes * PASS_SECONDS + loads * SCENE_LOAD_SECONDS
    return sum(jobs * (each + IMAGE_SECONDS) + fixed for each in render_seconds)


@dataclass(frozen=True)
class BudgetChoice:
    """The jobs ``--budget`` chose, and why."""

    minutes: float
    jobs: int
    seconds: float  # the bench's estimated wall at ``jobs``
    per_job: float  # renders, postprocessing and inference of one job under every setting
    settings: int  # settings compared, references included
    available: int  # distinct renders the spec plans: the most jobs a bench can sample

    def line(self) -> str:
        """One line saying what was chosen and why."""
        fixed = self.seconds - self.jobs * self.per_job
        why = (f"every distinct render the spec plans, estimated {duration(self.seconds)}" if self.jobs == self.available
               else f"the most estimated to fit: {duration(self.seconds)}")
        return (f"--budget {self.minutes:g} min: {self.jobs} job{'s' if self.jobs != 1 else ''}, {why} ({self.settings} settings with the "
                f"references: about {self.per_job:.1f} s of rendering and inference per job, plus "
                f"{duration(fixed)} of worker starts and scene loads; an estimate from per-sample costs on "
                "2 CPU cores)")


def choose_jobs(minutes: float, render_seconds: Sequence[float], scenes: int, available: int,
                rounds: int) -> BudgetChoice:
    """The most jobs (at most ``available``) whose estimated bench fits ``minutes``.

    Raises:
        UserError: not even one job fits; the message says how long one would take.
    """
    budget = check_budget(minutes) * 60.0
    per_job = sum(each + IMAGE_SECONDS for each in render_seconds)

    def choice(jobs: int) -> BudgetChoice:
        seconds = bench_seconds(jobs, render_seconds, scenes, rounds)
        return BudgetChoice(minutes, jobs, seconds, per_job, len(render_seconds), available)

    if available < 1:
        raise UserError("bench: the spec plans no job that can be rendered")
    smallest = choice(1)
    if smallest.seconds > budget:
        raise UserError(f"--budget {minutes:g} min is too short: a bench of 1 job is estimated at "
                        f"{duration(smallest.seconds)} with these settings; give more minutes, or lower "
                        "--reference-samples or add --no-floor")
    low, high = 1, available  # the estimate grows with the jobs: the largest that fits
    while low < high:
        mid = (low + high + 1) // 2
        if bench_seconds(mid, render_seconds, scenes, rounds) <= budget:
            low = mid
        else:
            high = mid - 1
    return choice(low)


def render_costs(loaded: LoadedSpec, settings: Sequence[Setting], model_crop: int) -> list[float]:
    """Each setting's estimated seconds per render, at the pixels it renders (``model_crop`` for
    the model's framing)."""
    render = loaded.spec.render
    costs = []
    for setting in settings:
        resolution = setting.resolution or render.resolution
        side = model_crop if resolution == "model" else int(resolution)
        costs.append(estimate_render_seconds(render.model_copy(update=setting.render_update(render.resolution)), side))
    return costs


def budget_chooser(loaded: LoadedSpec, settings: Sequence[Setting], minutes: float,
                   report: Callable[[BudgetChoice], None]) -> Callable[[Plan], int]:
    """For :func:`sweep3d.bench.measurement.measure`: picks the jobs from the reference's plan (its
    scenes and distinct renders) for ``settings`` (references included) and ``report`` s the choice."""
    check_budget(minutes)

    def choose(plan: Plan) -> int:
        framing = plan.framing
        renders = {job.render_key for job in plan.jobs}
        scenes = {job.scene for job in plan.jobs}
        costs = render_costs(loaded, settings, framing.crop if framing is not None else 224)
        choice = choose_jobs(minutes, costs, len(scenes), len(renders), ROUNDS)
        report(choice)
        return choice.jobs

    return choose
