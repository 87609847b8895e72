"""The base class of post-processing controls."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from sweep3d.core import Control, ControlParams, Registry


class PostControl(Control):
    """Maps a rendered image to a new one, after rendering (so changing it re-renders nothing).

    ``apply`` receives and returns float32 arrays of shape (H, W, 3) in [0, 1]. Controls that
    draw random numbers set ``stochastic = True`` and must use only the ``rng`` they are given,
    which is seeded from the job's cache key so cached results are reproducible.

    A control that reads render passes declares them (``passes = ("depth",)``, and/or "mask"):
    they are then rendered for every job, and ``apply`` is called with a fourth argument, ``frame``,
    a :class:`~sweep3d.stages.postprocess.frame.RenderFrame` holding the job's pass arrays and its
    camera (``apply(self, image, params, rng, frame)``). An ``apply`` that takes three arguments
    is called with three, as before.
    """

    stage = "post"
    stochastic: ClassVar[bool] = False

    def apply(self, image: np.ndarray, params: ControlParams, rng: np.random.Generator) -> np.ndarray:
        raise NotImplementedError


#: The post-processing controls a spec may name (``[[controls]] type = ...``).
POST_CONTROLS: Registry[type[PostControl]] = Registry("control")
