"""kill -9 at 20 seeded moments — mid-render, mid-segment-write, mid-inference, anywhere — loses
nothing: each rerun resumes, no file is ever read half-written, no committed row is lost or
duplicated, and the final results equal an uninterrupted run's.

The killed runs are real ``sweep3d run`` processes (real Blender, real model) started through a
small harness that (a) drops marker files when a stage starts, gives a result and ends, so a kill can be aimed
at a stage (the stages overlap: a kill aimed at inference mostly lands while Blender renders), and (b) pauses 0.4 s halfway through writing each Parquet segment, so a kill can land
while a segment is half on disk. The product code runs unchanged.

The main lane kills five times, once in each phase (render, postprocess, inference, a segment
flush, the parent process alone), and checks the same; the 20-kill soak is marked ``soak``: the
default run leaves it out and ``.ci/run`` runs it after the main lane (``pytest -m soak``).

Also: a run killed alone (its workers are not) takes its render workers with it, and a worker
killed while starting ends the run with one line, keeping what was rendered.
"""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from sweep3d.cache.maintenance import collect_garbage, verify
from sweep3d.cache.store import KEY_COLUMN, Store
from sweep3d.results import connect as connect_results
from sweep3d.runner.pipeline import run
from tests.helpers import REPO, TINY_SPEC, load_spec, write_spec

pytestmark = pytest.mark.slow

KILLS = 20
SEED = 5
SPEC = TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [-180, 180] }").replace(
    '[policy]\ntype = "grid"', '[policy]\ntype = "grid"\nsamples_per_dim = 24')  # 48 renders, 96 predictions

HARNESS = r'''
import io, os, sys, time
from pathlib import Path

import pyarrow.parquet as pq

markers = Path(os.environ["SWEEP3D_TEST_MARKERS"])
_write = pq.write_table

def half_then_rest(table, where, **kwargs):
    """Write the segment's first half, pause, then the rest: a kill in the pause leaves half a file."""
    if not isinstance(where, (str, os.PathLike)):  # a buffer (the jobs file is compared before written)
        return _write(table, where, **kwargs)
    buf = io.BytesIO()
    _write(table, buf, **kwargs)
    data = buf.getvalue()
    with open(where, "wb") as fh:
        fh.write(data[: len(data) // 2])
        fh.flush()
        time.sleep(0.4)
        fh.write(data[len(data) // 2 :])

pq.write_table = half_then_rest

import sweep3d.stages.infer.infer_stage as infer
from sweep3d.stages.postprocess import PostprocessStage
from sweep3d.stages.render import RenderStage

def marked(compute):
    def wrapped(self, *args, **kwargs):
        (markers / self.name).touch()  # the stage has started (stages overlap: others may run too)
        results = compute(self, *args, **kwargs)
        try:
            for result in results:
                yield result
                (markers / f"{self.name}.computed").touch()  # it has given a result in this run
        finally:
            results.close()
            (markers / f"{self.name}.done").touch()
    return wrapped

for stage in (RenderStage, PostprocessStage, infer.InferStage):
    stage.compute = marked(stage.compute)
_model_outputs = infer.model_outputs

def model_outputs(model, images, *args, **kwargs):
    if (markers / "infer").exists():
        (markers / "predict").touch()
    return _model_outputs(model, images, *args, **kwargs)

infer.model_outputs = model_outputs
_kept_load = infer.KeptOutputs.load

def kept_load(self, image_keys):  # a batch whose outputs were kept before a kill: inference all the same
    if (markers / "infer").exists():
        (markers / "predict").touch()
    return _kept_load(self, image_keys)

infer.KeptOutputs.load = kept_load

from sweep3d.cli import main
sys.argv = ["sweep3d", "run", "spec.toml", "--no-report"]
main()
'''


def _tmp_files(store: Path, table: str, since: float) -> list[Path]:
    """Temp files of ``table`` written since ``since`` (a wall-clock time): a segment being written
    now, not one an earlier kill left (which the run removes once it holds the lock)."""
    folder = store / "tables" / table
    out = []
    for path in folder.glob(".*.tmp") if folder.is_dir() else []:
        try:
            if path.stat().st_mtime >= since:
                out.append(path)
        except FileNotFoundError:
            pass
    return out


def _blobs_since(store: Path, since: float) -> int:
    """Blobs (re)written since ``since`` (a wall-clock time)."""
    folder = store / "blobs"
    count = 0
    for path in folder.glob("*/*.png") if folder.is_dir() else []:
        try:
            count += path.stat().st_mtime >= since
        except FileNotFoundError:
            pass
    return count


def _segments(store: Path, table: str) -> int:
    folder = store / "tables" / table
    return len(list(folder.glob("*.parquet"))) if folder.is_dir() else 0


class Killer:
    """Starts harnessed runs of one folder's spec and kills each at a chosen moment."""

    def __init__(self, folder: Path, rng: random.Random, render_share: float = 1.0) -> None:
        """``render_share``: a kill aimed mid-render waits for at most this share of the renders left."""
        self.folder, self.rng, self.render_share = folder, rng, render_share
        self.store = folder / "store"
        self.markers = folder / "markers"
        self.landed: list[str] = []

    def start(self) -> subprocess.Popen:
        for marker in self.markers.glob("*"):
            marker.unlink()
        self.markers.mkdir(exist_ok=True)
        env = {**os.environ, "PYTHONPATH": str(REPO), "SWEEP3D_TEST_MARKERS": str(self.markers)}
        with open(self.folder / "stderr.txt", "w") as err:  # a file, not a pipe nobody drains
            return subprocess.Popen([sys.executable, "-c", HARNESS], cwd=self.folder, env=env,
                                    start_new_session=True, stdout=subprocess.DEVNULL, stderr=err)

    def kill_at(self, target: str, renders_left: int) -> str:
        """Run once and kill it at ``target``; returns where the kill landed (or "finished")."""
        wall = time.time()
        proc = self.start()
        started = time.monotonic()
        predictions = _segments(self.store, "predictions")
        aim = self.rng.randint(1, max(1, int((renders_left - 1) * self.render_share)))  # render blobs to wait for
        delay = self.rng.uniform(0.0, 0.6)  # seconds into inference
        anywhere = self.rng.uniform(0.3, 2.5)  # seconds after start
        predicting_since = None
        landed = None
        while landed is None:
            if proc.poll() is not None:
                landed = "finished"
                break
            now = time.monotonic()
            rendering = (self.markers / "render").exists() and not (self.markers / "render.done").exists()
            if target == "random" and now - started >= anywhere:
                landed = "random"
            elif target == "render" and rendering and _blobs_since(self.store, wall) >= aim:
                landed = "render"
            elif target == "postprocess" and (self.markers / "postprocess.computed").exists() \
                    and not (self.markers / "postprocess.done").exists():
                landed = "postprocess"  # postprocessing, with an image of this run made
            elif target == "parent" and rendering and _blobs_since(self.store, wall) >= aim:
                landed = "parent"  # the parent alone, mid-render: its workers must not render on
            elif target == "infer-late" and _segments(self.store, "predictions") > predictions:
                landed = "infer"  # just after a segment of predictions was committed
            elif target == "segment" and any(_tmp_files(self.store, t, wall) for t in ("renders", "images", "predictions")):
                landed = "segment"
            elif target == "infer":
                if _tmp_files(self.store, "predictions", wall):
                    landed = "segment"  # the inference's segment write came first: a kill mid-write
                elif (self.markers / "predict").exists():
                    predicting_since = predicting_since or now
                    if now - predicting_since >= delay:
                        landed = "infer"
            if now - started > 240:
                landed = "timeout"
            time.sleep(0.005)
        if landed == "parent":
            proc.kill()
            proc.wait()
            deadline = time.monotonic() + 10
            while _session(proc.pid) and time.monotonic() < deadline:
                time.sleep(0.05)
            alive = _session(proc.pid)
            _kill_session(proc.pid)
            assert not alive, f"still running 10 s after the parent was killed: {alive}"
        elif landed != "finished":
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        assert landed != "timeout", "the run never reached the kill point"
        if landed == "finished":
            assert proc.returncode == 0, (self.folder / "stderr.txt").read_text()[-2000:]
        return landed


def _segment_keys(store: Path) -> dict[str, list[str]]:
    """Every key of every committed segment, each segment read whole with checksums verified."""
    out = {}
    for table, column in KEY_COLUMN.items():
        keys = []
        for path in sorted((store / "tables" / table).glob("*.parquet")):
            data = pq.read_table(path, page_checksum_verification=True)  # raises on a half-written file
            keys += data.column(column).to_pylist()
        out[table] = keys
    return out


def _results(folder: Path) -> list[tuple]:
    con = connect_results(Store(folder / "store"), "tiny")
    return con.execute(
        "SELECT job, object, environment, render_key, image_key, pred_key, top1_label, correct, loss "
        "FROM results ORDER BY job").fetchall()


def _kill_resume_and_compare(tmp_path: Path, aims: list[str], seed: int, render_share: float = 1.0) -> list[str]:
    """Kill a run at each of ``aims`` in turn, checking the store after each kill; then resume it
    and compare its results with an uninterrupted run's. Returns where each kill landed."""
    killed, clean = tmp_path / "killed", tmp_path / "clean"
    for folder in (killed, clean):
        folder.mkdir()
        write_spec(folder, SPEC)
    rng = random.Random(seed)
    killer = Killer(killed, rng, render_share)
    plan_renders = 48
    committed = {table: set() for table in KEY_COLUMN}
    landed = []
    for aim in aims:
        renders_left = plan_renders - len(Store(killed / "store").keys("renders"))
        if aim in ("render", "parent") and renders_left <= 1:
            aim = "infer"
        where = killer.kill_at(aim, renders_left)
        assert where != "finished", f"the run finished before the kill aimed at {aim!r}"
        landed.append(where)

        keys = _segment_keys(killed / "store")  # no segment on disk is half-written
        for table, table_keys in keys.items():
            assert len(table_keys) == len(set(table_keys)), f"duplicate {table} rows after a kill at {where}"
            assert committed[table] <= set(table_keys), f"committed {table} rows lost after a kill at {where}"
            committed[table] = set(table_keys)
        assert not (killed / "store" / "quarantine").exists()
        report = verify(killed / "store")
        assert report.ok, [p.line(killed / "store") for p in report.problems]

    resumed = run(load_spec(killed / "spec.toml"))
    assert resumed.failed == 0
    assert resumed.outcome("render").cached == len(committed["renders"])
    assert resumed.outcome("infer").cached == len(committed["predictions"])
    assert run(load_spec(clean / "spec.toml")).failed == 0

    collect_garbage(killed / "store", older_than=0)  # half-written temp files and orphan blobs go
    assert not list((killed / "store").rglob("*.tmp"))
    assert verify(killed / "store").ok
    got, want = _results(killed), _results(clean)
    assert len(got) == len(want) == 96
    assert len({r[0] for r in got}) == len(got), "no duplicate results"
    for a, b in zip(got, want):
        assert a[:8] == b[:8]  # job, scene, keys, top-1 label, correct
        assert a[8] == pytest.approx(b[8], abs=0.05)  # loss (renders may differ by 1 LSB across processes)
    return landed


@pytest.mark.soak
def test_twenty_kills_lose_nothing_and_the_resumed_run_equals_an_uninterrupted_one(tmp_path: Path) -> None:
    # Aims: renders and segment writes while rendering is left, then inference and its segment
    # writes; a few "anywhere" kills land wherever the run happens to be.
    aims = ["render", "segment", "render", "render", "segment", "render", "random", "segment",
            "infer", "segment", "infer", "random", "infer", "infer-late", "segment", "infer",
            "random", "segment", "infer", "infer"]
    landed = _kill_resume_and_compare(tmp_path, aims, SEED)
    assert len(landed) == KILLS
    for stage in ("render", "segment", "infer"):
        assert landed.count(stage) >= 3, " ".join(landed)


def test_a_kill_in_each_phase_loses_nothing_and_the_resumed_run_equals_an_uninterrupted_one(tmp_path: Path) -> None:
    """The soak's checks after one aimed kill per phase: mid-postprocess (once it has made an image),
    the parent alone mid-render, mid-render, a segment half on disk, inference (or
    its segment write). Kills mid-render wait for at most a quarter of the renders left, so that
    each later phase still has work to be killed in."""
    aims = ["postprocess", "parent", "render", "segment", "infer"]
    landed = _kill_resume_and_compare(tmp_path, aims, SEED, render_share=0.25)
    assert landed[:4] == aims[:4] and landed[4] in ("infer", "segment"), " ".join(landed)


# -- the parent alone killed; a worker killed while starting -------------------------------------

ORPHAN_SPEC = SPEC.replace("samples_per_dim = 24", "samples_per_dim = 12")  # 24 renders


def _session(sid: int) -> list[str]:
    """The live processes of session ``sid`` ("pid state command"), as ``ps`` lists them (zombies,
    dead and waiting for init to reap them, left out)."""
    out = subprocess.run(["ps", "-s", str(sid), "-o", "pid=,stat=,args="], capture_output=True, text=True).stdout
    return [line.strip() for line in out.splitlines() if line.strip() and line.split()[1][0] != "Z"]


def _kill_session(sid: int) -> None:
    """SIGKILL what is left of the test's session ``sid``, so a failing test leaves no orphan."""
    for line in _session(sid):
        try:
            os.kill(int(line.split()[0]), signal.SIGKILL)
        except ProcessLookupError:
            pass


def _files(root: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``root`` with its size and modification time (ns)."""
    out = {}
    for path in root.rglob("*"):
        try:
            stat = path.stat()
        except FileNotFoundError:
            continue
        if path.is_file():
            out[str(path.relative_to(root))] = (stat.st_size, stat.st_mtime_ns)
    return out


def test_a_run_killed_alone_takes_its_render_workers_with_it(tmp_path: Path) -> None:
    """``setsid sweep3d run & kill -9 $!``: no worker renders on, nor writes the store unlocked."""
    from sweep3d.stages.render.pool import SCRATCH_PREFIX, scratch_root

    write_spec(tmp_path, ORPHAN_SPEC)
    store = tmp_path / "store"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    with open(tmp_path / "stderr.txt", "w") as err:
        proc = subprocess.Popen([sys.executable, "-m", "sweep3d", "run", "spec.toml", "--no-report"], cwd=tmp_path,
                                env=env, start_new_session=True, stdout=subprocess.DEVNULL, stderr=err)
    try:
        deadline = time.monotonic() + 240
        while _blobs_since(store, 0) < 2:  # rendering, with most of the 24 renders to go
            assert proc.poll() is None and time.monotonic() < deadline, (tmp_path / "stderr.txt").read_text()
            time.sleep(0.02)
        assert len(_session(proc.pid)) >= 2, "a render worker runs beside the parent"
        proc.kill()  # the parent only
        proc.wait()
        at_kill = _files(store)
        deadline = time.monotonic() + 5
        while _session(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _session(proc.pid), f"still running 5 s after the kill: {_session(proc.pid)}"
        assert _files(store) == at_kill, "the store changed after its run was killed"
        assert "Traceback" not in (tmp_path / "stderr.txt").read_text()
        assert list(scratch_root().glob(f"{SCRATCH_PREFIX}{proc.pid}-*")), "SIGKILL left the scratch folder"
        assert verify(store).ok
    finally:
        _kill_session(proc.pid)
        for folder in scratch_root().glob(f"{SCRATCH_PREFIX}{proc.pid}-*"):
            shutil.rmtree(folder, ignore_errors=True)


DYING_WORKERS = '''
"""Render workers for the test: the first is SIGKILLed before its fourth render, every later one
while starting (as the OOM killer does during `import bpy`)."""
import os
import signal
from pathlib import Path

from sweep3d.stages.render import worker


def worker_main(conn, settings, scratch, *args):
    starts = Path(os.environ["SWEEP3D_TEST_STARTS"])
    with open(starts, "a") as fh:
        fh.write("started\\n")
    if len(starts.read_text().splitlines()) > 1:
        os.kill(os.getpid(), signal.SIGKILL)
    render, rendered = worker.render_job, []

    def render_three(scene, job, *args, **kwargs):
        if len(rendered) == 3:
            os.kill(os.getpid(), signal.SIGKILL)
        rendered.append(job.render_key)
        return render(scene, job, *args, **kwargs)

    worker.render_job = render_three
    worker.worker_main(conn, settings, scratch, *args)
'''

DYING_HARNESS = """
import sys

import dying_workers
import sweep3d.stages.render.pool as pool

pool.worker_main = dying_workers.worker_main
from sweep3d.cli import main
sys.argv = ["sweep3d", "run", "spec.toml", "--no-report"]
main()
"""


def test_a_worker_killed_while_starting_ends_the_run_in_one_line_keeping_what_was_rendered(tmp_path: Path) -> None:
    write_spec(tmp_path, TINY_SPEC)  # 4 renders, one worker
    hooks = tmp_path / "hooks"
    hooks.mkdir()
    (hooks / "dying_workers.py").write_text(DYING_WORKERS)
    env = {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{hooks}", "SWEEP3D_TEST_STARTS": str(tmp_path / "starts")}
    proc = subprocess.run([sys.executable, "-c", DYING_HARNESS], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300)
    assert (tmp_path / "starts").read_text().count("started") == 2, "a worker was started for the retry"
    assert proc.returncode == 1, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    assert "render worker died while starting (killed by SIGKILL: out of memory?)" in lines[0]
    assert "run again to resume" in lines[0]
    assert "Traceback" not in proc.stdout + proc.stderr and "Aborted" not in proc.stdout + proc.stderr

    store = Store(tmp_path / "store")
    assert len(store.keys("renders")) == 3, "the three finished renders are stored"
    assert verify(tmp_path / "store").ok
    resumed = run(load_spec(tmp_path / "spec.toml"))
    assert resumed.failed == 0
    assert (resumed.outcome("render").cached, resumed.outcome("render").computed) == (3, 1)
