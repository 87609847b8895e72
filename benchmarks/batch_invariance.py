"""Does an image's output depend on the batch it is inferred in? EfficientNet-Lite0, torch and ONNX Runtime.

One image is put into batches of other sizes, at other positions, among other images, and its
logits are compared bit for bit with its logits alone (batch of one), per backend and thread count;
then each backend's logits of one batch at other thread counts. Prints one line per case.

    .venv/bin/python benchmarks/batch_invariance.py [--threads 1 2 4 8]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np

#: (batch size, the image's position, seed of the other images)
CASES = [(2, 0, 1), (2, 1, 1), (8, 3, 2), (8, 3, 3), (16, 15, 4), (31, 5, 7), (32, 0, 5), (32, 17, 6)]
SIDE = 96  # the stored image; preprocessing resizes it to 256 and crops 224


def _batch(target: np.ndarray, size: int, position: int, seed: int) -> np.ndarray:
    images = np.random.default_rng(seed).random((size, SIDE, SIDE, 3), dtype=np.float32)
    images[position] = target
    return images


def _compare(name: str, run: Callable[[np.ndarray], np.ndarray], preprocess, target: np.ndarray) -> None:
    """The image's logits in each case against its logits alone."""
    alone = run(preprocess(target[None]))[0]
    for size, position, seed in CASES:
        got = run(preprocess(_batch(target, size, position, seed)))[position]
        rel = float(np.abs(got - alone).max() / np.abs(alone).max())
        print(f"{name}: batch {size:2d}, position {position:2d}: "
              f"{'same bits' if np.array_equal(got, alone) else f'differs (max relative {rel:.1e})'}")
    fixed = [run(preprocess(_batch(target, 32, position, seed)))[position]
             for position, seed in [(0, 100), (5, 101), (31, 102), (16, 103)]]
    print(f"{name}: batch 32 at 4 positions among other images: "
          f"{'same bits' if all(np.array_equal(f, fixed[0]) for f in fixed) else 'differs'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    import torch

    from sweep3d.stages.infer.models import load_model
    from sweep3d.stages.infer.onnx_backend import OnnxRunner

    model = load_model("efficientnet-lite0")
    folder = Path(tempfile.mkdtemp())
    runner = OnnxRunner(model, folder, "lite0", args.threads[0], scratch=folder)
    target = np.random.default_rng(0).random((SIDE, SIDE, 3), dtype=np.float32)

    def torch_logits(batch):
        with torch.inference_mode():
            return model.module(batch).numpy()

    per_threads: dict[str, list[np.ndarray]] = {"torch": [], "onnxruntime": []}
    for threads in args.threads:
        torch.set_num_threads(threads)
        runner.use_threads(threads)
        _compare(f"torch, {threads} threads", torch_logits, model.preprocess, target)
        _compare(f"onnxruntime, {threads} threads", runner._run, model.preprocess, target)
        batch = model.preprocess(_batch(target, 8, 3, 2))
        per_threads["torch"].append(torch_logits(batch))
        per_threads["onnxruntime"].append(runner._run(batch))
    for name, outputs in per_threads.items():
        same = all(np.array_equal(o, outputs[0]) for o in outputs)
        print(f"{name}: one batch at {', '.join(map(str, args.threads))} threads: {'same bits' if same else 'differs'}")


if __name__ == "__main__":
    main()
