"""What a render costs before it is made: ``plan``'s estimate and the warning for settings that
would run for hours (``samples = 65536``, ``resolution = 4096``) before ``run`` starts on them."""

from __future__ import annotations

from sweep3d.spec import RenderSpec
from sweep3d.stages.render.backends import backend

# Fallback per-image costs on a 2-core CPU (measured with bench), when the store has no history;
# each engine's own per sample and per render are its backend's ``seconds_224``.
DENOISE_SECONDS_224 = {"fast": 0.04, "accurate": 0.3, "none": 0.02}
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
    per_sample, per_render = backend(render.engine).seconds_224
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
