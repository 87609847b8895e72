"""Cycles' NVIDIA GPUs, per back-end; imports nothing of sweep3d, so it also runs as a script.

Run as a script (``python gpus.py``), it imports bpy and prints how many GPUs each back-end
finds, as one JSON line: the parent's probe (see :mod:`.device`), which never imports bpy
itself. Cycles can crash while listing devices on some drivers: in a child, that costs
nothing but the answer. Render workers import :func:`gpus` to enable the devices they render on.
"""

from __future__ import annotations

import json
from typing import Any

#: Cycles' names of the GPU back-ends ``[render] device`` can name, in auto's order of preference.
BACKENDS = ("OPTIX", "CUDA")


def gpus(bpy: Any, backend: str) -> list[Any]:
    """The Cycles preference entries of ``backend``'s GPUs (Cycles lists the CPU beside them: left out)."""
    prefs = bpy.context.preferences.addons["cycles"].preferences
    prefs.refresh_devices()  # Blender does not list devices on start-up: unstable drivers crash there
    return [d for d in prefs.get_devices_for_type(backend) if d.type == backend]


def main() -> None:
    import bpy

    print(json.dumps({backend.lower(): len(gpus(bpy, backend)) for backend in BACKENDS}))


if __name__ == "__main__":
    main()
