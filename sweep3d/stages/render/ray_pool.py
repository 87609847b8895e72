"""Render on a Ray cluster: the same jobs and results as :class:`RenderPool`, with Ray actors
as the persistent workers.

Each actor imports bpy once and keeps its scene, as a local worker does. Assets travel through
Ray's object store (a mesh with its materials and textures, a custom HDRI), and pixels come
back as PNG bytes, so workers need no shared file system: the driver writes every blob and
every row, and stays the store's single writer. A group whose actor dies is rendered again by
a new actor; results are yielded only for finished groups, so nothing is counted twice.
"""

from __future__ import annotations

import importlib.util
import io
import os
import sys
import tarfile
import tempfile
from collections import Counter, deque
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterator

from sweep3d.assets import bpy_root, mesh_files
from sweep3d.cache import atomic_write, digest
from sweep3d.core import UserError, is_user_plugin
from sweep3d.stages.render.worker_protocol import RenderJob, RenderReply, RenderSettings

MAX_GROUP_RETRIES = 2


#: Ray's switch for token authentication, and where it finds a token (its own names).
AUTH_MODE = "RAY_AUTH_MODE"
TOKEN_SOURCES = ("RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH")


def require_ray() -> None:
    """Refuse ``--executor ray`` in one line where Ray is not installed (without importing it:
    a run with nothing to compute never does)."""
    if importlib.util.find_spec("ray") is None:
        raise UserError("--executor ray needs Ray: pip install 'sweep3d[ray]'")


def _ray():
    require_ray()
    import ray

    return ray


@dataclass
class _Session:
    """One run's Ray: the cluster to join, and whether joining started Ray (then the run stops it)."""

    address: str | None
    started: bool = False


_session: _Session | None = None


@contextmanager
def ray_session(address: str | None) -> Iterator[None]:
    """Ray for one run, joined only when something renders or infers on it: a run whose every
    result is cached never starts it (seconds). What it started is shut down when the run ends."""
    global _session
    require_ray()
    outer, _session = _session, _Session(address)
    try:
        yield
    finally:
        session, _session = _session, outer
        if session is not None and session.started:
            import ray

            ray.shutdown()


def join() -> Any:
    """``ray``, joined to the current run's cluster (now, if this is the first use)."""
    connect(_session.address if _session is not None else None)
    return _ray()


def connect(address: str | None) -> bool:
    """Join the cluster at ``address``, or start a local one bound to 127.0.0.1; True if this
    call started Ray and the caller must shut it down (False within a :func:`ray_session`, which
    shuts down what it started).

    Raises:
        UserError: one line: the cluster asks for an authentication token this process does not
            send (Ray 2.52+ with token authentication), or there is no cluster at ``address``.
    """
    if address:
        _use_token_if_there_is_one()
    ray = _ray()
    if ray.is_initialized():
        return False
    if address:
        _join(ray, address)
    else:
        ray.init(_node_ip_address="127.0.0.1", include_dashboard=False, log_to_driver=False)
    if _session is not None:
        _session.started = True
        return False
    return True


def _use_token_if_there_is_one() -> None:
    """Send this user's Ray token to an explicit address, as Ray itself does only for a cluster
    it finds on its own (``ray start`` turns token authentication on when a token exists, and a
    client given an address sends none unless ``RAY_AUTH_MODE=token``). Ray reads the mode once,
    at import: this runs before it is imported."""
    if os.environ.get(AUTH_MODE) is not None or "ray" in sys.modules:
        return
    if any(os.environ.get(name) for name in TOKEN_SOURCES) or (Path.home() / ".ray" / "auth_token").is_file():
        os.environ[AUTH_MODE] = "token"


def _join(ray: Any, address: str) -> None:
    """``ray.init(address)``, its C++ client's retries (one stderr line a second for 20 s when the
    cluster refuses the token) kept out of the terminal unless the join succeeds."""
    with tempfile.TemporaryFile() as held:
        saved = os.dup(2)
        sys.stderr.flush()
        os.dup2(held.fileno(), 2)
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
            failure = None
        except Exception as exc:  # noqa: BLE001  (Ray's ConnectionError, RuntimeError, AuthenticationError)
            failure = exc
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        held.seek(0)
        said = held.read().decode("utf-8", "replace")
    if failure is None:
        sys.stderr.write(said)
        return
    auth = type(failure).__name__ == "AuthenticationError" or "InvalidAuthToken" in said + str(failure)
    if auth:
        sent = os.environ.get(AUTH_MODE, "").lower() == "token"
        raise UserError(
            f"--address {address}: the Ray cluster asks for an authentication token and this process "
            f"{'sent one it does not accept' if sent else 'sends none'}: set RAY_AUTH_TOKEN to the cluster's "
            "token (`ray get-auth-token` on its head node) and RAY_AUTH_MODE=token, or start the cluster with "
            "RAY_AUTH_MODE=disabled") from None
    raise UserError(f"--address {address}: cannot join a Ray cluster there ({str(failure).splitlines()[0]}); start "
                    "one with `ray start --head`, or leave --address out for a local one") from None


class RenderActor:
    """A Ray actor holding one Blender scene (created remotely through ``ray.remote``)."""

    def __init__(self, settings: RenderSettings) -> None:
        import tempfile

        from sweep3d.stages.render.render_log import RenderLog
        from sweep3d.stages.render.worker import make_scene

        self.scratch = Path(tempfile.mkdtemp(prefix="sweep3d-ray-"))
        log = RenderLog(self.scratch / "blender.log")  # Blender prints progress straight to fd 1
        self.scene = make_scene(settings, self.scratch, log)
        self.unpacked: dict[str, str] = {}

    def pid(self) -> int:
        import os

        return os.getpid()

    def render_group(self, jobs: list[RenderJob], packs: dict[str, bytes]) -> list[RenderReply]:
        """Render a group with its shipped assets unpacked here; replies carry the PNG bytes."""
        from sweep3d.stages.render.worker import render_job

        out = []
        for job in jobs:
            env = job.environment
            if env.hdri:
                env = replace(env, hdri=self._local(env.hdri, packs))
            job = replace(job, mesh=self._local(job.mesh, packs), environment=env)
            out.append(render_job(self.scene, job, keep_pixels=True))
        return out

    def _local(self, ref: str, packs: dict[str, bytes]) -> str:
        """The local path of a shipped asset ("pack:<digest>/<name>"), unpacked once per actor."""
        if not ref.startswith("pack:"):
            return ref
        pack, _, name = ref.removeprefix("pack:").partition("/")
        if pack not in self.unpacked:
            folder = self.scratch / "assets" / pack
            with tarfile.open(fileobj=io.BytesIO(packs[pack])) as tar:
                tar.extractall(folder, filter="data")
            self.unpacked[pack] = str(folder)
        return str(Path(self.unpacked[pack]) / name)


def _ship_code(job: RenderJob) -> None:
    """Send the code of the job's user controls with it (by value), so an actor on any node runs
    them without the module file: Ray's pickler then copies their module instead of naming it."""
    from ray import cloudpickle

    for control, _ in job.controls:
        module = sys.modules.get(type(control).__module__)
        if is_user_plugin(control.type_name) and module is not None and module.__name__ not in _SHIPPED:
            cloudpickle.register_pickle_by_value(module)
            _SHIPPED.add(module.__name__)


_SHIPPED: set[str] = set()


class RayRenderPool:
    """Ray actors as render workers (a :class:`RenderExecutor`); use as a context manager and call
    :meth:`run`."""

    def __init__(self, settings: RenderSettings, workers: int = 1, address: str | None = None) -> None:
        ray = self.ray = _ray()
        self._owns_ray = connect(address)
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)) // max(workers, 1))
        self.actor_cls = ray.remote(num_cpus=cpus, max_restarts=0)(RenderActor)
        self.settings = settings
        self.n_workers = workers
        self.actors: list[Any] = []
        self.packs: dict[str, bytes] = {}
        self.recycled: Counter[str] = Counter()  # actors are not recycled: [render] worker_memory is local

    def __enter__(self) -> "RayRenderPool":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def run(self, groups: list[list[RenderJob]]) -> Iterator[RenderReply]:
        """Render every group, yielding one reply per job as each group finishes."""
        ray = self.ray
        queue = deque(self._shippable(g) for g in groups if g)
        self.actors = [self.actor_cls.remote(self.settings) for _ in range(min(self.n_workers, len(queue)))]
        packs_ref = ray.put(self.packs)
        running: dict[Any, tuple[Any, list[RenderJob], int]] = {}
        last_scene: dict[Any, tuple[Any, str]] = {}

        def submit(actor, group, tries: int) -> None:
            running[actor.render_group.remote(group, packs_ref)] = (actor, group, tries)
            last_scene[actor] = (group[0].environment, group[0].mesh)

        def next_group(actor) -> list[RenderJob]:
            """The actor's scene if more of it is queued, else its world (a world switch rebuilds
            Cycles' importance map; an object it has loaded is only shown), else the next."""
            world, mesh = last_scene.get(actor, (None, ""))
            for same in ((world, mesh), (world,)):
                for i, group in enumerate(queue):
                    if (group[0].environment, group[0].mesh)[: len(same)] == same:
                        del queue[i]
                        return group
            return queue.popleft()

        for actor in self.actors:
            if queue:
                submit(actor, next_group(actor), 0)
        while running:
            done, _ = ray.wait(list(running), num_returns=1)
            actor, group, tries = running.pop(done[0])
            try:
                replies = ray.get(done[0])
            except (ray.exceptions.RayActorError, ray.exceptions.WorkerCrashedError) as exc:
                self.actors.remove(actor)
                if tries >= MAX_GROUP_RETRIES:
                    for job in group:
                        yield RenderReply(job.render_key, False, error=f"render actor died: {exc}")
                else:  # a new actor takes the group; its results were never yielded
                    replacement = self.actor_cls.remote(self.settings)
                    self.actors.append(replacement)
                    submit(replacement, group, tries + 1)
                continue
            for job, reply in zip(group, replies):
                yield self._written(job, reply)
            if queue:
                submit(actor, next_group(actor), 0)

    @staticmethod
    def _written(job: RenderJob, reply: RenderReply) -> RenderReply:
        """The reply, once its pixels are in the store: the driver writes every blob."""
        if reply.ok and job.blob is not None:  # None: only the UV pass was wanted
            atomic_write(Path(job.blob), reply.png or b"")
        return reply

    def _shippable(self, group: list[RenderJob]) -> list[RenderJob]:
        """Replace local asset paths by packs in the object store (built-in HDRIs stay: every
        node with bpy has them)."""
        out = []
        builtin = str(bpy_root())
        for job in group:
            _ship_code(job)
            env = job.environment
            if env.hdri and not env.hdri.startswith(builtin):
                env = replace(env, hdri=self._pack(Path(env.hdri), [Path(env.hdri)]))
            out.append(replace(job, mesh=self._pack(Path(job.mesh), mesh_files(Path(job.mesh))), environment=env))
        return out

    def _pack(self, main: Path, files: list[Path]) -> str:
        key = digest([str(main)] + [str(f) for f in files])[:16]
        if key not in self.packs:
            buffer = io.BytesIO()
            with tarfile.open(fileobj=buffer, mode="w") as tar:
                for f in files:
                    tar.add(f, arcname=str(f.relative_to(main.parent)))
            self.packs[key] = buffer.getvalue()
        return f"pack:{key}/{main.name}"

    def kill_one(self) -> None:
        """Kill one actor (for fault-tolerance tests)."""
        if self.actors:
            self.ray.kill(self.actors[0], no_restart=True)

    def prestart(self) -> None:
        """Nothing: actors start on the cluster when :meth:`run` asks for them."""

    def close(self, wait: bool = True) -> None:
        """Kill the actors (at once, ``wait`` or not) and end a Ray this pool started."""
        for actor in self.actors:
            try:
                self.ray.kill(actor)
            except Exception:  # noqa: BLE001  (already gone)
                pass
        self.actors = []
        if self._owns_ray:
            self.ray.shutdown()

    def join(self) -> None:
        """Nothing: :meth:`close` ends the actors at once."""
