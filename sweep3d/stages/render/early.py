"""The run's first render worker, started before the spec is read.

A cold ``sweep3d run`` reads its spec, checks its meshes and plans for most of a second before
it knows what to render; a render worker then spends another half second importing Blender
(benchmarks/RESULTS.md, issue 46). The command line therefore starts one interpreter at once,
importing Blender and the worker's modules while the run plans, and the render pool takes it as
its first worker (:func:`take`) when it renders with Cycles on the CPU: the settings it would
have been started with arrive with its work. A run that renders nothing, or otherwise, ends it
(:func:`drop`); so does this process's exit, as for every child.
"""

from __future__ import annotations

import os

from sweep3d.stages.render.child import Child

#: What the interpreter started ahead imports: Blender (through the module that cleans
#: ``sys.path`` first), then the Cycles worker's own modules.
PRELOAD = ("sweep3d.stages.render.cycles._bpy:import_bpy", "sweep3d.stages.render.worker",
           "sweep3d.stages.render.cycles.scene")

_waiting: Child | None = None


def start() -> None:
    """Start the interpreter now (once; a second call keeps the first), where this process may
    use more than one core: on one, Blender's import would only slow the planning down."""
    global _waiting
    if _waiting is None and _usable_cores() > 1:
        try:
            _waiting = Child(None, name="sweep3d-render", preload=PRELOAD)
        except OSError:  # the pool starts its worker as ever, and says what stops it in its own words
            _waiting = None


def take(engine: str, device: str) -> Child | None:
    """The interpreter started ahead, for a Cycles worker on the CPU (a GPU worker's environment
    is set before it starts: see ``device.prepare_gpu_environment``); None when there is none or
    it does not fit, which is then ended."""
    global _waiting
    child, _waiting = _waiting, None
    if child is None or (engine == "cycles" and device == "cpu" and child.is_alive()):
        return child
    child.end(grace=0)
    return None


def drop() -> None:
    """End the interpreter started ahead if nothing took it."""
    global _waiting
    child, _waiting = _waiting, None
    if child is not None:
        child.end(grace=0)


def _usable_cores() -> int:
    """The cores this process may run on (its affinity, where the system says; else every core)."""
    affinity = getattr(os, "sched_getaffinity", None)
    return len(affinity(0)) if affinity is not None else os.cpu_count() or 1
