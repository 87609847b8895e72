"""Which Cycles device renders: the CPU, or NVIDIA GPUs through OptiX or CUDA.

``[render] device = "auto"`` is resolved in the parent before the run is planned, so that its
render keys are known up front and the same wherever they are computed: the device is in a
render key only for a GPU (GPU Cycles does not give CPU's pixels), so auto on a machine without
one keys and renders exactly as ``"cpu"``. The parent never imports bpy: a probe, a child process
running :mod:`.gpus`, asks Cycles which GPUs each back-end finds, once per process, and only
where an NVIDIA driver is present (elsewhere auto is the CPU at no cost).

A device named explicitly is keyed as named; the workers enable it on start-up and report one
they cannot use (:func:`use_device`) as a user error, before any job is sent.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from sweep3d.core import UserError
from sweep3d.spec import RenderSpec
from sweep3d.stages.render.backends import backend
from sweep3d.stages.render.cycles import gpus as gpus_module

PROBE_TIMEOUT = 120.0  # seconds the probe may take to import bpy and list Cycles' devices
#: What shows an NVIDIA driver: its /proc entry and device node (Linux), or WSL's GPU node.
DRIVER_PATHS = ("/proc/driver/nvidia/version", "/dev/nvidiactl", "/dev/dxg")
NAMES = {"optix": "OptiX", "cuda": "CUDA"}
#: Where the driver keeps the kernels it compiled, and the size a GPU run raises its cache to
#: (the most it allows) unless the user set one: its default (256 MiB or 1 GiB, by driver) is
#: shared with every other program's kernels, and a recompile costs minutes.
CUDA_CACHE = "CUDA_CACHE_PATH, default ~/.nv/ComputeCache"
CUDA_CACHE_SIZE = ("CUDA_CACHE_MAXSIZE", str(4 * 2**30))
#: Seconds a GPU worker's first job may take beyond ``render.timeout``: the driver may compile
#: Cycles' kernels there (more than 5 minutes measured on an H200), OptiX its pipeline.
KERNEL_GRACE = 3600.0


def prepare_gpu_environment(device: str) -> None:
    """Before GPU workers start: let the driver's kernel cache hold Cycles' kernels (workers
    inherit the environment), unless the user sized it."""
    if device != "cpu":
        os.environ.setdefault(*CUDA_CACHE_SIZE)


def resolve_device(requested: str) -> str:
    """The device renders are made on: ``requested``, with "auto" as the best GPU back-end that
    finds a GPU here (OptiX, then CUDA), else "cpu"."""
    if requested != "auto":
        return requested
    return next((b.lower() for b in gpus_module.BACKENDS if gpu_count(b.lower())), "cpu")


def gpu_count(device: str) -> int:
    """How many GPUs Cycles finds here through ``device``'s back-end (0 for "cpu")."""
    return int(probe().get(device, 0))


@functools.cache
def probe() -> dict[str, Any]:
    """GPUs per back-end ("optix", "cuda": counts), and under "compiles" the compute capabilities
    Blender ships no CUDA kernel for, as a child importing bpy sees them; empty without an
    NVIDIA driver, or when the child fails (no bpy, a crashing driver): then auto is the CPU."""
    if not any(Path(p).exists() for p in DRIVER_PATHS):
        return {}
    try:
        done = subprocess.run([sys.executable, gpus_module.__file__], capture_output=True, text=True,
                              timeout=PROBE_TIMEOUT, check=True)
        found = json.loads(done.stdout.strip().splitlines()[-1])
    except (OSError, subprocess.SubprocessError, ValueError, IndexError):
        return {}
    if not isinstance(found, dict):
        return {}
    counts = {k: int(v) for k, v in found.items() if k in NAMES}
    return {**counts, "compiles": [str(c) for c in found.get("compiles", [])]}


def worker_count(spec: RenderSpec, device: str) -> int:
    """Render workers: the spec's ``workers``, or one per GPU when a GPU renders and it is not set."""
    if device == "cpu" or "workers" in spec.model_fields_set:
        return spec.workers
    return max(gpu_count(device), 1)


def device_note(spec: RenderSpec, device: str) -> str | None:
    """The line a run that renders says first about its device: that auto found no GPU, or that
    the driver must first compile Cycles' kernels for this GPU (None: nothing to say, as for
    another engine: Mitsuba renders on the CPU whatever ``device`` says)."""
    if set(backend(spec.engine).devices) == {"cpu"}:
        return None
    if spec.device == "auto" and device == "cpu":
        return ('render.device = "auto" found no NVIDIA GPU that Cycles can use (OptiX or CUDA): rendering on '
                'the CPU')
    compiles = probe().get("compiles", []) if device != "cpu" else []
    if not compiles:
        return None
    return (f'render.device = "{device}": Blender ships no CUDA kernel for this GPU (compute capability '
            f'{", ".join(compiles)}), so the NVIDIA driver compiles Cycles\' kernels at the first render: more '
            f'than 8 minutes on an H200, then kept in its cache ({CUDA_CACHE}) for later runs; to compile it once '
            f'ahead, on any machine: bash scripts/cycles_kernel.sh {compiles[0].replace(".", "")}')


def missing_gpu_warning(requested: str, to_render: int) -> str | None:
    """What ``sweep3d plan`` says of a GPU ``[render] device`` named outright that this machine
    lacks (a run would find out only as its first worker starts), and what a run here would do;
    None for "cpu", "auto", or a back-end that finds a GPU."""
    if requested not in NAMES or gpu_count(requested) > 0:
        return None
    run = (f"sweep3d run here would stop with an error before its {to_render} renders" if to_render
           else "every render is cached, so sweep3d run here renders nothing, but a new one would fail")
    return (f'render.device = "{requested}": no {NAMES[requested]} GPU here (Cycles finds none); {run}; run it on a '
            'machine with one, or set device = "auto" (the best GPU back-end that works, else the CPU) or "cpu"')


def use_device(bpy: Any, scene: Any, device: str, gpu: int | None = None) -> None:
    """Make ``scene`` render on ``device`` (in a worker): the CPU, or the GPUs of its back-end, all
    of them or only number ``gpu`` (modulo their count: one worker per GPU).

    Raises:
        UserError: the back-end finds no GPU here: one line naming ``render.device`` and the fix.
    """
    if device == "cpu":
        scene.cycles.device = "CPU"
        return
    if not gpus_module.enable(bpy, scene, device.upper(), gpu):
        raise UserError(f'render.device = "{device}": Cycles finds no {NAMES[device]} GPU on this machine (is the '
                        'NVIDIA driver installed and the GPU visible?); set device = "auto" (the best GPU back-end '
                        'that works, else the CPU) or "cpu"')
