"""An optional ONNX Runtime backend for classifiers (4–6× faster than eager torch on CPU).

The torch module is exported once per model digest into the store (``models/<digest>.onnx``)
and checked against torch on a fixed batch before first use: if the two disagree (top-1 class
or logits beyond a tolerance) the export is refused, so a faster backend never silently
changes answers.
"""

from __future__ import annotations

import io
import warnings
from contextlib import redirect_stderr
from pathlib import Path

import numpy as np

from sweep3d.cache.store import atomic_write
from sweep3d.errors import UserError
from sweep3d.stages.infer.models import Classifier

TOLERANCE = 1e-3  # max |logit difference| accepted between torch and ONNX Runtime
CHECK_BATCH = 4


class OnnxRunner:
    """Runs a classifier's module through ONNX Runtime; call with the preprocessed batch."""

    def __init__(self, classifier: Classifier, folder: Path, digest: str, threads: int) -> None:
        try:
            import onnxruntime as ort
        except ImportError:
            raise UserError("model.backend = 'onnx' needs onnxruntime: pip install 'sweep3d[onnx]'") from None
        self.path = folder / f"{digest}.onnx"
        if not self.path.exists():
            self._export(classifier)
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        self.session = ort.InferenceSession(str(self.path), options, providers=["CPUExecutionProvider"])
        self.input = self.session.get_inputs()[0].name
        if not (folder / f"{digest}.checked").exists():
            self._check(classifier)
            atomic_write(folder / f"{digest}.checked", b"ok")

    def __call__(self, batch) -> np.ndarray:
        """Logits, float32 (N, C), of a preprocessed batch (torch tensor or array (N, 3, H, W))."""
        array = batch.numpy() if hasattr(batch, "numpy") else np.asarray(batch)
        return self.session.run(None, {self.input: np.ascontiguousarray(array, dtype=np.float32)})[0]

    def _export(self, classifier: Classifier) -> None:
        import torch

        sample = classifier.preprocess(np.full((1, 256, 256, 3), 0.5, np.float32))
        buffer = io.BytesIO()
        with warnings.catch_warnings(), redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore")
            try:
                torch.onnx.export(classifier.module, sample, buffer, input_names=["images"], output_names=["logits"],
                                  dynamic_axes={"images": {0: "batch"}, "logits": {0: "batch"}},
                                  opset_version=17, dynamo=False)
            except Exception as exc:  # noqa: BLE001  (a model torch cannot export is a user-facing limit)
                raise UserError(f"cannot export the model to ONNX ({type(exc).__name__}: {exc}); "
                                "use model.backend = 'torch'") from None
        atomic_write(self.path, buffer.getvalue())

    def _check(self, classifier: Classifier) -> None:
        import torch

        rng = np.random.default_rng(0)
        batch = classifier.preprocess(rng.random((CHECK_BATCH, 240, 240, 3), dtype=np.float32))
        with torch.inference_mode():
            expected = classifier.module(batch).float().numpy()
        got = self(batch)
        diff = float(np.abs(expected - got).max())
        if diff > TOLERANCE or not np.array_equal(expected.argmax(1), got.argmax(1)):
            self.path.unlink(missing_ok=True)
            raise UserError(f"the ONNX export disagrees with torch (max logit difference {diff:.2g}); "
                            "use model.backend = 'torch'")
