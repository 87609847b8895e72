"""Cycles' NVIDIA GPUs, per back-end; imports nothing of sweep3d, so it also runs as a script.

Run as a script (``python gpus.py``), it imports bpy and prints, as one JSON line, how many GPUs
each back-end finds and the compute capabilities Blender ships no CUDA kernel for (there the
driver compiles Cycles' kernels from PTX at the first render: minutes, once): the parent's probe
(see :mod:`.device`), which never imports bpy itself. Cycles can crash while listing devices on
some drivers: in a child, that costs nothing but the answer. Render workers call :func:`enable` to render on a GPU; so does the
bpy-only GPU benchmark (``benchmarks/gpu.py``), which loads this file by its path.
"""

from __future__ import annotations

import ctypes
import json
from pathlib import Path
from typing import Any

#: Cycles' names of the GPU back-ends ``[render] device`` can name, in auto's order of preference.
BACKENDS = ("OPTIX", "CUDA")
CAPABILITY_MAJOR, CAPABILITY_MINOR = 75, 76  # CUdevice_attribute: CU_DEVICE_ATTRIBUTE_COMPUTE_CAPABILITY_*


def gpus(bpy: Any, backend: str) -> list[Any]:
    """The Cycles preference entries of ``backend``'s GPUs (Cycles lists the CPU beside them: left out)."""
    prefs = bpy.context.preferences.addons["cycles"].preferences
    prefs.refresh_devices()  # Blender does not list devices on start-up: unstable drivers crash there
    return [d for d in prefs.get_devices_for_type(backend) if d.type == backend]


def enable(bpy: Any, scene: Any, backend: str, gpu: int | None = None) -> bool:
    """Make ``scene`` render on ``backend``'s GPUs ("OPTIX", "CUDA"): all of them, or only number
    ``gpu`` (modulo their count); False, and nothing changed, where the back-end finds none."""
    found = gpus(bpy, backend)
    if not found:
        return False
    chosen = {found[gpu % len(found)].id} if gpu is not None else {d.id for d in found}
    prefs = bpy.context.preferences.addons["cycles"].preferences
    prefs.compute_device_type = backend
    for entry in prefs.devices:  # the CPU too: GPUs alone, as the render key says
        entry.use = entry.type == backend and entry.id in chosen
    scene.cycles.device = "GPU"
    return True


def capabilities() -> list[str]:
    """The compute capability of each NVIDIA GPU here ("9.0"), from the CUDA driver; empty without one."""
    try:
        cuda = ctypes.CDLL("libcuda.so.1")
    except OSError:
        return []
    count, device, major, minor = ctypes.c_int(), ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
    if cuda.cuInit(0) or cuda.cuDeviceGetCount(ctypes.byref(count)):
        return []
    found = []
    for i in range(count.value):
        if (cuda.cuDeviceGet(ctypes.byref(device), i)
                or cuda.cuDeviceGetAttribute(ctypes.byref(major), CAPABILITY_MAJOR, device)
                or cuda.cuDeviceGetAttribute(ctypes.byref(minor), CAPABILITY_MINOR, device)):
            continue
        found.append(f"{major.value}.{minor.value}")
    return found


def uncompiled(capabilities: list[str], kernels: Path) -> list[str]:
    """The capabilities among ``capabilities`` that Cycles has no CUDA binary for in ``kernels``
    (its ``lib`` folder): Cycles loads ``kernel_sm_<major><minor>.cubin`` for exactly its GPU's
    capability, else has the driver compile its PTX (CUDA and OptiX alike)."""
    shipped = {p.name.split(".")[0].removeprefix("kernel_sm_") for p in kernels.glob("kernel_sm_*.cubin*")}
    return sorted({c for c in capabilities if c.replace(".", "") not in shipped})


def main() -> None:
    import bpy

    found = {backend.lower(): len(gpus(bpy, backend)) for backend in BACKENDS}
    kernels = Path(bpy.utils.system_resource("SCRIPTS")) / "addons_core" / "cycles" / "lib"
    found["compiles"] = uncompiled(capabilities(), kernels) if any(found.values()) else []
    print(json.dumps(found))


if __name__ == "__main__":
    main()
