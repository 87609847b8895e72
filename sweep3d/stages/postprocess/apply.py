"""Applying a job's post controls to one image: in the run's process, or in a post-processing worker
(``post_workers``), with the same bytes either way: each control draws only from the generator
seeded by the job's image key (the corruptions seed numpy's global one from it, per call).
"""

from __future__ import annotations

import inspect
from functools import lru_cache
from typing import Any, Sequence

import numpy as np

from sweep3d.core import TRUTH_PASSES, PluginError, blamed, is_user_plugin, to_uint8
from sweep3d.spec import ControlInstance
from sweep3d.stages.postprocess.frame import RenderFrame


def apply_post(image: np.ndarray, controls: Sequence[ControlInstance], values: dict[str, dict[str, Any]],
               seed_key: str, frame: RenderFrame | None = None) -> np.ndarray:
    """Apply the post controls that this job has, in spec order.

    Args:
        image: float32 (H, W, 3) in [0, 1].
        seed_key: the job's image key; seeds the random generator so results are reproducible.
        frame: the job's render passes and camera, for the controls that declare ``passes``.
    """
    rng = np.random.default_rng(int(seed_key[:16], 16))
    out = image
    for inst in controls:
        if inst.id in values and not inst.control.is_identity(values[inst.id]):
            out = _applied(inst, out, inst.control.params(values[inst.id]), rng, frame)
    return np.asarray(out, dtype=np.float32)


def reads_passes(inst: ControlInstance, values: dict[str, dict[str, Any]]) -> tuple[str, ...]:
    """The truth passes ``inst`` reads for a job with ``values`` (none when it is neutral there)."""
    passes = tuple(p for p in getattr(inst.control, "passes", ()) if p in TRUTH_PASSES)
    if not passes or inst.id not in values or inst.control.is_identity(values[inst.id]):
        return ()
    return passes


@lru_cache(maxsize=None)
def takes_frame(cls: type) -> bool:
    """Whether ``cls.apply`` accepts a fourth argument (the frame): older controls take three."""
    try:
        parameters = list(inspect.signature(cls.apply).parameters.values())[1:]  # after self
    except (TypeError, ValueError):
        return False
    if any(p.kind is inspect.Parameter.VAR_POSITIONAL for p in parameters):
        return True
    positional = [p for p in parameters if p.kind in (inspect.Parameter.POSITIONAL_ONLY,
                                                      inspect.Parameter.POSITIONAL_OR_KEYWORD)]
    return len(positional) >= 4


def _applied(inst: ControlInstance, image: np.ndarray, params: Any, rng: np.random.Generator,
             frame: RenderFrame | None = None) -> np.ndarray:
    """One control's ``apply`` (with the frame when it declares passes and takes one); a user's
    control that raises or returns no image of ``image``'s shape is a :class:`PluginError` naming
    it (sweep3d's own controls' failures are bugs: raised)."""
    control = inst.control
    with blamed(control, "apply()"):
        if getattr(control, "passes", ()) and takes_frame(type(control)):
            out = control.apply(image, params, rng, frame)
        else:
            out = control.apply(image, params, rng)
    try:
        array = np.asarray(out, dtype=np.float32)
    except (TypeError, ValueError):
        array = None
    if array is None or array.shape != image.shape:
        what = f"an array of shape {array.shape}" if array is not None else f"a {type(out).__name__}"
        raise PluginError(f"control {control.type_name!r} (id {inst.id!r}) returned {what} from apply(); return the image as a float array of shape "
                          f"{image.shape} (H, W, 3), values in [0, 1]")
    return in_range(inst, array) if is_user_plugin(control.type_name) else array


#: How far outside [0, 1] a user's post control may go (float rounding), clipped; beyond it is refused.
RANGE_TOLERANCE = 1e-3


def in_range(inst: ControlInstance, array: np.ndarray) -> np.ndarray:
    """A user's control's image, its finite values in [0, 1]: a float overshoot within
    :data:`RANGE_TOLERANCE` is clipped; further out (an 8-bit image, 1e30) is a :class:`PluginError`
    naming the control, or the model would be tested on pixels no image has. NaN and infinity
    are left as they are: they make the image invalid, counted apart (see :class:`Made`)."""
    finite = np.isfinite(array)
    low = float(np.min(array, initial=np.inf, where=finite))  # no finite pixel: inf and -inf, nothing to refuse
    high = float(np.max(array, initial=-np.inf, where=finite))
    if low >= 0.0 and high <= 1.0:
        return array
    if low < -RANGE_TOLERANCE or high > 1.0 + RANGE_TOLERANCE:
        hint = " (divide an 8-bit image by 255)" if 1.5 < high <= 255.0 and low >= 0.0 else ""
        raise PluginError(f"control {inst.control.type_name!r} (id {inst.id!r}) returned values from {low:g} to "
                          f"{high:g} from apply(); return the image with values in [0, 1]{hint}")
    return np.clip(array, 0.0, 1.0, out=array.copy(), where=finite)


def post_image(render: np.ndarray, controls: Sequence[ControlInstance], values: dict[str, dict[str, Any]],
               seed_key: str, frame: RenderFrame | None = None) -> tuple[np.ndarray, bool]:
    """:func:`apply_post` as the store keeps its result: (uint8 pixels, whether the float image
    was finite before it was quantised)."""
    image = apply_post(render, controls, values, seed_key, frame)
    return to_uint8(image), bool(np.isfinite(image).all())
