"""Inference on a Ray actor (on a GPU when the cluster has one), for ``--executor ray``.

The actor loads the model once and answers batches of images with logits; the driver keeps
evaluating and writing, so it stays the store's single writer.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class InferenceActor:
    """Holds one classifier; ``logits`` runs a batch on the actor's device."""

    def __init__(self, name: str, model_framed: bool = False, paths: tuple[str, ...] = ()) -> None:
        import sys

        import torch

        from sweep3d.stages.infer.models import for_model_framing, load_model

        # the driver's import path first, as a render worker is sent it: a user's model beside the spec
        # (``module:make``) is found on a node that has its folder
        sys.path[:0] = [p for p in paths if p not in sys.path]

        self.model = load_model(name)
        if model_framed:  # images are the model's input already (resolution = "model")
            self.model.preprocess = for_model_framing(self.model.preprocess, name)
        self.device = "cuda" if torch.cuda.is_available() else "cpu"
        self.model.module.to(self.device)

    def logits(self, images: np.ndarray) -> np.ndarray:
        import torch

        with torch.inference_mode():
            batch = self.model.preprocess(images).to(self.device)
            out = self.model.module(batch)
        if isinstance(out, (tuple, list)):
            out = out[0]
        return out.detach().float().cpu().numpy()


def remote_runner(name: str, model_framed: bool = False) -> Any:
    """A callable mapping images (N, H, W, 3) to logits through a Ray actor (Ray joined now, if
    the run has not yet: see :func:`~sweep3d.stages.render.ray_pool.ray_session`)."""
    from sweep3d.stages.render import join_ray

    ray = join_ray()

    gpus = 1 if ray.cluster_resources().get("GPU", 0) >= 1 else 0
    import sys

    actor = ray.remote(num_gpus=gpus, num_cpus=1)(InferenceActor).remote(name, model_framed, tuple(sys.path))
    return lambda images: ray.get(actor.logits.remote(images))
