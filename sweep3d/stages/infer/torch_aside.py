"""Torch's logits for near ties, from a child process at the lowest priority.

Where ONNX Runtime stands in for a built-in classifier, a handful of images a run (4 of the cold
quickstart's 960) are near ties that torch must rank (``onnx_backend``). Importing torch and
loading the model there cost the run's own process 1.1 core-seconds, under its global interpreter
lock: the render pool's thread waited to send Blender its next job, and a cold quickstart took
0.7 s longer than with no near tie at all (benchmarks/RESULTS.md, issue 46). A large pass
therefore starts this process when its model is checked: it imports torch at the lowest priority,
on the cycles the renders leave idle, and answers the near ties as they come.

Its answers are the run's own process's bits: the same module, one torch thread, each image alone
and in the memory layout the run's process would have given torch (channels last, as
``Preprocess.of_pixels`` lays it out; tests/stages/infer/test_infer.py). Anything wrong with it
(it died, it cannot load the model, or it has not answered within :data:`ANSWER_WITHIN` seconds:
a machine busy with other work leaves the lowest priority little) sends the near ties back to
the run's process.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from sweep3d.stages.render import Child

#: A pass with fewer images to infer loads torch in its own process at the first near tie, if
#: any: a near tie is one image in a few hundred, and the process costs a core-second.
MIN_IMAGES = 256
LOWEST = 19  # the niceness: it runs on what the renders leave idle
ANSWER_WITHIN = 30.0  # seconds a near tie waits for it (its import included) before this process answers


class TorchAside:
    """A child process that loads the built-in model ``name`` in torch and gives the logits of
    the images it is sent, each alone. Start it from the thread that outlives the pass (the child
    dies with the thread that started it)."""

    def __init__(self, name: str) -> None:
        self.child = Child(serve, (name,), name="sweep3d-torch")
        try:
            os.setpriority(os.PRIO_PROCESS, self.child.pid, LOWEST)
        except OSError:
            pass  # it runs at the run's priority: slower to share, the same answers

    def logits(self, images: np.ndarray, channels_last: bool) -> np.ndarray | None:
        """float32 (N, C) logits of ``images`` (N, 3, H, W) as torch gives each alone; None when
        the process cannot answer (the caller computes them itself)."""
        if not self.child.is_alive():
            return None
        layout = images.transpose(0, 2, 3, 1) if channels_last else images
        try:
            self.child.conn.send((np.ascontiguousarray(layout, dtype=np.float32), channels_last))
            if not self.child.conn.poll(ANSWER_WITHIN):
                return None  # the caller ends it: no late answer is left in the pipe
            answer = self.child.conn.recv()
        except (EOFError, OSError):
            return None
        return answer if isinstance(answer, np.ndarray) else None

    def close(self) -> None:
        """End it at once: it keeps nothing, and torch's exit takes a third of a second."""
        self.child.kill()
        self.child.join(5)


def serve(conn: Any, name: str) -> None:
    """In the child: load the model, then answer each batch of images until told to stop."""
    import torch

    from sweep3d.stages.infer.models import load_model, logits_each_alone

    torch.set_num_threads(1)  # as the run's process does for its near ties
    try:
        module = load_model(name).module
    except Exception:  # noqa: BLE001  (the parent computes them itself, and says what is wrong)
        module = None
    while True:
        message = conn.recv()
        if message is None:
            return
        array, channels_last = message
        if module is None:
            conn.send(None)
            continue
        images = torch.from_numpy(array)
        conn.send(logits_each_alone(module, images.permute(0, 3, 1, 2) if channels_last else images))
