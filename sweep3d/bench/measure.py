"""Measure render settings against a high-sample reference on a seeded sample of a spec's jobs.

Every setting's renders and predictions go through the normal cached stages, so a second
bench (or a run at the chosen setting) reuses them. Error is measured on the renders (PSNR,
SSIM against the reference, at the reference's resolution); agreement on the predictions
(same top-1 class; same correct/incorrect verdict).
"""

from __future__ import annotations

import dataclasses
import statistics
from dataclasses import dataclass

import numpy as np

from sweep3d.cache.store import Store
from sweep3d.errors import UserError
from sweep3d.pixels import decode_png
from sweep3d.progress import RunProgress
from sweep3d.spec.loader import LoadedSpec
from sweep3d.stages.infer import infer_stage
from sweep3d.stages.plan import Plan, make_plan
from sweep3d.stages.postprocess import postprocess_stage
from sweep3d.stages.render import render_stage


@dataclass(frozen=True)
class Setting:
    """Render settings that trade time for error (the rest of [render] stays as in the spec)."""

    samples: int
    denoise: str  # "off" or the OIDN prefilter: "none", "fast", "accurate"
    max_bounces: int = 8
    resolution: int | None = None  # None: the spec's

    def render_update(self, spec_resolution: int) -> dict:
        return {"samples": self.samples, "denoise": self.denoise != "off",
                "denoise_prefilter": "fast" if self.denoise == "off" else self.denoise,
                "max_bounces": self.max_bounces, "resolution": self.resolution or spec_resolution}

    def label(self) -> str:
        """Compact, e.g. ``4spp oidn-fast``, ``64spp plain b2 160px``."""
        parts = [f"{self.samples}spp", "plain" if self.denoise == "off" else f"oidn-{self.denoise}"]
        if self.max_bounces != 8:
            parts.append(f"b{self.max_bounces}")
        if self.resolution:
            parts.append(f"{self.resolution}px")
        return " ".join(parts)


@dataclass
class BenchRow:
    setting: Setting
    seconds: float  # median render seconds per image
    psnr: float  # dB against the reference, mean over jobs
    ssim: float
    top1_agreement: float  # share of jobs whose top-1 class matches the reference's
    verdict_agreement: float  # share whose correct/incorrect verdict matches
    is_reference: bool = False


def default_settings(current: Setting) -> list[Setting]:
    """The grid: samples × denoiser, a few bounce and resolution variants, and the spec's own."""
    grid = [Setting(s, d) for s in (1, 4, 16, 64) for d in ("off", "fast", "accurate")]
    grid += [Setting(4, "fast", max_bounces=b) for b in (2, 4)]
    grid += [Setting(4, "fast", resolution=160)]
    return list(dict.fromkeys(grid + [current]))


def measure(loaded: LoadedSpec, settings: list[Setting], reference: Setting, jobs: int,
            progress: RunProgress) -> list[BenchRow]:
    """Render the sample under every setting and the reference; compare each with the reference."""
    plans = {}
    indices = None
    for setting in [reference] + settings:
        plan = make_plan(_with(loaded, setting))
        if indices is None:
            indices = _sample(plan, jobs, loaded.spec.experiment.seed)
        by_index = {j.index: j for j in plan.jobs}
        plans[setting] = Plan(plan.spec, [by_index[i] for i in indices], plan.model_digest, plan.columns)
    store = Store(loaded.store)
    with store.lock():
        for setting, plan in plans.items():
            for stage in (render_stage, postprocess_stage, infer_stage):
                outcome = stage(plan, store, progress)
                if outcome.failed:
                    raise UserError(f"bench: {outcome.failed} {outcome.stage} jobs failed at {setting.label()}: "
                                    f"{outcome.errors[0].splitlines()[0]}")
    con = store.connect()
    seconds = dict(con.execute("SELECT render_key, seconds FROM renders").fetchall())
    verdicts = {r[0]: (r[1], r[2]) for r in con.execute("SELECT pred_key, top1, correct FROM predictions").fetchall()}
    ref_plan = plans[reference]
    ref_images = [decode_png(store.blob_path(j.render_key)) for j in ref_plan.jobs]
    rows = []
    for setting, plan in plans.items():
        images = [decode_png(store.blob_path(j.render_key)) for j in plan.jobs]
        errors = [_errors(img, ref) for img, ref in zip(images, ref_images)]
        same_top1 = [verdicts[j.pred_key][0] == verdicts[r.pred_key][0] for j, r in zip(plan.jobs, ref_plan.jobs)]
        same_verdict = [verdicts[j.pred_key][1] == verdicts[r.pred_key][1] for j, r in zip(plan.jobs, ref_plan.jobs)]
        rows.append(BenchRow(
            setting, statistics.median(seconds[j.render_key] for j in plan.jobs),
            float(np.mean([e[0] for e in errors])), float(np.mean([e[1] for e in errors])),
            float(np.mean(same_top1)), float(np.mean(same_verdict)), is_reference=setting == reference))
    return rows


def recommend(rows: list[BenchRow], agreement: float = 0.99) -> BenchRow | None:
    """The fastest non-reference setting whose top-1 and verdict agreement both reach ``agreement``."""
    good = [r for r in rows if not r.is_reference and min(r.top1_agreement, r.verdict_agreement) >= agreement]
    return min(good, key=lambda r: r.seconds, default=None)


def pareto(rows: list[BenchRow]) -> list[BenchRow]:
    """Settings no other setting beats on both time and PSNR."""
    return [r for r in rows if not any(o.seconds <= r.seconds and o.psnr >= r.psnr and o is not r
                                       and (o.seconds < r.seconds or o.psnr > r.psnr) for o in rows)]


def _with(loaded: LoadedSpec, setting: Setting) -> LoadedSpec:
    render = loaded.spec.render.model_copy(update=setting.render_update(loaded.spec.render.resolution))
    return dataclasses.replace(loaded, spec=loaded.spec.model_copy(update={"render": render}))


def _sample(plan: Plan, jobs: int, seed: int) -> list[int]:
    """A seeded sample of job indices with distinct renders."""
    distinct = list({j.render_key: j for j in plan.jobs}.values())
    if not distinct:
        raise UserError("bench: the spec plans no job that can be rendered")
    rng = np.random.default_rng(seed)
    chosen = rng.choice(len(distinct), size=min(jobs, len(distinct)), replace=False)
    return sorted(distinct[i].index for i in chosen)


def _errors(image: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """(PSNR in dB, SSIM) of ``image`` against ``reference``, resized to it if needed."""
    from skimage.metrics import structural_similarity

    if image.shape != reference.shape:
        from PIL import Image

        pil = Image.fromarray((np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8))
        image = np.asarray(pil.resize(reference.shape[1::-1], Image.Resampling.BICUBIC), np.float32) / 255.0
    mse = float(np.mean((image - reference) ** 2))
    psnr = 100.0 if mse == 0 else 10.0 * np.log10(1.0 / mse)
    ssim = float(structural_similarity(image, reference, channel_axis=2, data_range=1.0))
    return psnr, ssim
