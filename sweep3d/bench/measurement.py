"""Measure render settings against a high-sample reference on a seeded sample of a spec's jobs.

Every setting's renders and predictions go through the normal cached stages, so a second
bench (or a run at the chosen setting) reuses them. Error is measured on what the model sees:
the reference is rendered at the model's input (``resolution = "model"``) when its size is
known, and each setting's image is brought to that view by the model's own resize and crop
before PSNR and SSIM, so full-frame and model-framed settings are compared like with like.
Agreement is measured on the predictions (same top-1 class; same correct/incorrect verdict),
with a 95 % Wilson interval, against a noise floor: the reference rendered again with
another seed (a near-tie job can flip between two references too). The reference and the grid
are rendered by the spec's renderer; another renderer (``--engine``) adds its rows at the spec's
setting.

Time is steady-state: each worker reports what switching to a job's scene cost (a mesh import,
a world, Cycles' BVH and importance map: ``RenderInfo.load_seconds``), and a setting's s/img is
the median of its renders' time without it, so a spec with many scenes gives the same speed-ups
as one cut to a single scene. The loads are reported beside it.
"""

from __future__ import annotations

import dataclasses
import functools
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from sweep3d.cache import Store
from sweep3d.core import UserError, decode_png
from sweep3d.driver import Plan, RunProgress
from sweep3d.results import wilson_interval
from sweep3d.runner import plan_spec, running
from sweep3d.spec import LoadedSpec
from sweep3d.stages.infer import ModelHandle, Preprocess
from sweep3d.stages.render import RenderInfo

#: The sample is rendered in this many rounds, every setting taking its turn in each, so that
#: timings taken on a shared machine whose load changes are comparable (a worker start per turn).
ROUNDS = 4


@dataclass(frozen=True)
class Setting:
    """Render settings that trade time for error (the rest of [render] stays as in the spec)."""

    samples: int
    denoise: str  # "off" or the OIDN prefilter: "none", "fast", "accurate"
    max_bounces: int = 8
    resolution: int | str | None = None  # None: the spec's; "model": the model's input
    adaptive: float = 0.0  # Cycles adaptive sampling threshold (0 = off)
    seed: int = 0  # the renderer's seed: the noise-floor reference differs from the reference only here
    engine: str = "cycles"  # the spec's renderer, or another's row: its time against the spec renderer's reference

    def render_update(self, spec_resolution: int | str) -> dict:
        return {"samples": self.samples, "denoise": self.denoise != "off",
                "denoise_prefilter": "fast" if self.denoise == "off" else self.denoise,
                "max_bounces": self.max_bounces, "resolution": self.resolution or spec_resolution,
                "adaptive_threshold": self.adaptive, "seed": self.seed, "engine": self.engine}

    def label(self) -> str:
        """Compact, e.g. ``4spp oidn-fast``, ``64spp plain b2 160px``, ``4spp oidn-fast model``."""
        parts = [f"{self.samples}spp", "plain" if self.denoise == "off" else f"oidn-{self.denoise}"]
        if self.engine != "cycles":
            parts.insert(0, self.engine)
        if self.adaptive:
            parts.append(f"adaptive {self.adaptive:g}")
        if self.max_bounces != 8:
            parts.append(f"b{self.max_bounces}")
        if self.resolution == "model":
            parts.append("model")
        elif self.resolution:
            parts.append(f"{self.resolution}px")
        if self.seed:
            parts.append(f"seed {self.seed}")
        return " ".join(parts)


@dataclass
class BenchRow:
    setting: Setting
    seconds: float  # median steady-state render seconds per image (scene loads left out)
    psnr: float  # dB against the reference, mean over jobs, in the model's view
    ssim: float
    top1: int  # jobs whose top-1 class matches the reference's
    verdicts: int  # jobs whose correct/incorrect verdict matches
    jobs: int
    is_reference: bool = False
    is_floor: bool = False  # the reference again with another seed: the noise floor
    passes: bool = False  # set by :func:`recommend`
    load_seconds: float | None = None  # mean seconds per scene load in this run (None: none timed)
    loads: int = 0  # renders of this run that switched scene first
    timed: int = 0  # renders made in this run (the rest were cached: their stored time holds any load)
    render_total: float = 0.0  # steady-state seconds of this run's renders, loads left out

    @property
    def load_total(self) -> float:
        """Seconds this run's renders of the setting spent loading scenes."""
        return (self.load_seconds or 0.0) * self.loads

    @property
    def top1_agreement(self) -> float:
        return self.top1 / self.jobs

    @property
    def verdict_agreement(self) -> float:
        return self.verdicts / self.jobs

    def interval(self) -> tuple[float, float]:
        """95 % Wilson interval of the top-1 agreement (verdicts agree whenever top-1 classes do)."""
        return wilson_interval(self.top1, self.jobs)

    @property
    def is_setting(self) -> bool:
        """A candidate (not one of the two references)."""
        return not (self.is_reference or self.is_floor)


def default_settings(current: Setting, model_view: bool = True, full_frame: int | None = None,
                     engines: Sequence[str] = ()) -> list[Setting]:
    """The grid in the spec's renderer: samples × denoiser, adaptive sampling (where the renderer
    has it), bounces, resolutions, the model's view (when its input size is known), the spec's own
    setting, and that setting in each of ``engines``.

    Args:
        full_frame: the pixel size of the grid's full-frame settings when the spec itself renders
            at the model's framing (they would otherwise repeat the model-framed ones).
        engines: other renderers to time and compare with the reference at the spec's setting.
    """
    from sweep3d.stages.render import engine_backend

    side = full_frame if current.resolution == "model" else None
    own = functools.partial(Setting, engine=current.engine)
    grid = [own(s, d, resolution=side) for s in (1, 4, 16) for d in ("off", "fast", "accurate")]
    grid += [own(64, "fast", resolution=side)]
    if "adaptive_threshold" not in engine_backend(current.engine).ignored_settings:
        grid += [own(64, "fast", resolution=side, adaptive=0.05)]
    grid += [own(4, "fast", max_bounces=b, resolution=side) for b in (2, 4)]
    grid += [own(4, "fast", resolution=160)]
    if model_view:
        grid += [own(s, d, resolution="model") for s, d in ((1, "fast"), (4, "fast"), (4, "accurate"), (16, "fast"))]
    others = [dataclasses.replace(current, engine=e) for e in engines if e != current.engine]
    return list(dict.fromkeys(grid + [current] + others))


def reference_settings(samples: int, denoise: str, current: Setting, model_view: bool) -> tuple[Setting, Setting]:
    """The reference and its noise floor (the same render with another seed), both in the spec's
    renderer: a second renderer's settings are judged by its own converged image."""
    reference = Setting(samples, denoise, max(current.max_bounces, 12), "model" if model_view else None,
                        engine=current.engine)
    return reference, dataclasses.replace(reference, seed=1)


def measure(loaded: LoadedSpec, settings: list[Setting], reference: Setting, floor: Setting | None,
            jobs: int | Callable[[Plan], int], progress: RunProgress, wait: float = 0.0) -> list[BenchRow]:
    """Render the sample under every setting and both references; compare each with the reference.

    Args:
        jobs: the sample's size, or a function choosing it from the reference's whole plan
            (``--budget``: see :mod:`sweep3d.bench.budget`), called before anything renders.
        wait: seconds to wait for another command holding the store's lock.
    """
    plans: dict[Setting, Plan] = {}
    models: dict[Setting, ModelHandle] = {}
    indices = None
    for setting in [reference] + ([floor] if floor else []) + settings:
        variant = _with(loaded, setting)
        models[setting] = ModelHandle.resolve(variant)
        plan = plan_spec(variant, models[setting])
        if indices is None:
            count = jobs(plan) if callable(jobs) else jobs
            indices = _sample(plan, count, loaded.spec.experiment.seed)
        by_index = {j.index: j for j in plan.jobs}
        plans[setting] = dataclasses.replace(plan, jobs=[by_index[i] for i in indices], out_of_frame=[])
    store = Store(loaded.store)
    timings: dict[str, RenderInfo] = {}  # the renders made in this run, with their scene loads
    with running(loaded, wait=wait, progress=progress, store=store) as runner:
        for chunk in range(ROUNDS):  # settings take turns, so a machine's changing load hits all alike
            for setting, plan in plans.items():
                n = len(plan.jobs)  # contiguous: a scene's jobs stay together, as in a run
                part = dataclasses.replace(plan, jobs=plan.jobs[chunk * n // ROUNDS : (chunk + 1) * n // ROUNDS])
                # a timed render stage per turn (a worker start each), every image stored
                try:
                    runner.run(part, models[setting], every_image=True, timings=timings, strict=True, overlap=False)
                except UserError as exc:
                    raise UserError(f"bench at {setting.label()}: {exc}") from None
    con = store.connect()
    seconds = dict(con.execute("SELECT render_key, seconds FROM renders").fetchall())
    verdicts = {r[0]: (r[1], r[2]) for r in con.execute("SELECT pred_key, top1, correct FROM predictions").fetchall()}
    ref_plan = plans[reference]
    view = models[reference].view
    ref_images = [_as_seen(decode_png(store.blob_path(j.render_key)), ref_plan, view) for j in ref_plan.jobs]
    rows = []
    for setting, plan in plans.items():
        images = [_as_seen(decode_png(store.blob_path(j.render_key)), plan, view, ref_images[0].shape[0])
                  for j in plan.jobs]
        errors = [_errors(img, ref) for img, ref in zip(images, ref_images)]
        pairs = [(verdicts[j.pred_key], verdicts[r.pred_key]) for j, r in zip(plan.jobs, ref_plan.jobs)]
        rows.append(BenchRow(
            setting=setting, psnr=float(np.mean([e[0] for e in errors])), ssim=float(np.mean([e[1] for e in errors])),
            top1=sum(a[0] == b[0] for a, b in pairs), verdicts=sum(a[1] == b[1] for a, b in pairs), jobs=len(pairs),
            is_reference=setting == reference, is_floor=setting == floor,
            **split_times([j.render_key for j in plan.jobs], timings, seconds)))
    return rows


def split_times(keys: list[str], timings: dict[str, RenderInfo], stored: dict[str, float]) -> dict:
    """One setting's times over its render ``keys``, as :class:`BenchRow` fields: ``seconds``
    (median steady-state seconds per render), ``load_seconds`` (mean seconds per scene load, None
    without one), ``loads``, ``timed`` (renders made in this run) and ``render_total``.

    The steady time is taken over the renders made in this run (``timings``: each without its
    scene load); when all were cached, over their ``stored`` seconds, which hold whatever load
    the run that made them paid.
    """
    fresh = [timings[k] for k in keys if k in timings]
    if fresh:
        steady = statistics.median(info.render_seconds for info in fresh)
    else:
        steady = statistics.median(stored[k] for k in keys)
    loads = [info.load_seconds for info in fresh if info.load_seconds > 0]
    return {"seconds": steady, "load_seconds": statistics.fmean(loads) if loads else None, "loads": len(loads),
            "timed": len(fresh), "render_total": sum(info.render_seconds for info in fresh)}


def recommend(rows: list[BenchRow], agreement: float = 0.99, engine: str = "cycles") -> BenchRow | None:
    """The fastest setting of ``engine`` (the spec's renderer) that passes; marks each row's ``passes``.

    Another renderer's rows are measured and marked but never recommended: the bench tunes the
    spec's renders; a change of renderer is the user's call (``[render] engine``).

    A setting passes when its top-1 agreement with the reference is not clearly below the
    target: the top of its 95 % Wilson interval reaches ``agreement``, or the noise floor's
    agreement (the reference against itself at another seed) if that is lower, since no
    setting can be expected to agree with the reference more than the reference does with itself.
    """
    target = required_agreement(rows, agreement)
    for row in rows:
        row.passes = row.is_setting and row.interval()[1] >= target
    return min((r for r in rows if r.passes and r.setting.engine == engine), key=lambda r: r.seconds, default=None)


def required_agreement(rows: list[BenchRow], agreement: float) -> float:
    """The target, lowered to the noise floor's agreement when that is lower."""
    floor = next((r for r in rows if r.is_floor), None)
    return min(agreement, floor.top1_agreement) if floor else agreement


def pareto(rows: list[BenchRow]) -> list[BenchRow]:
    """Settings no other setting beats on both time and PSNR."""
    return [r for r in rows if not any(o.seconds <= r.seconds and o.psnr >= r.psnr and o is not r
                                       and (o.seconds < r.seconds or o.psnr > r.psnr) for o in rows)]


def _with(loaded: LoadedSpec, setting: Setting) -> LoadedSpec:
    render = loaded.spec.render.model_copy(update=setting.render_update(loaded.spec.render.resolution))
    # the bench times images: the spec's truth passes (mask, depth) would add their own cost
    evaluator = loaded.spec.evaluator.model_copy(update={"passes": []})
    return dataclasses.replace(loaded, spec=loaded.spec.model_copy(update={"render": render, "evaluator": evaluator}))


def _sample(plan: Plan, jobs: int, seed: int) -> list[int]:
    """A seeded sample of job indices with distinct renders: renders drawn at random, then one of
    each render's jobs at random (not always the last: with a post control such as blur, that
    would sample only its last value)."""
    by_render: dict[str, list[int]] = {}
    for job in plan.jobs:
        by_render.setdefault(job.render_key, []).append(job.index)
    if not by_render:
        raise UserError("bench: the spec plans no job that can be rendered")
    renders = list(by_render.values())
    rng = np.random.default_rng(seed)
    chosen = rng.choice(len(renders), size=min(jobs, len(renders)), replace=False)
    pick = np.random.default_rng([seed, 1])
    return sorted(int(pick.choice(renders[i])) for i in chosen)


def _as_seen(image: np.ndarray, plan: Plan, view: Preprocess | None, side: int | None = None) -> np.ndarray:
    """The image as the model sees it (its resize and centre crop; nothing for a model-framed
    render), or, when the model's input size is unknown, resized to the reference's ``side``."""
    framing = plan.framing
    if framing is not None and framing.model:
        return image
    if view is None:  # a user's own preprocessing: compare at the reference's resolution
        return image if side in (None, image.shape[0]) else _resize(image, side)
    geometry = Preprocess(view.resize, view.crop, mean=(0.0, 0.0, 0.0), std=(1.0, 1.0, 1.0))
    return geometry(image[None])[0].permute(1, 2, 0).numpy()


def _resize(image: np.ndarray, side: int) -> np.ndarray:
    from PIL import Image

    pil = Image.fromarray((np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8))
    return np.asarray(pil.resize((side, side), Image.Resampling.BICUBIC), np.float32) / 255.0


def _errors(image: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """(PSNR in dB, SSIM) of ``image`` against ``reference`` (same shape)."""
    from skimage.metrics import structural_similarity

    image = np.clip(image, 0.0, 1.0)
    mse = float(np.mean((image - reference) ** 2))
    psnr = 100.0 if mse == 0 else 10.0 * np.log10(1.0 / mse)
    ssim = float(structural_similarity(image, reference, channel_axis=2, data_range=1.0))
    return psnr, ssim
