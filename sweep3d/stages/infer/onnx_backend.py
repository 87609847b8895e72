"""ONNX Runtime for classifiers: about 4× faster than eager torch per image on this project's CPU.

It serves in two ways (``stages.infer.prediction_keys.choose_backend`` picks):

- ``[model] backend = "onnx"``: ONNX Runtime's own answers, for any model torch can export; the
  backend is part of the prediction keys, so they are stored apart from torch's.
- ``backend`` left out, for the built-in model and evaluator: ONNX Runtime *stands in* for torch
  and its ranks are torch's (its probabilities differ in the last digits, so eager torch for the
  same model is keyed apart: ``prediction_keys.key_backend``). Two things make that hold. Before use, the
  export is checked against torch on a fixed batch (top-1 equal, logits within ``TOLERANCE``).
  Then, per image, where ranking by its logits could come out differently within the error the
  check measured (times ``SAFETY``; two of the top k + 1 logits closer than twice it, or one not
  finite), that image is run through torch: the ranks the evaluator records (top-1, top-k and
  their order) are torch's.

The torch module is exported once per model digest into the store (``models/<digest>.onnx``), and
its check's outcome is kept beside it under the graph's bytes, the torch and onnxruntime releases
and the CPU (``onnx_kept``): a new release or another machine is checked again. Both are also kept
in the user's cache folder, so that a fresh store neither exports nor checks again. With both
kept, ONNX Runtime answers without torch being imported: the module is loaded at the first near
tie (a second and a half on two cores, benchmarks/RESULTS.md, issue 37), or never; a large pass
has a process of its own load it and answer its near ties (:mod:`.torch_aside`).
"""

from __future__ import annotations

import io
import os
import uuid
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np

from sweep3d.cache import atomic_write
from sweep3d.core import UserError
from sweep3d.stages.infer import onnx_kept
from sweep3d.stages.infer.models import Classifier, logits_each_alone, on_device

TOLERANCE = 1e-3  # max |logit difference| accepted between torch and ONNX Runtime
CHECK_BATCH = 4
#: An image's logits are taken to be within this many times the check's largest difference of
#: torch's (EfficientNet-Lite0 on real renders: 1.7e-5 at most, 7e-6 typical, on the check's
#: noise 1e-5), and never nearer than ``FLOOR``: a near tie is two logits closer than twice that.
#: Against the fixed ``TOLERANCE`` it sends a sixth as many images through torch, one at a time.
SAFETY = 16.0
FLOOR = 1e-5
#: Images per ONNX Runtime call on the CPU, whatever the batch: a convolution network's
#: activations for 32 images at 224² (tens of MB) do not stay in a CPU's caches, for 4 they
#: mostly do. EfficientNet-Lite0 on this project's 2-core machine: 4.8 ms an image on one thread
#: against 6.5 ms at 32 (2.6 against 3.4 ms on two; benchmarks/RESULTS.md). A row is the same
#: bits at any batch size on the CPU, so nothing stored changes.
CHUNK = 4


class OnnxRunner:
    """Runs a classifier's module through ONNX Runtime; call it with the preprocessed batch.

    Args:
        model: the torch model, or what loads it: called only when torch is needed (an export,
            its check, a near tie).
        folder: where the exported model is kept (the store's ``models/``).
        digest: the model's digest (its weights and preprocessing), naming the file.
        threads: ONNX Runtime's intra-op threads; idle ones sleep instead of spinning, so that
            renders running beside inference keep the cores.
        exact_ranks: stand in for torch: images whose top ``exact_ranks`` + 1 logits are within
            twice :attr:`error` of a tie go through torch (None: ONNX Runtime's own answers).
        scratch: where the export is written before it is moved into ``folder`` (the store's
            ``tmp/``, which ``cache gc`` empties: a run killed mid-export leaves nothing else).

    Raises:
        UserError: when onnxruntime is missing, the export fails, or it disagrees with torch.
    """

    def __init__(self, model: Classifier | Callable[[], Classifier], folder: Path, digest: str, threads: int,
                 exact_ranks: int | None = None, scratch: Path | None = None) -> None:
        try:
            import onnxruntime  # noqa: F401  (the sessions import it again)
        except ImportError:
            raise UserError("model.backend = 'onnx' needs onnxruntime: pip install onnxruntime") from None
        self._load = model if callable(model) else (lambda: model)
        self._classifier: Classifier | None = None
        self._aside: Any = None  # a TorchAside answering the near ties, when one was started
        self.exact_ranks = exact_ranks
        self.by_torch = 0  # images run through torch instead (near ties)
        self.error = TOLERANCE  # how far a logit may be from torch's: set by the check below
        self.path = folder / f"{digest}.onnx"
        if not self.path.exists() and not onnx_kept.fetch(self.path):
            self._export(scratch or folder)
        self.threads = threads
        self.session = _session(self.path, threads)
        # On the CPU, a row's logits are the same bits at any batch size, position, company and
        # thread count (checked on EfficientNet-Lite0); on CUDA that is not known.
        self.batch_invariant = self.session.get_providers() == ["CPUExecutionProvider"]
        self.input = self.session.get_inputs()[0].name
        checked = onnx_kept.checked_error(self.path, self.session.get_providers())
        self.error = checked if checked is not None else self._check()

    @property
    def classifier(self) -> Classifier:
        """The torch model (loaded, and torch imported, on first use: the export, its check, a near tie)."""
        if self._classifier is None:
            import torch

            self._classifier = self._load()
            torch.set_num_threads(1)  # beside ONNX Runtime's threads: idle torch threads would spin on its cores
        return self._classifier

    def use_threads(self, threads: int) -> None:
        """Run with ``threads`` threads from now on (a new session of the same checked export)."""
        if threads != self.threads:
            self.session, self.threads = _session(self.path, threads), threads

    def __call__(self, batch: Any) -> np.ndarray:
        """Logits, float32 (N, C), of a preprocessed batch (torch tensor or array (N, 3, H, W))."""
        logits = self._run(batch)
        if self.exact_ranks is not None:
            rows = near_ties(logits, self.exact_ranks, 2 * self.error)
            if rows.size:
                logits[rows] = self._torch(batch, rows)
                self.by_torch += int(rows.size)
        return logits

    def unranked(self, batch: Any) -> np.ndarray:
        """ONNX Runtime's logits alone, near ties left as they are: for a check of the model's
        outputs (their shape, its classes), which needs no torch."""
        return self._run(batch)

    def _run(self, batch: Any) -> np.ndarray:
        """ONNX Runtime's logits of a preprocessed batch: on the CPU, :data:`CHUNK` images at a
        time (the same bits as the whole batch at once, and faster)."""
        array = batch.numpy() if hasattr(batch, "numpy") else np.asarray(batch)
        step = CHUNK if self.batch_invariant else max(len(array), 1)
        chunks = [array[i:i + step] for i in range(0, max(len(array), 1), step)]  # an empty batch: one empty chunk
        return np.concatenate([self.session.run(None, {self.input: np.ascontiguousarray(chunk, dtype=np.float32)})[0]
                               for chunk in chunks])

    def answer_ties_aside(self, name: str) -> None:
        """Have a child process load the built-in model ``name`` in torch now, at the lowest
        priority, and answer the near ties (:mod:`.torch_aside`): call it from the thread that
        outlives the pass."""
        from sweep3d.stages.infer.torch_aside import TorchAside

        if self.exact_ranks is not None and self._aside is None and self._classifier is None:
            try:
                self._aside = TorchAside(name)
            except OSError:  # no process to spare: the near ties are answered here
                self._aside = None

    def close(self) -> None:
        """End the process answering near ties, if one was started."""
        aside, self._aside = self._aside, None
        if aside is not None:
            aside.close()

    def _torch(self, batch: Any, rows: np.ndarray) -> np.ndarray:
        """Torch's logits for ``rows`` of the batch, each row alone: torch's bits change with the
        batch size, so run together a near tie's logits would depend on how many others its batch had."""
        layout = _layout(batch) if self._aside is not None else None
        if layout is not None:
            answer = self._aside.logits(batch[rows], channels_last=layout == "channels last")  # type: ignore[union-attr]
            if answer is not None and answer.shape[0] == rows.size:
                return answer
            self.close()  # it could not answer: this process does from now on
        import torch

        return logits_each_alone(self.classifier.module, torch.as_tensor(batch), rows.tolist())

    def _export(self, scratch: Path) -> None:
        import torch

        classifier = self.classifier

        sample = on_device(classifier.module, classifier.preprocess(np.full((1, 256, 256, 3), 0.5, np.float32)))
        buffer = io.BytesIO()
        with warnings.catch_warnings():  # tracer warnings; nothing else is printed
            warnings.simplefilter("ignore")
            try:
                torch.onnx.export(classifier.module, sample, buffer, input_names=["images"], output_names=["logits"],
                                  dynamic_axes={"images": {0: "batch"}, "logits": {0: "batch"}},
                                  opset_version=17, dynamo=False)
            except Exception as exc:  # noqa: BLE001  (a model torch cannot export is a user-facing limit)
                raise UserError(f"cannot export the model to ONNX ({type(exc).__name__}: {exc}); "
                                "use model.backend = 'torch'") from None
        staged = scratch / f"{self.path.name}.{uuid.uuid4().hex}"
        atomic_write(staged, buffer.getvalue())
        self.path.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staged, self.path)
        onnx_kept.keep(self.path)

    def _check(self) -> float:
        """The largest logit difference from torch on a fixed batch, times ``SAFETY`` (see
        :data:`SAFETY`), kept for the next runner; an export whose top-1 or logits differ from
        torch's is refused (and deleted)."""
        import torch

        classifier = self.classifier
        rng = np.random.default_rng(0)
        images = np.concatenate([rng.random((CHECK_BATCH - 1, 240, 240, 3), dtype=np.float32),
                                 np.full((1, 240, 240, 3), 0.5, np.float32)])
        batch = classifier.preprocess(images)
        with torch.inference_mode():
            expected = classifier.module(on_device(classifier.module, batch)).float().cpu().numpy()
        got = self._run(batch)
        diff = float(np.abs(expected - got).max())
        if not diff <= TOLERANCE or not np.array_equal(expected.argmax(1), got.argmax(1)):
            self.path.unlink(missing_ok=True)
            raise UserError(f"the ONNX export disagrees with torch (max logit difference {diff:.2g}); "
                            "use model.backend = 'torch'")
        error = min(TOLERANCE, max(SAFETY * diff, FLOOR))
        onnx_kept.keep_check(self.path, self.session.get_providers(), error)
        return error


def _session(path: Path, threads: int) -> Any:
    """An ONNX Runtime session on a CUDA GPU when this onnxruntime has one, else on the CPU; its
    idle CPU threads sleep instead of spinning, so that renders beside inference keep the cores."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(str(path), options, providers=providers(ort.get_available_providers()))


def providers(available: list[str]) -> list[str]:
    """The execution providers a session asks for: CUDA first where ``available`` has it (ONNX
    Runtime falls back to the CPU for what CUDA cannot run), else the CPU alone."""
    cuda = ["CUDAExecutionProvider"] if "CUDAExecutionProvider" in available else []
    return [*cuda, "CPUExecutionProvider"]


def _layout(batch: Any) -> str | None:
    """How a preprocessed numpy batch (N, 3, H, W) lies in memory, as torch would see it: "channels
    last" (``Preprocess.of_pixels``), "contiguous", else None (a torch tensor: torch is loaded)."""
    if not isinstance(batch, np.ndarray) or batch.ndim != 4:
        return None
    if batch.transpose(0, 2, 3, 1).flags.c_contiguous:
        return "channels last"
    return "contiguous" if batch.flags.c_contiguous else None


def near_ties(logits: np.ndarray, ranks: int, margin: float = 2 * TOLERANCE) -> np.ndarray:
    """Rows whose ranking of the top ``ranks`` classes could change if each logit moved by up to
    ``margin`` / 2: two of their top ``ranks`` + 1 logits are within ``margin``, or one is not finite.

    If every logit is within ``margin`` / 2 of torch's, the other rows rank their top ``ranks``
    classes exactly as torch does (the classes, and their order).
    """
    if logits.size == 0:
        return np.zeros(0, dtype=np.int64)
    top = -np.sort(-logits, axis=1)[:, : min(ranks + 1, logits.shape[1])]
    close = (np.diff(-top, axis=1) < margin).any(axis=1)  # gaps between neighbours, descending
    return np.flatnonzero(close | ~np.isfinite(logits).all(axis=1))
