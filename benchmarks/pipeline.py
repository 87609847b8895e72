"""Pipeline benchmarks (issue 4), measured in one run and printed as one table.

1. Render throughput of `sweep3d run` against a bare bpy render loop at the same settings.
2. Against one Blender process per render (3DB-style cold start).
3. A no-op rerun of 10 000 cached jobs.
4. Time in render / postprocess / infer (overlapped) and store I/O, against the wall.
5. Peak memory per render worker (and of the parent, which holds the model).

    .venv/bin/python benchmarks/pipeline.py [--renders 40] [--cold 4] [--cached 10000]

`--multi-scene` instead measures sweep3d against a bare bpy loop on the quickstart's 240 distinct
renders (5 objects × 4 environments): a hand-written bpy process that imports every mesh and
builds every world once and renders world by world, object by object; sweep3d's render stage on
a fresh store (in this process); and a cold `sweep3d run` of the quickstart from process start to
exit on a fresh store (what a user waits for), interleaved round by round (`--rounds 2` runs
bare, stage, run, then run, stage, bare). The whole run's honest limit is the bare loop plus the
inference of the same images (timed alone on the stage's store): on 2 cores both are CPU-bound,
so overlapping them cannot beat their sum by much. The bare image path is also timed in batches
of 4, as sweep3d's ONNX Runtime runs them on the CPU, and the run's ratio printed against that
limit too. Stores and frames are on disk, as a user's are.

    .venv/bin/python benchmarks/pipeline.py --multi-scene [--rounds 2]

`--image-path` times the image path alone, per image: sweep3d's postprocess and infer stages (in a
fresh process each, on a copy of one store of the quickstart's renders) against the bare process
(`bare_infer.py`), each over the 240 renders blurred at 4 and at 8 σ (960 and 1,920 images),
interleaved. The difference between the two sizes is the cost of 960 images, set-up left out; the
set-up is reported apart. sweep3d runs with its user cache (an ONNX export and check kept from an
earlier run), with nothing kept (`SWEEP3D_CACHE=off`), and optionally as another checkout:

    .venv/bin/python benchmarks/pipeline.py --image-path [--rounds 2] [--old ../other-checkout]

`--post-heavy --cores 1,2` instead times the post-heavy spec's post-processing alone (its renders
made once; then the postprocess stage in a fresh process per side, `[postprocess] workers` = 1, 2,
interleaved round by round), in images/s against linear scaling:

    .venv/bin/python benchmarks/pipeline.py --post-heavy --objects 1 --cores 1,2 [--rounds 2]

`--run-phases --old ../other-checkout` times where a cold `sweep3d run` of the quickstart spends
its time before its first render and after its last: this checkout's and the other one's runs
interleaved (ABBA), each from process start to exit, with the store's render blobs counted every
50 ms (the first, the last), on a fresh store each:

    .venv/bin/python benchmarks/pipeline.py --run-phases --old ../other-checkout [--rounds 2]

`--image-path-paired` runs both sides in this one process instead, alternated run by run (ABBA),
at 960 images, torch imported first (its import is reported apart): on a machine whose speed
drifts, the tightest comparison.

    .venv/bin/python benchmarks/pipeline.py --image-path-paired [--rounds 2]
"""

from __future__ import annotations

import argparse
import compileall
import json
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

REPO = Path(__file__).resolve().parents[1]
#: The sweep3d this process imports: this checkout, or another one's (``--image-path --old``).
CHECKOUT = Path(os.environ.get("SWEEP3D_CHECKOUT", REPO))
sys.path.insert(0, str(CHECKOUT))

MESH = "/usr/share/sweethome3d/furniture/BlendSwap-CC-0.sh3f#blendswap-cc-0/basketball/basketball.obj"
SETTINGS = {"resolution": 224, "samples": 4}

SPEC = f"""
[experiment]
name = "bench"
store = "store"

[render]
resolution = {SETTINGS['resolution']}
samples = {SETTINGS['samples']}

[[objects]]
name = "basketball"
mesh = "{MESH}"
labels = ["basketball"]

[[environments]]
name = "forest"
hdri = "builtin:forest"

[[controls]]
type = "orientation"
yaw = {{ range = [-180, 180] }}

[policy]
type = "grid"
samples_per_dim = {{n}}
"""

# A hand-written bpy loop: what a careful user would write without sweep3d (same scene, same settings).
BARE = textwrap.dedent("""
    import json, math, os, sys, time, zipfile
    t0 = time.perf_counter()
    import bpy
    n, hdri, archive, member, out = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5]
    folder = out + "/mesh"
    with zipfile.ZipFile(archive) as zf:
        for name in zf.namelist():
            if name.startswith(member.rsplit("/", 1)[0] + "/") and not name.endswith("/"):
                zf.extract(name, folder)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device, c.samples, c.use_adaptive_sampling, c.use_denoising = "CPU", 4, False, True
    c.denoiser, c.denoising_prefilter = "OPENIMAGEDENOISE", "FAST"
    c.max_bounces = 8  # sweep3d's default
    scene.render.image_settings.compression = 0
    scene.render.resolution_x = scene.render.resolution_y = 224
    scene.render.use_persistent_data = True
    scene.render.threads_mode, scene.render.threads = "FIXED", os.cpu_count()
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    bpy.ops.wm.obj_import(filepath=folder + "/" + member)
    obj = bpy.context.selected_objects[0]
    # Frame it as sweep3d does: centred, unit bounding sphere spanning 80 % of the frame, 20° up.
    corners = [obj.matrix_world @ __import__("mathutils").Vector(c) for c in obj.bound_box]
    centre = sum(corners, __import__("mathutils").Vector()) / 8
    radius = max((v - centre).length for v in obj.data.vertices and [obj.matrix_world @ v.co for v in obj.data.vertices])
    obj.location -= centre
    obj.scale = [s / radius for s in obj.scale]
    obj.location /= radius
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    d = 1 / (0.8 * math.sin(math.atan(18 / 50)))
    cam.location = (0, -d * math.cos(math.radians(20)), d * math.sin(math.radians(20)))
    cam.rotation_euler = (math.radians(70), 0, 0)
    world = bpy.data.worlds.new("w"); scene.world = world; world.use_nodes = True
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(hdri)
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    t1 = time.perf_counter()
    devnull = os.open(os.devnull, os.O_WRONLY); saved = os.dup(1); os.dup2(devnull, 1)
    for i in range(n):
        obj.rotation_euler[2] = 2 * math.pi * i / max(n, 1)
        scene.render.filepath = f"{out}/frame{i}.png"
        bpy.ops.render.render(write_still=True)
    os.dup2(saved, 1)
    t2 = time.perf_counter()
    print(json.dumps({"setup": t1 - t0, "loop": t2 - t1}))
""")


def bare_loop(n: int, scratch: Path) -> dict:
    """Seconds of a bare bpy loop of ``n`` renders in one process (import + setup, loop)."""
    from sweep3d.assets.sources import builtin_hdris

    archive, member = MESH.split("#")
    started = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", BARE, str(n), str(builtin_hdris()["forest"]), archive, member,
                          str(scratch)], capture_output=True, text=True, check=True)
    timing = json.loads(out.stdout.strip().splitlines()[-1])
    timing["wall"] = time.perf_counter() - started
    return timing


def cold_start(n: int, scratch: Path) -> float:
    """Seconds per image when each render starts its own Blender process."""
    started = time.perf_counter()
    for i in range(n):
        bare_loop(1, scratch / f"cold{i}")
    return (time.perf_counter() - started) / n


class MemoryWatch(threading.Thread):
    """Polls the peak resident memory (VmHWM) of this process's children while a run goes on."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.peaks: dict[int, int] = {}
        self.stop = threading.Event()

    def run(self) -> None:
        from sweep3d.stages.render.child import live_children  # render workers are plain child processes

        while not self.stop.is_set():
            for child in live_children():
                try:
                    status = Path(f"/proc/{child.pid}/status").read_text()
                except OSError:
                    continue
                for line in status.splitlines():
                    if line.startswith("VmHWM"):  # absent once the process is a zombie
                        self.peaks[child.pid] = max(self.peaks.get(child.pid, 0), int(line.split()[1]))
            time.sleep(0.05)


def pipeline(n: int, folder: Path) -> dict:
    """Run the spec through sweep3d in this process: stage times, store I/O time, memory."""
    import resource

    import sweep3d
    from sweep3d.cache import store as store_module
    from sweep3d.runner.pipeline import run

    io = {"seconds": 0.0}

    def timed(fn):
        def wrapper(*args, **kwargs):
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                io["seconds"] += time.perf_counter() - t
        return wrapper

    for name in ("append", "keys", "write_table_file"):  # benchmark-only instrumentation
        setattr(store_module.Store, name, timed(getattr(store_module.Store, name)))
    store_module.atomic_write = timed(store_module.atomic_write)
    (folder / "spec.toml").write_text(SPEC.replace("{n}", str(n)))  # a full turn: n distinct yaws
    watch = MemoryWatch()
    watch.start()
    started = time.perf_counter()
    result = run(sweep3d.load(folder / "spec.toml").spec)
    wall = time.perf_counter() - started
    watch.stop.set()
    assert result.failed == 0 and result.outcome("render").computed == n, result.outcomes
    stages = {o.stage: o.seconds for o in result.outcomes}
    return {"wall": wall, "stages": stages, "store_io": io["seconds"],
            "worker_peak_mb": max(watch.peaks.values(), default=0) / 1024,
            "parent_peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def noop_rerun(n: int, folder: Path) -> dict:
    """Seconds for `sweep3d run` when all ``n`` jobs are cached (rows synthesised, blobs tiny)."""
    import sweep3d
    from sweep3d.cache.store import Store, atomic_write, utc_now
    from sweep3d.core.pixels import encode_png
    from sweep3d.runner.pipeline import plan_spec
    from sweep3d.stages.infer import ClassificationEvaluator
    from sweep3d.stages.infer.infer_stage import predictions_schema

    (folder / "cube.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    spec = SPEC.replace(MESH, "cube.obj").replace('samples_per_dim = {n}', "").replace(
        'type = "grid"', f'type = "random"\nsamples = {n}').replace('yaw = {', 'pitch = { range = [-90, 90] }\nyaw = {')
    (folder / "spec.toml").write_text(spec)
    plan = plan_spec(sweep3d.load(folder / "spec.toml").spec)
    store = Store(folder / "store")
    png = encode_png(np.zeros((8, 8, 3), np.float32))
    now = utc_now()
    for job in plan.jobs:
        atomic_write(store.blob_path(job.render_key), png)
    store.append("renders", [{"render_key": j.render_key, "width": 8, "height": 8, "valid": True, "seconds": 0.0,
                              "created_at": now} for j in plan.jobs])
    schema = predictions_schema(ClassificationEvaluator())
    store.append("predictions", [{"pred_key": j.pred_key, "image_key": j.image_key, "model": "m", "valid": True,
                                  "correct": True, "top1_label": "basketball", "loss": 0.1, "created_at": now}
                                 for j in plan.jobs], schema)
    started = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "sweep3d", "run", "spec.toml", "--no-report"], cwd=folder,
                         capture_output=True, text=True)
    wall = time.perf_counter() - started
    assert out.returncode == 0 and f"{n} jobs" in out.stdout, out.stdout + out.stderr
    return {"jobs": len(plan.jobs), "wall": wall}


# -- multi-scene: the quickstart's jobs, bare bpy loop against the render stage ---------------------
QUICKSTART = REPO / "specs" / "quickstart.toml"

# The hand-written loop is benchmarks/bare_loop.py: a script that needs bpy and numpy alone.
BARE_LOOP = Path(__file__).with_name("bare_loop.py")


def quickstart_spec(folder: Path) -> Path:
    """The quickstart spec in ``folder``, with its store there."""
    folder.mkdir(parents=True, exist_ok=True)
    text = QUICKSTART.read_text().replace('store = "../.sweep3d"', 'store = "store"')
    assert 'store = "store"' in text
    (folder / "spec.toml").write_text(text)
    return folder / "spec.toml"


def bare_jobs(folder: Path) -> tuple[Path, int]:
    """The quickstart's distinct renders as the bare loop's input (world, object, pose order)."""
    import sweep3d
    from sweep3d.assets.sources import materialise_mesh
    from sweep3d.runner.pipeline import plan_spec
    from sweep3d.stages.render import render_settings

    plan = plan_spec(sweep3d.load(quickstart_spec(folder)).spec)
    spec = plan.spec
    rendered = {c.control.id for c in spec.controls if c.control.stage == "render"}
    assert rendered == {"orientation", "camera"}, f"the bare loop poses only these controls, not {rendered}"
    settings = render_settings(plan)
    meshes = {o.name: str(materialise_mesh(spec.meshes[o.name], folder / "assets")) for o in spec.objects}
    unique = {j.render_key: j for j in plan.jobs}.values()
    jobs = [{"key": j.render_key, "mesh": meshes[j.object], "environment": j.environment,
             "yaw": j.values["orientation"]["yaw"], "elevation": j.values["camera"]["elevation"],
             "sun": key_light(spec, j)}
            for j in sorted(unique, key=lambda j: (j.environment, j.object, j.index))]
    environments = {e.name: {"hdri": spec.hdris[e.name], "color": e.color, "strength": e.strength,
                             "fill": e.key_light.fill if e.key_light is not None else 1.0}
                    for e in spec.environments}
    path = folder / "bare.json"
    path.write_text(json.dumps({"settings": {"size": settings.resolution, "crop": settings.crop or settings.resolution,
                                             "samples": settings.samples, "seed": settings.seed,
                                             "max_bounces": settings.max_bounces},
                                "meshes": list(meshes.values()), "environments": environments, "jobs": jobs}))
    return path, len(jobs)


def key_light(spec, job) -> dict | None:
    """The sun sweep3d lights a plain colour with for ``job`` (its energy, angle and column-major
    world matrix, by rows), from sweep3d's own light code; None for an HDRI."""
    from sweep3d.stages.render.cycles.lamps import blender_light
    from sweep3d.stages.render.lights import SunLight
    from sweep3d.stages.render.state import SceneState

    env = next(e for e in spec.environments if e.name == job.environment)
    if env.key_light is None:
        return None
    state = SceneState()
    for inst in sorted((c.control for c in spec.controls if c.control.stage == "render"), key=lambda c: c.order):
        if inst.id in job.values:
            inst.apply(state, inst.params(job.values[inst.id]))
    key = env.key_light
    sun = SunLight((1.0, 1.0, 1.0), key.strength * env.strength, key.angle, key.azimuth, key.elevation, "camera")
    _, values, matrix = blender_light(sun, state)
    return {"energy": values["energy"], "angle": values["angle"], "matrix": matrix.tolist()}


def bare_multi(folder: Path) -> dict:
    """Seconds and peak memory of the hand-written loop over the quickstart's renders."""
    spec, n = bare_jobs(folder)
    out = folder / "frames"
    out.mkdir()
    started = time.perf_counter()
    done = subprocess.run([sys.executable, str(BARE_LOOP), str(spec), str(out)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    timing = json.loads(done.stdout.strip().splitlines()[-1])
    described = json.loads(spec.read_text())
    return {**timing, "wall": time.perf_counter() - started, "n": n, "frames": out, "jobs": described["jobs"],
            "environments": described["environments"]}


def stage_multi(folder: Path) -> dict:
    """Seconds of sweep3d's render stage over the quickstart on a fresh store, and worker memory."""
    import sweep3d
    from sweep3d.cache.store import Store
    from sweep3d.driver.loop import run_stage
    from sweep3d.driver.progress import RunProgress
    from sweep3d.runner.pipeline import plan_spec
    from sweep3d.stages.render import RenderStage

    plan = plan_spec(sweep3d.load(quickstart_spec(folder)).spec)
    store = Store(folder / "store")
    watch = MemoryWatch()
    watch.start()
    outcome = run_stage(RenderStage(), plan, store, RunProgress(None))
    watch.stop.set()
    assert outcome.failed == 0 and outcome.computed == outcome.total, outcome
    return {"seconds": outcome.seconds, "n": outcome.computed, "store": store,
            "worker_peak_mb": max(watch.peaks.values(), default=0) / 1024}


def cli_multi(folder: Path) -> dict:
    """Seconds of a cold ``sweep3d run --no-report`` of the quickstart on a fresh store, process
    start to exit (the bare processes write no report either: it takes another 4 s)."""
    spec = quickstart_spec(folder)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "sweep3d", "run", str(spec), "--no-report"], capture_output=True, text=True,
                          cwd=folder)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return {"seconds": time.perf_counter() - started}


#: The blur's σ values of the image-path comparison: the quickstart's four, and eight.
SIGMAS = {4: [0.0, 1.0, 2.0, 3.0], 8: [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5]}


def blurred_spec(folder: Path, sigmas: list[float]) -> Path:
    """The quickstart with its blur at ``sigmas`` (its renders are the same: blur is post-processing)."""
    spec = quickstart_spec(folder)
    text = spec.read_text()
    assert "sigma = [0.0, 1.0, 2.0, 3.0]" in text
    spec.write_text(text.replace("sigma = [0.0, 1.0, 2.0, 3.0]", f"sigma = {sigmas}"))
    return spec


def infer_alone(stage: dict, folder: Path, sigmas: list[float] | None = None, cpu: dict | None = None) -> float:
    """Seconds of the postprocess and inference stages alone over the stage's renders, overlapped
    as a run overlaps them (the model loaded first, as a run's is before its renders end):
    sweep3d's image path. ``cpu`` gets the CPU seconds they took (every thread's) under ``"cpu"``."""
    import sweep3d
    from sweep3d.driver.loop import run_stages
    from sweep3d.driver.progress import RunProgress
    from sweep3d.runner.pipeline import plan_spec
    from sweep3d.stages.infer import InferStage, ModelHandle
    from sweep3d.stages.postprocess import ImageHandoff, PostprocessStage

    try:
        from sweep3d.cache import skip_pandas_probe

        skip_pandas_probe()  # as the CLI does
    except ImportError:  # an older checkout
        pass
    spec = sweep3d.load(blurred_spec(folder, sigmas or SIGMAS[4])).spec
    model = ModelHandle.resolve(spec)
    plan = plan_spec(spec, model)
    post = PostprocessStage.for_spec(spec, ImageHandoff())  # as a run wires them
    infer = InferStage(model, handoff=post.handoff, images_stored=post.store_images)
    started, cpu_started = time.perf_counter(), time.process_time()
    outcomes = run_stages([post, infer], plan, stage["store"], RunProgress(None), overlap=True)  # as a run does
    assert all(o.failed == 0 for o in outcomes), outcomes
    if cpu is not None:
        cpu["cpu"] = time.process_time() - cpu_started
    return time.perf_counter() - started


def image_path_side(renders: Path, folder: Path, sigmas: list[float], checkout: Path, keep: bool) -> dict:
    """Wall and CPU seconds of sweep3d's image path in a fresh process of ``checkout`` over a copy
    of the store at ``renders`` (its renders only), with the user's cache or (``keep`` False)
    nothing kept."""
    shutil.copytree(renders, folder)
    env = {**os.environ, "SWEEP3D_CHECKOUT": str(checkout), **({} if keep else {"SWEEP3D_CACHE": "off"})}
    done = subprocess.run([sys.executable, __file__, "--infer-alone", str(folder), "--sigmas", str(len(sigmas))],
                          capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    shutil.rmtree(folder)
    return json.loads(done.stdout.strip().splitlines()[-1])


def compiled(*checkouts: Path | None) -> None:
    """Byte-compile each checkout's package before it is timed: a checkout only ever run with
    ``PYTHONDONTWRITEBYTECODE`` set (or whose render workers alone import a module) compiles from
    source in every process, a tenth of a second at each start that the other side does not pay."""
    for checkout in checkouts:
        if checkout is not None:
            compileall.compile_dir(str(Path(checkout) / "sweep3d"), quiet=1)


def image_path(rounds: int, old: Path | None, console: Console) -> None:
    """The image path per image: sweep3d's stages against the bare process at 960 and 1,920 images."""
    sides = {"bare": None, "sweep3d": (REPO, True), "sweep3d, nothing kept": (REPO, False),
             **({"old checkout": (old, False)} if old else {})}
    seconds: dict[tuple[str, int], list[dict]] = {(side, n): [] for side in sides for n in SIGMAS}
    compiled(REPO, old)
    with tempfile.TemporaryDirectory(prefix="sweep3d-path-") as tmp:
        console.print("the quickstart's renders, once ...")
        stage = stage_multi(Path(tmp) / "renders")
        renders = Path(tmp) / "renders"
        model = export_onnx(Path(tmp) / "lite0.onnx")
        image_path_side(renders, Path(tmp) / "warm", SIGMAS[4], REPO, True)  # the user cache holds the export
        order = [(side, n) for n in SIGMAS for side in sides]
        for i in range(rounds):
            for side, n in order if i % 2 == 0 else order[::-1]:
                console.print(f"round {i + 1}: {side}, {n} σ ...")
                if side == "bare":
                    took = bare_infer(stage["store"].root / "blobs", model, SIGMAS[n])
                else:
                    checkout, keep = sides[side]
                    took = image_path_side(renders, Path(tmp) / "side", SIGMAS[n], checkout, keep)
                seconds[(side, n)].append({"wall": took["wall"], "cpu": took["cpu"]})
    renders_n = stage["n"]
    small, large = (renders_n * n for n in SIGMAS)
    for measure, unit in (("wall", "s"), ("cpu", "CPU s")):
        table = Table(title=f"the image path per image, {measure}: {renders_n} renders blurred at 4 and 8 σ ({small} "
                            f"and {large} images), read, post-processed, classified (rounds: {rounds}, interleaved; "
                            "medians)")
        for column in ("side", f"{small} images ({unit})", f"{large} images ({unit})", "per image (ms)",
                       f"set-up ({unit})", "per image / bare"):
            table.add_column(column, justify="left" if column == "side" else "right")
        bare_slope = None
        for side in sides:
            a, b = (float(np.median([t[measure] for t in seconds[(side, n)]])) for n in SIGMAS)
            slope = (b - a) / (large - small)
            bare_slope = slope if side == "bare" else bare_slope
            table.add_row(side, " / ".join(f"{t[measure]:.2f}" for t in seconds[(side, 4)]),
                          " / ".join(f"{t[measure]:.2f}" for t in seconds[(side, 8)]), f"{slope * 1000:.2f}",
                          f"{a - slope * small:.2f}", f"{slope / bare_slope:.2f}" if bare_slope else "")
        console.print(table)
    console.print("sweep3d's times are its stages' in a fresh process (imports left out); the bare process's, "
                  "start to exit. per image: (time at 1,920 − time at 960) / 960; set-up: the rest at 960.")


def image_path_paired(rounds: int, console: Console) -> None:
    """The image path, sweep3d's stages against the bare loop (``bare_infer.image_path``), both in
    this one process, alternated image set by image set (ABBA): on a machine whose speed drifts,
    each pair of runs sees the same machine. torch is imported first, so that neither side pays
    its import (sweep3d pays it once per process at its first near tie: timed here apart)."""
    import bare_infer

    from sweep3d.cache.store import Store

    started = time.perf_counter()
    import torch  # noqa: F401  (see above)

    torch_import = time.perf_counter() - started
    sides: dict[str, list[dict]] = {"bare": [], "sweep3d": []}
    with tempfile.TemporaryDirectory(prefix="sweep3d-paired-") as tmp:
        console.print("the quickstart's renders, once ...")
        stage = stage_multi(Path(tmp) / "renders")
        model = export_onnx(Path(tmp) / "lite0.onnx")
        scratch = Path(tmp) / "side"
        for i in range(rounds * 2 + 1):  # the first sweep3d round only fills the user cache: not counted
            for side in ("sweep3d", "bare") if i % 2 == 0 else ("bare", "sweep3d"):
                if i == 0 and side == "bare":
                    continue
                wall, cpu = time.perf_counter(), time.process_time()
                if side == "bare":
                    run = bare_infer.onnx_runner(model, 2)
                    run(np.zeros((1, 3, 224, 224), np.float32))
                    images = len(bare_infer.image_path(stage["store"].root / "blobs", run, SIGMAS[4], 32)["top1"])
                else:
                    shutil.copytree(Path(tmp) / "renders", scratch)
                    wall, cpu = time.perf_counter(), time.process_time()
                    infer_alone({"store": Store(scratch / "store")}, scratch)
                    shutil.rmtree(scratch)
                    images = stage["n"] * len(SIGMAS[4])
                took = {"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu, "images": images}
                console.print(f"round {i}: {side} {took['wall']:.2f} s")
                if i:
                    sides[side].append(took)
    table = Table(title=f"the image path in one process, alternated (ABBA, {rounds * 2} runs a side): the "
                        f"quickstart's {stage['n']} renders blurred at 4 σ, read, post-processed, classified")
    for column in ("side", "runs (s)", "per image (ms)", "CPU per image (ms)", "/ bare (wall)", "/ bare (CPU)"):
        table.add_column(column, justify="left" if column == "side" else "right")
    per = {side: (sum(t["wall"] for t in runs) / sum(t["images"] for t in runs),
                  sum(t["cpu"] for t in runs) / sum(t["images"] for t in runs)) for side, runs in sides.items()}
    for side, runs in sides.items():
        table.add_row(side, " / ".join(f"{t['wall']:.2f}" for t in runs), f"{per[side][0] * 1000:.2f}",
                      f"{per[side][1] * 1000:.2f}", f"{per[side][0] / per['bare'][0]:.2f}",
                      f"{per[side][1] / per['bare'][1]:.2f}")
    console.print(table)
    console.print(f"torch's import in this process: {torch_import:.2f} s (sweep3d pays it at its first near tie, "
                  "if any; the bare loop never)")


BARE_INFER = Path(__file__).with_name("bare_infer.py")


def bare_infer(renders: Path, model: Path, sigmas: list[float] | None = None, batch: int = 32) -> dict:
    """The hand-written image path over ``renders`` (PNGs, searched recursively): read, blur at
    σ = 0, 1, 2, 3, classify with ONNX Runtime on 2 threads in batches of ``batch``, in a fresh
    process; its JSON line and its wall time from start to exit."""
    import resource

    started, before = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([sys.executable, str(BARE_INFER), str(renders), "--backend", "onnx", "--model", str(model),
                           "--threads", "2", "--sigmas", ",".join(str(s) for s in sigmas or SIGMAS[4]),
                           "--batch", str(batch)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    wall, after = time.perf_counter() - started, resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return {**json.loads(done.stdout.strip().splitlines()[-1]), "wall": wall, "cpu": cpu}


def export_onnx(path: Path) -> Path:
    """Lite0's ONNX graph as sweep3d exports it (for the bare inference process)."""
    done = subprocess.run([sys.executable, str(BARE_INFER), "--export", str(path)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    return path


def agreement(bare: dict, stage: dict) -> tuple[float, float]:
    """Mean |difference| in 8-bit levels between the two sides' images, and the share of pixels
    more than 2 levels apart (edges against a plain background are blended differently)."""
    from PIL import Image

    from sweep3d.core.pixels import decode_png

    means, far = [], []
    backgrounds = {job["key"]: bare["environments"][job["environment"]]["color"] for job in bare["jobs"]}
    for frame in sorted(bare["frames"].glob("*.png")):
        with Image.open(frame) as img:  # the bare loop's plain colours come out transparent
            rgba = np.asarray(img.convert("RGBA"), dtype=np.float32) / 255.0
        rgb, alpha = rgba[..., :3], rgba[..., 3:]
        if backgrounds[frame.stem] is not None:
            rgb = rgb * alpha + np.asarray(backgrounds[frame.stem], dtype=np.float32) * (1 - alpha)
        diff = np.abs(np.round(rgb * 255) / 255 - decode_png(stage["store"].blob_path(frame.stem))) * 255
        means.append(diff.mean())
        far.append((diff.max(axis=2) > 2.5).mean())
    return float(np.mean(means)), float(np.mean(far))


def multi_scene(rounds: int, console: Console) -> None:
    """Bare loop, render stage and cold run on the quickstart's renders, interleaved (bare, stage,
    run; run, stage, bare; ...)."""
    from sweep3d.cache.store import Store

    sides = {"bare": bare_multi, "stage": stage_multi, "run": cli_multi}
    done: dict[str, list[dict]] = {side: [] for side in sides}
    compiled(REPO)
    with tempfile.TemporaryDirectory(prefix="sweep3d-bench-") as tmp:
        for i in range(rounds):
            for side in list(sides) if i % 2 == 0 else list(sides)[::-1]:
                console.print(f"round {i + 1}: {side} ...")
                done[side].append(sides[side](Path(tmp) / f"{side}{i}"))
        mean_diff, far = agreement(done["bare"][0], done["stage"][0])
        model = export_onnx(Path(tmp) / "lite0.onnx")
        paths: dict[str, list[float]] = {"bare": [], "bare, batches of 4": [], "sweep3d": []}
        for i in range(rounds):  # the image path alone, interleaved: bare, sweep3d; sweep3d, bare; ...
            for side in list(paths) if i % 2 == 0 else list(paths)[::-1]:
                console.print(f"image path, round {i + 1}: {side} ...")
                if side.startswith("bare"):
                    paths[side].append(bare_infer(done["stage"][0]["store"].root / "blobs", model,
                                                  batch=4 if "4" in side else 32)["wall"])
                else:
                    scratch = Path(tmp) / f"path{i}"
                    shutil.copytree(Path(tmp) / "stage0", scratch)
                    paths[side].append(infer_alone({"store": Store(scratch / "store")}, scratch))
        infer = float(np.mean(paths["bare"]))
    bare, stage, run = done["bare"], done["stage"], done["run"]
    n = stage[0]["n"]
    bare_rate = n / np.mean([b["wall"] for b in bare])
    loop_rate = n / np.mean([b["loop"] for b in bare])
    stage_rate = n / np.mean([s["seconds"] for s in stage])
    table = Table(title=f"render stage against a bare bpy loop: the quickstart's {n} renders, 5 objects × 4 "
                        f"environments (rounds: {rounds}, bare and stage interleaved)")
    for column in ("measure", "value", "target", "met"):
        table.add_column(column, justify="right" if column != "measure" else "left")
    table.add_row("bare bpy loop, whole process (img/s)", f"{bare_rate:.2f}", "", "")
    table.add_row("bare bpy loop, render loop only (img/s)", f"{loop_rate:.2f}", "", "")
    table.add_row("   its set-up: import bpy, meshes, worlds (s)", f"{np.mean([b['setup'] for b in bare]):.1f}", "", "")
    table.add_row("sweep3d render stage, incl. worker start (img/s)", f"{stage_rate:.2f}", "", "")
    ratio = stage_rate / bare_rate
    table.add_row("render stage / bare process", f"{ratio:.2f}", "≥ 0.95", "yes" if ratio >= 0.95 else "NO")
    table.add_row("render stage / bare render loop only", f"{stage_rate / loop_rate:.2f}", "", "")
    bare_wall = np.mean([b["wall"] for b in bare])
    run_wall = np.mean([r["seconds"] for r in run])
    images = n * 4  # the quickstart's four blurs
    ours = float(np.mean(paths["sweep3d"]))
    table.add_row("bare image path: read, blur, ONNX Runtime, one process (s)",
                  " / ".join(f"{x:.1f}" for x in paths["bare"]), "", "")
    table.add_row("   the same in batches of 4 (what sweep3d's ONNX Runtime runs) (s)",
                  " / ".join(f"{x:.1f}" for x in paths["bare, batches of 4"]), "", "")
    table.add_row("sweep3d's image path: postprocess + infer stages (s)",
                  " / ".join(f"{x:.1f}" for x in paths["sweep3d"]), "", "")
    table.add_row("   per image: sweep3d / bare (ms)", f"{ours / images * 1000:.1f} / {infer / images * 1000:.1f}", "", "")
    path_ratio = ours / infer
    table.add_row("image path: sweep3d / bare (×)", f"{path_ratio:.2f}", "≤ 1.1", "yes" if path_ratio <= 1.1 else "NO")
    table.add_row("cold `sweep3d run`, process start to exit (s)", " / ".join(f"{r['seconds']:.1f}" for r in run), "", "")
    table.add_row("   its limit: bare render process + bare image path (s)", f"{bare_wall:.1f} + {infer:.1f}", "", "")
    table.add_row("whole run / bare render process (×)", f"{run_wall / bare_wall:.2f}", "", "")
    limit_ratio = run_wall / (bare_wall + infer)
    table.add_row("whole run / its limit (×)", f"{limit_ratio:.3f}", "≤ 1.05", "yes" if limit_ratio <= 1.05 else "NO")
    small = float(np.mean(paths["bare, batches of 4"]))
    table.add_row("whole run / the limit with the bare path in batches of 4 (×)", f"{run_wall / (bare_wall + small):.3f}",
                  "", "")
    table.add_row("peak memory: render worker / bare process (MB)",
                  f"{max(s['worker_peak_mb'] for s in stage):.0f} / {max(b['peak_mb'] for b in bare):.0f}", "", "")
    table.add_row("images, bare vs stage: mean |Δ| (8-bit levels)", f"{mean_diff:.2f}", "", "")
    table.add_row("images, bare vs stage: pixels > 2 levels apart", f"{far:.2%}", "", "")
    console.print(table)


#: ImageNet-C's corruptions but glass_blur (2 s an image in imagecorruptions' Python loop: it
#: alone would be 90 % of the run, whatever the image path costs), at every severity.
HEAVY_CORRUPTIONS = ["gaussian_noise", "shot_noise", "impulse_noise", "defocus_blur", "motion_blur", "zoom_blur",
                     "snow", "frost", "fog", "brightness", "contrast", "elastic_transform", "pixelate",
                     "jpeg_compression", "speckle_noise", "gaussian_blur", "spatter", "saturate"]


def post_heavy_spec(folder: Path, objects: int) -> Path:
    """The quickstart with its first ``objects`` objects, blur replaced by the corruptions above at
    severities 1–5: 48 renders an object, 90 images a render."""
    (folder / "spec.toml").write_text(post_heavy_text(quickstart_spec(folder).read_text(), objects))
    return folder / "spec.toml"


def post_heavy_text(text: str, objects: int) -> str:
    """A quickstart spec's text made post-heavy (see :func:`post_heavy_spec`)."""
    head, *blocks = text.split("[[objects]]")
    kept, rest = blocks[:objects], blocks[-1].split("[[environments]]", 1)[1]
    kept[-1] = kept[-1].split("[[environments]]", 1)[0] if len(blocks) == objects else kept[-1]
    text = head + "".join("[[objects]]" + b for b in kept) + "[[environments]]" + rest
    blur = text[text.index('type  = "blur"'):text.index("[policy]")]
    names = ", ".join(f'"{n}"' for n in HEAVY_CORRUPTIONS)
    return text.replace(blur, f'type     = "corruption"\nname     = [{names}]\nseverity = [1, 2, 3, 4, 5]\n\n')


def post_heavy(rounds: int, objects: int, old: Path | None, console: Console) -> None:
    """Cold `sweep3d run --no-report` of the post-heavy spec on fresh stores, this checkout against
    ``old`` (another checkout, e.g. the commit before the in-memory image path), interleaved."""
    sides = {"new": REPO, **({"old": old} if old else {})}
    walls: dict[str, list[float]] = {side: [] for side in sides}
    compiled(REPO, old)
    with tempfile.TemporaryDirectory(prefix="sweep3d-heavy-") as tmp:
        for i in range(rounds):
            for side in list(sides) if i % 2 == 0 else list(sides)[::-1]:
                folder = Path(tmp) / f"{side}{i}"
                folder.mkdir()
                spec = post_heavy_spec(folder, objects)
                console.print(f"round {i + 1}: {side} ...")
                started = time.perf_counter()
                done = subprocess.run([sys.executable, "-m", "sweep3d", "run", str(spec), "--no-report"],
                                      capture_output=True, text=True, cwd=folder,
                                      env={**os.environ, "PYTHONPATH": str(sides[side])})
                assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
                walls[side].append(time.perf_counter() - started)
                console.print(done.stdout.strip().splitlines()[-1] if done.stdout.strip() else "")
    renders = 48 * objects
    table = Table(title=f"post-heavy: {renders} renders × {len(HEAVY_CORRUPTIONS)} corruptions × 5 severities "
                        f"= {renders * len(HEAVY_CORRUPTIONS) * 5} images, cold `sweep3d run`, process start to exit")
    for column in ("checkout", "seconds", "images/s"):
        table.add_column(column)
    for side, seconds in walls.items():
        table.add_row(f"{side} ({sides[side]})", " / ".join(f"{x:.1f}" for x in seconds),
                      f"{renders * len(HEAVY_CORRUPTIONS) * 5 / np.mean(seconds):.1f}")
    console.print(table)


def post_heavy_cores(rounds: int, objects: int, cores: list[int], console: Console) -> None:
    """The post-heavy spec's post-processing alone on each of ``cores`` (``[postprocess] workers``):
    its renders made once by the render stage, then, interleaved round by round, the postprocess
    stage in a fresh process over a copy of that store (its images made in memory, as a run's are,
    and dropped: no inference), timed from the stage's start to its end."""
    import sweep3d
    from sweep3d.cache.store import Store
    from sweep3d.driver.loop import run_stage
    from sweep3d.driver.progress import RunProgress
    from sweep3d.runner.pipeline import plan_spec
    from sweep3d.stages.render import RenderStage

    took: dict[int, list[dict]] = {k: [] for k in cores}
    loads = [os.getloadavg()]
    with tempfile.TemporaryDirectory(prefix="sweep3d-cores-") as tmp:
        renders = Path(tmp) / "renders"
        plan = plan_spec(sweep3d.load(post_heavy_spec(renders, objects)).spec)
        console.print(f"the post-heavy spec's {objects} object(s): its renders, once ...")
        outcome = run_stage(RenderStage(), plan, Store(renders / "store"), RunProgress(None))
        assert outcome.failed == 0, outcome
        for i in range(rounds):
            for k in cores if i % 2 == 0 else cores[::-1]:
                console.print(f"round {i + 1}: {k} core(s) ...")
                side = Path(tmp) / "side"
                shutil.copytree(renders, side)
                done = subprocess.run([sys.executable, __file__, "--post-alone", str(side), "--workers", str(k)],
                                      capture_output=True, text=True)
                assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
                took[k].append(json.loads(done.stdout.strip().splitlines()[-1]))
                shutil.rmtree(side)
                loads.append(os.getloadavg())
    images = took[cores[0]][0]["images"]
    one = float(np.median([images / t["seconds"] for t in took[min(cores)]]))
    table = Table(title=f"post-heavy post-processing alone: {images:,} images ({outcome.total} renders × "
                        f"{len(HEAVY_CORRUPTIONS)} corruptions × 5 severities), rounds: {rounds}, interleaved")
    for column in ("cores ([postprocess] workers)", "seconds", "CPU seconds", "images/s (median)",
                   "processes that made images", f"× {min(cores)} core", "of linear"):
        table.add_column(column, justify="right")
    for k in cores:
        rate = float(np.median([images / t["seconds"] for t in took[k]]))
        table.add_row(str(k), " / ".join(f"{t['seconds']:.1f}" for t in took[k]),
                      " / ".join(f"{t['cpu']:.1f}" for t in took[k]), f"{rate:.1f}",
                      " / ".join(str(t["processes"]) for t in took[k]), f"{rate / one:.2f}",
                      f"{rate / one / (k / min(cores)):.2f}")
    console.print(table)
    console.print("load averages (1, 5, 15 min) before and after each side: "
                  + "; ".join(" ".join(f"{x:.2f}" for x in load) for load in loads))


def post_alone(folder: Path, workers: int) -> dict:
    """Seconds of the postprocess stage alone over the renders in ``folder``'s store, with ``workers``."""
    import sweep3d
    from sweep3d.cache.store import Store
    from sweep3d.driver.loop import run_stage
    from sweep3d.driver.progress import RunProgress
    from sweep3d.runner.pipeline import plan_spec
    from sweep3d.stages.postprocess import PostprocessStage

    plan = plan_spec(sweep3d.load(folder / "spec.toml").spec)
    stage = PostprocessStage(store_images=False, workers=workers)
    started, cpu = time.perf_counter(), _cpu()
    outcome = run_stage(stage, plan, Store(folder / "store"), RunProgress(None))
    seconds, cpu = time.perf_counter() - started, _cpu() - cpu
    assert outcome.failed == 0 and outcome.computed == outcome.total, outcome
    return {"seconds": seconds, "cpu": cpu, "images": outcome.computed, "processes": len(stage.spread.pids)}


def _cpu() -> float:
    """CPU seconds of this process and of its children that have ended (the post workers)."""
    import resource

    return sum(u.ru_utime + u.ru_stime for u in (resource.getrusage(resource.RUSAGE_SELF),
                                                 resource.getrusage(resource.RUSAGE_CHILDREN)))


def run_phases(rounds: int, old: Path | None, console: Console) -> None:
    """Cold quickstart runs of this checkout and ``old`` interleaved (ABBA): seconds from process
    start to the first render blob, to the last, and to exit."""
    sides = {"this": CHECKOUT, **({"old": old.resolve()} if old is not None else {})}
    times: dict[str, list[tuple[float, float, float]]] = {side: [] for side in sides}
    compiled(*sides.values())
    with tempfile.TemporaryDirectory(prefix="sweep3d-phases-") as tmp:
        for i in range(rounds):
            for side in list(sides) if i % 2 == 0 else list(sides)[::-1]:
                console.print(f"round {i + 1}: {side} ...")
                folder = Path(tmp) / f"{side}{i}"
                spec = quickstart_spec(folder)
                env = {**os.environ, "PYTHONPATH": str(sides[side])}
                started = time.perf_counter()
                run = subprocess.Popen([sys.executable, "-m", "sweep3d", "run", str(spec), "--no-report"], cwd=folder,
                                       env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                first = last = None
                seen = 0
                while run.poll() is None:
                    blobs = len(list((folder / "store" / "blobs").glob("*/*.png")))
                    now = time.perf_counter() - started
                    if blobs and first is None:
                        first = now
                    if blobs > seen:
                        seen, last = blobs, now
                    time.sleep(0.05)
                ended = time.perf_counter() - started
                assert run.returncode == 0, run.stderr.read()[-3000:]
                times[side].append((first or ended, last or ended, ended))
    table = Table(title=f"cold `sweep3d run` of the quickstart, phases (rounds: {rounds}, sides interleaved)")
    for column in ("side", "to the first render (s)", "renders (s)", "last render to exit (s)", "whole (s)"):
        table.add_column(column, justify="right" if column != "side" else "left")
    for side, rows in times.items():
        table.add_row(side, *(" / ".join(f"{x:.2f}" for x in column) for column in (
            [r[0] for r in rows], [r[1] - r[0] for r in rows], [r[2] - r[1] for r in rows], [r[2] for r in rows])))
    console.print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--renders", type=int, default=40, help="renders in the throughput comparison")
    parser.add_argument("--cold", type=int, default=4, help="renders for the one-process-per-render baseline")
    parser.add_argument("--cached", type=int, default=10_000, help="jobs in the no-op rerun")
    parser.add_argument("--multi-scene", action="store_true",
                        help="only the quickstart's renders: bare bpy loop against the render stage")
    parser.add_argument("--rounds", type=int, default=1, help="with --multi-scene or --post-heavy: rounds of each side")
    parser.add_argument("--post-heavy", action="store_true",
                        help="only the post-heavy spec: the quickstart's renders × 18 corruptions × 5 severities")
    parser.add_argument("--objects", type=int, default=5, help="with --post-heavy: the quickstart's first N objects")
    parser.add_argument("--cores", type=str, help="with --post-heavy: time its post-processing alone on these "
                        "core counts ([postprocess] workers), e.g. 1,2, instead of whole runs")
    parser.add_argument("--post-alone", type=Path, help=argparse.SUPPRESS)  # one side of --post-heavy --cores
    parser.add_argument("--workers", type=int, default=1, help=argparse.SUPPRESS)
    parser.add_argument("--old", type=Path, help="with --post-heavy, --image-path or --run-phases: another checkout to "
                        "time beside this one")
    parser.add_argument("--image-path", action="store_true",
                        help="only the image path, per image: sweep3d's stages against the bare process")
    parser.add_argument("--run-phases", action="store_true",
                        help="only cold runs of the quickstart: time to the first render, the renders, last render to exit")
    parser.add_argument("--image-path-paired", action="store_true",
                        help="only the image path: sweep3d's stages and the bare loop in one process, alternated")
    parser.add_argument("--infer-alone", type=Path, help=argparse.SUPPRESS)  # one side of --image-path
    parser.add_argument("--sigmas", type=int, default=4, choices=sorted(SIGMAS), help=argparse.SUPPRESS)
    args = parser.parse_args()
    console = Console()
    if args.infer_alone:
        from sweep3d.cache.store import Store

        took: dict = {}
        took["wall"] = infer_alone({"store": Store(args.infer_alone / "store")}, args.infer_alone, SIGMAS[args.sigmas], took)
        print(json.dumps(took))
        return
    if args.run_phases:
        run_phases(args.rounds, args.old, console)
        return
    if args.image_path:
        image_path(args.rounds, args.old, console)
        return
    if args.image_path_paired:
        image_path_paired(args.rounds, console)
        return
    if args.post_alone:
        print(json.dumps(post_alone(args.post_alone, args.workers)))
        return
    if args.post_heavy and args.cores:
        post_heavy_cores(args.rounds, args.objects, [int(k) for k in args.cores.split(",")], console)
        return
    if args.post_heavy:
        post_heavy(args.rounds, args.objects, args.old, console)
        return
    if args.multi_scene:
        multi_scene(args.rounds, console)
        return
    with tempfile.TemporaryDirectory(prefix="sweep3d-bench-", dir="/dev/shm" if Path("/dev/shm").is_dir() else None) as tmp:
        tmp = Path(tmp)
        for sub in ("bare", "cold", "pipe", "noop"):
            (tmp / sub).mkdir()
        console.print("bare bpy loop ...")
        bare = bare_loop(args.renders, tmp / "bare")
        console.print("one process per render ...")
        cold = cold_start(args.cold, tmp / "cold")
        console.print("sweep3d run ...")
        pipe = pipeline(args.renders, tmp / "pipe")
        console.print("no-op rerun ...")
        noop = noop_rerun(args.cached, tmp / "noop")

    n = args.renders
    bare_rate = n / bare["wall"]
    bare_loop_rate = n / bare["loop"]
    render_rate = n / pipe["stages"]["render"]
    e2e_rate = n / pipe["wall"]
    table = Table(title=f"sweep3d pipeline benchmarks ({n} renders at {SETTINGS['resolution']}², "
                        f"{SETTINGS['samples']} spp + OIDN fast, one scene)")
    for column in ("measure", "value", "target", "met"):
        table.add_column(column, justify="right" if column != "measure" else "left")

    def row(name: str, value: str, target: str = "", met: bool | None = None) -> None:
        table.add_row(name, value, target, "" if met is None else ("yes" if met else "NO"))

    row("bare bpy loop, whole process (img/s)", f"{bare_rate:.2f}")
    row("bare bpy loop, render loop only (img/s)", f"{bare_loop_rate:.2f}")
    row("sweep3d render stage (img/s)", f"{render_rate:.2f}")
    row("1. render stage / bare process", f"{render_rate / bare_rate:.2f}", "≥ 0.85", render_rate / bare_rate >= 0.85)
    row("   render stage / bare loop only", f"{render_rate / bare_loop_rate:.2f}")
    row("   whole run incl. model load + inference (img/s)", f"{e2e_rate:.2f}")
    row("2. render stage / one process per render", f"{render_rate * cold:.1f}×", "≥ 5×", render_rate * cold >= 5)
    row(f"3. no-op rerun of {noop['jobs']:,} cached jobs (s, CLI wall)", f"{noop['wall']:.2f}", "≤ 5", noop["wall"] <= 5)
    total = pipe["wall"]
    for stage in ("render", "postprocess", "infer"):  # the stages overlap: their shares add up to more than 100 %
        row(f"4. stage time / wall: {stage}", f"{pipe['stages'][stage] / total:.0%}")
    row("4. share of wall: store I/O (inside the stages)", f"{pipe['store_io'] / total:.1%}")
    row("4. share of wall outside the render stage (plan, model load, last batch)",
        f"{1 - pipe['stages']['render'] / total:.0%}")
    row("5. peak memory per render worker (MB)", f"{pipe['worker_peak_mb']:.0f}")
    row("5. peak memory of the parent (MB, model + store)", f"{pipe['parent_peak_mb']:.0f}")
    console.print(table)


if __name__ == "__main__":
    main()
