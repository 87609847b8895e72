"""What a render costs before it is made: ``plan``'s estimate and the warning for settings that
would run for hours (``samples = 65536``, ``resolution = 4096``) before ``run`` starts on them."""

from __future__ import annotations

from sweep3d.spec import RenderSpec

# Fallback per-image costs on a 2-core CPU (measured with bench), when the store has no history.
SECONDS_PER_SAMPLE_224 = 0.034
DENOISE_SECONDS_224 = {"fast": 0.04, "accurate": 0.3, "none": 0.02}
#: Each engine's (seconds per sample, seconds per render besides samples and the denoiser) at 224².
#: Cycles': measured with bench. Mitsuba's (issue 45): the same tiny spec (2 objects × white and
#: studio × 6 yaws, 224² of 256², denoised) run with each engine at 4 and 16 samples; the runs' CPU
#: seconds, steadier than their wall time on a shared machine, gave Mitsuba 2.2× Cycles' CPU per
#: sample and 0.17 s more per render (its scene is translated per job, its denoiser's albedo and
#: normals rendered), put on Cycles' basis: about 2.5× Cycles' estimate at 4–16 samples
#: (benchmarks/RESULTS.md, "The Mitsuba engine's cost in plan's estimate").
ENGINE_SECONDS_224 = {"cycles": (SECONDS_PER_SAMPLE_224, 0.02), "mitsuba": (0.075, 0.19)}
#: Estimated render time past which ``plan`` and ``run`` warn.
LONG_RENDERING_SECONDS = 3600.0


#: The truth passes' own work per render (reading the passes back, encoding them), and the
#: index-only second render where an occluder or the frame's edge hides part of the object,
#: counted for every render as the planner does not know which (benchmarks/RESULTS.md).
TRUTH_SECONDS_224 = 0.02
SECOND_RENDER_SECONDS_224 = 0.15


def estimate_render_seconds(render: RenderSpec, pixels: int, truth_passes: bool = False,
                            hidden: bool = False) -> float:
    """A rough per-render cost from the settings, the engine and the rendered side in pixels
    (measured on 2 CPU cores; see docs/architecture.md).

    Args:
        truth_passes: the renders carry the mask (and depth) pass.
        hidden: an occluder or the frame's edge may hide part of the object (a control that
            occludes or moves it), so the mask pass needs its second render.
    """
    scale = (pixels / 224) ** 2
    denoise = DENOISE_SECONDS_224[render.denoise_prefilter] if render.denoise else 0.0
    passes = (TRUTH_SECONDS_224 + (SECOND_RENDER_SECONDS_224 if hidden else 0.0)) if truth_passes else 0.0
    per_sample, per_render = ENGINE_SECONDS_224[render.engine]
    return (per_sample * render.samples + denoise + per_render + passes) * scale


def slow_render_warning(render: RenderSpec, pixels: int, renders: int) -> str | None:
    """One line when ``renders`` renders at these settings would take over an hour, or one render
    longer than ``render.timeout`` (so each would fail); None when they would not."""
    each = estimate_render_seconds(render, pixels)
    total = each * renders
    if renders == 0 or (total <= LONG_RENDERING_SECONDS and each <= render.timeout):
        return None
    line = (f"{renders:,} renders at about {duration(each)} each ({pixels}² pixels, {render.samples} samples) "
            f"would take about {duration(total)} on 2 CPU cores")
    if each > render.timeout:
        line += f", and each is over render.timeout = {render.timeout:g} s, so every render would time out"
    return line + "; lower [render] samples or resolution (sweep3d bench finds the cheapest that is as good)"


def duration(seconds: float) -> str:
    """Seconds as a short human duration: 42 s, 3.5 min, 4.4 h."""
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"
