"""The render worker process: imports bpy once, keeps its scene, renders job after job.

It talks to the parent over one pipe with the messages of :mod:`.protocol`: it receives a list
of :class:`RenderJob` (one scene group) or None to stop, and sends :class:`Ready` (or
:class:`Fatal`) once, then :class:`Started` and a :class:`RenderReply` per job, and :class:`Idle`
after each list. After a job's reply, a worker that reached one of its :class:`WorkerLimits`
(its resident memory, its number of jobs) sends :class:`Retired` and exits: the pool gives the
rest of its list to a fresh worker.

A worker dies with its run: it is a :class:`~.child.Child`, which asks the kernel for SIGKILL
when its parent dies, and it never writes a blob once its parent has gone (a new run may hold the
store's lock by then).
"""

from __future__ import annotations

import os
import signal
import time
import traceback
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from sweep3d.core import UserError
from sweep3d.stages.render.backends import backend
from sweep3d.stages.render.child import orphaned
from sweep3d.stages.render.worker_protocol import (
    NO_LIMITS,
    Editing,
    Fatal,
    Idle,
    Ready,
    RenderInfo,
    RenderJob,
    RenderReply,
    RenderSettings,
    Retired,
    Started,
    WorkerLimits,
)

if TYPE_CHECKING:
    from sweep3d.stages.render.backend import RenderScene
    from sweep3d.stages.render.cycles.scene_edit import OnEdit


def worker_main(conn: Connection, settings: RenderSettings, scratch: str, limits: WorkerLimits = NO_LIMITS,
                gpu: int | None = None) -> None:
    """Entry point of a worker process (a :class:`~.child.Child`: it dies with its parent; ``gpu``:
    the one GPU it renders on; None: all)."""
    try:
        _serve(conn, settings, scratch, limits, gpu)
    except (BrokenPipeError, ConnectionResetError, EOFError):
        pass  # the parent has gone: nobody to report to, and nothing may be written


def _serve(conn: Connection, settings: RenderSettings, scratch: str, limits: WorkerLimits, gpu: int | None) -> None:
    """Build the scene, then render the lists of jobs the parent sends until it sends None, or
    until a limit is reached after a job."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when workers stop
    from sweep3d.stages.render.render_log import RenderLog

    try:
        # Blender prints progress straight to fd 1: into scratch, where a scene load's set-up is read
        log = RenderLog(Path(scratch) / f"blender-{os.getpid()}.log")
        scene = make_scene(settings, Path(scratch), log, gpu)
    except UserError as exc:  # a device it cannot use, bpy missing: the user's to fix (exit 2)
        conn.send(Fatal(str(exc), user=True))
        return
    except Exception as exc:  # noqa: BLE001  (reported to the parent, which fails the run)
        conn.send(Fatal(f"{type(exc).__name__}: {exc}"))
        return
    conn.send(Ready(os.getpid()))
    rendered = 0
    while True:
        jobs = conn.recv()
        if jobs is None:
            return
        for job in jobs:
            conn.send(Started(job.render_key))
            conn.send(render_job(scene, job, on_edit=_telling(conn, job.render_key)))
            rendered += 1
            reason = limits.reached(rendered, resident_mb())
            if reason is not None:
                conn.send(Retired(reason))
                return
        conn.send(Idle())


def make_scene(settings: RenderSettings, scratch: Path, log=None, gpu: int | None = None) -> RenderScene:
    """The worker's scene for ``settings.engine``, built by its backend (which imports its
    renderer only then: Cycles' workers never load Mitsuba, nor Mitsuba's Blender)."""
    return backend(settings.engine).scene(settings, scratch, log, gpu)


def _telling(conn: Connection, render_key: str) -> OnEdit:
    """What hears a job's edits: it tells the pool, which times each ``edit`` (see :class:`Editing`)."""
    return lambda control: conn.send(Editing(render_key, control))


def resident_mb(pid: int | str = "self") -> float | None:
    """The resident memory of process ``pid`` in MB (2^20 bytes), from ``/proc``; None where
    there is no ``/proc`` (no limit is checked then)."""
    try:
        pages = int(Path(f"/proc/{pid}/statm").read_text().split()[1])
    except (OSError, IndexError, ValueError):
        return None
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def posed_state(job: RenderJob):
    """The job's :class:`SceneState`: each rendered control's ``apply``, in order, on a fresh state.

    Raises:
        PluginError: a control's ``apply`` raised.
    """
    from sweep3d.core import blamed
    from sweep3d.stages.render.state import SceneState

    state = SceneState()
    for control, params in job.controls:
        with blamed(control, "apply()"):
            control.apply(state, params)
    return state


def render_job(scene: RenderScene, job: RenderJob, keep_pixels: bool = False, on_edit: OnEdit | None = None) -> RenderReply:
    """Render one job in ``scene`` (its engine's: see ``backend.RenderScene``); shared by process workers and Ray actors
    (``on_edit``: see :func:`~.scene_edit.render_edited`).

    Returns:
        The reply for the parent. With ``keep_pixels`` it carries the PNG bytes instead of
        writing them to ``job.blob`` (so a remote worker needs no shared file system: the driver
        writes the store). A job whose ``blob`` is None is rendered only for its UV pass: no
        pixels are written or returned. With the UV pass on, ``info.parts`` holds what it saw;
        with truth passes on, ``info.truth`` their numbers and ``reply.truth`` their blobs.
        ``info.load_seconds`` is the part of ``info.seconds`` its scene switch took (see
        ``BlenderScene.load_seconds``; 0 when the scene was already shown). ``on_edit`` is told
        of each user's control's ``edit()`` (see :func:`.scene_edit.render_edited`).
        A :class:`UserError` (the spec's input, a full disk) gives kind "user"; any other
        failure "internal", so one bad job does not kill the sweep.
    """
    from sweep3d.cache import atomic_write
    from sweep3d.core import PluginError, encode_png, png_size
    from sweep3d.stages.render.cycles.scene_edit import EditedRenderError, render_edited

    key = job.render_key
    started = time.perf_counter()
    try:
        scene.prepare(job.mesh, job.environment, job.look)
        scene.pose_scene(posed_state(job))
        edits = [(control, params) for control, params in job.controls if control.edits_scene]
        if edits:
            rgb, rebuilt = render_edited(scene, edits, job.object_name, job.environment_name, on_edit)
            finite, png = bool(np.isfinite(rgb).all()), encode_png(rgb)
        else:  # Blender's 8-bit file: finite by construction
            finite, png, rebuilt = True, scene.render_png(), ()
        width, height = png_size(png)
        if job.blob is None:  # the render is cached, the job is here for its UV pass
            png = None
        else:
            if not keep_pixels:
                if orphaned():  # its run was killed: the store is no longer ours to write
                    os._exit(1)
                atomic_write(Path(job.blob), png)
        truth = getattr(scene, "truth_pass", None)
        info = RenderInfo(seconds=time.perf_counter() - started, valid=finite, width=width,
                          height=height, parts=scene.parts, load_seconds=scene.load_seconds,
                          truth=truth.truth if truth is not None else None, rebuilt=rebuilt)
        return RenderReply(key, True, info, png=png if keep_pixels else None,
                           truth=dict(truth.blobs) if truth is not None else None)
    except PluginError as exc:  # a user's control raised: its one line, and the traceback for --debug
        return RenderReply(key, False, error=str(exc), kind="plugin", details=exc.details)
    except UserError as exc:  # the spec's input (a mesh, an HDRI) or a full disk: exit 2
        return RenderReply(key, False, error=str(exc), kind="user")
    except EditedRenderError as exc:  # its line names the control whose edit() left the scene
        return RenderReply(key, False, error=f"{exc}\n{traceback.format_exc(limit=3)}")
    except Exception as exc:  # noqa: BLE001  (one bad job must not kill the sweep)
        return RenderReply(key, False, error=f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}")
    finally:
        scene.rebuild_if_stale()  # after the reply took this render's passes and timings
