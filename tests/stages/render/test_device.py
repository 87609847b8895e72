"""``[render] device`` (CPU, CUDA, OptiX; auto) and render workers recycled between jobs
(``[render] worker_memory``, ``worker_jobs``).

Planning and the small pieces run in the fast lane, whatever GPUs the machine has (the probe is
replaced); what needs Blender renders a handful of 32-pixel jobs.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from sweep3d.core.errors import UserError
from sweep3d.core.pixels import decode_png
from sweep3d.spec.models import RenderSpec
from sweep3d.stages.render import device as device_module
from sweep3d.stages.render.device import device_note, resolve_device, worker_count
from sweep3d.stages.render.render_stage import recycled_note
from sweep3d.stages.render.worker import resident_mb
from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob, RenderSettings, WorkerLimits
from tests.helpers import REPO, TINY_SPEC, load_spec, plan_for, write_spec

NO_GPU: dict[str, int] = {}
TWO_GPUS = {"optix": 2, "cuda": 2}


def with_render(extra: str) -> str:
    """The tiny spec with ``extra`` lines added to its [render] table."""
    return TINY_SPEC.replace("denoise = false\n", f"denoise = false\n{extra}\n")


def plan_with(folder: Path, extra: str = ""):
    """Plan the tiny spec with ``extra`` [render] lines, in a fresh subfolder (no model loaded)."""
    sub = folder / f"spec{len(list(folder.iterdir()))}"
    sub.mkdir()
    return plan_for(load_spec(write_spec(sub, with_render(extra))), "model-x")


def render_keys(plan) -> list[str]:
    return [job.render_key for job in plan.jobs]


@pytest.fixture
def gpus(monkeypatch):
    """Set what the device probe finds (it is never run)."""
    def found(what: dict[str, int]) -> None:
        monkeypatch.setattr(device_module, "probe", lambda: what)
    found(NO_GPU)
    return found


# -- keys ----------------------------------------------------------------------------------------

def test_auto_without_a_gpu_keys_its_renders_as_cpu_and_as_a_spec_without_device(tmp_path, gpus) -> None:
    plain = plan_with(tmp_path)
    auto, cpu = plan_with(tmp_path, 'device = "auto"'), plan_with(tmp_path, 'device = "cpu"')
    assert plain.device == auto.device == cpu.device == "cpu"
    assert render_keys(auto) == render_keys(cpu) == render_keys(plain)
    assert [j.pred_key for j in auto.jobs] == [j.pred_key for j in plain.jobs]


def test_a_gpu_is_in_the_render_key_and_auto_keys_by_the_gpu_it_finds(tmp_path, gpus) -> None:
    cpu = render_keys(plan_with(tmp_path, 'device = "cpu"'))
    cuda, optix = render_keys(plan_with(tmp_path, 'device = "cuda"')), render_keys(plan_with(tmp_path, 'device = "optix"'))
    assert len(set(cpu) | set(cuda) | set(optix)) == 3 * len(set(cpu))  # GPU Cycles: other pixels, other keys
    gpus(TWO_GPUS)
    auto = plan_with(tmp_path, 'device = "auto"')
    assert auto.device == "optix" and render_keys(auto) == optix
    gpus({"optix": 0, "cuda": 1})
    assert resolve_device("auto") == "cuda"


def test_worker_recycling_settings_are_not_in_render_keys(tmp_path, gpus) -> None:
    base = render_keys(plan_with(tmp_path))
    assert render_keys(plan_with(tmp_path, "worker_memory = 1\nworker_jobs = 1")) == base
    assert render_keys(plan_with(tmp_path, "worker_memory = 0")) == base


def test_timeouts_are_not_in_render_keys_and_must_be_finite_seconds(tmp_path, gpus) -> None:
    import pydantic

    from sweep3d.spec.models import RenderSpec

    base = render_keys(plan_with(tmp_path))
    assert render_keys(plan_with(tmp_path, "timeout = 5\nedit_timeout = 1")) == base
    assert (RenderSpec().timeout, RenderSpec().edit_timeout) == (600, 60)
    for bad in (0, -1, float("inf")):
        with pytest.raises(pydantic.ValidationError):
            RenderSpec(edit_timeout=bad)


def test_a_gpu_run_has_one_worker_per_gpu_unless_workers_is_set(gpus) -> None:
    gpus({"optix": 3, "cuda": 3})
    assert worker_count(RenderSpec(device="optix"), "optix") == 3
    assert worker_count(RenderSpec(), "optix") == 3  # auto resolved to OptiX
    assert worker_count(RenderSpec(workers=1), "optix") == 1
    assert worker_count(RenderSpec(workers=2), "cpu") == 2 and worker_count(RenderSpec(), "cpu") == 1
    gpus(NO_GPU)
    assert worker_count(RenderSpec(device="cuda"), "cuda") == 1  # its worker says what is wrong


def test_the_probe_starts_no_process_without_an_nvidia_driver(monkeypatch) -> None:
    monkeypatch.setattr(device_module, "DRIVER_PATHS", (os.devnull + "-absent",))
    monkeypatch.setattr(device_module.subprocess, "run", lambda *a, **k: pytest.fail("the probe ran"))
    device_module.probe.cache_clear()
    try:
        assert device_module.probe() == {} and resolve_device("auto") == "cpu"
    finally:
        device_module.probe.cache_clear()


def test_the_probe_reads_the_childs_gpu_counts_and_the_capabilities_it_must_compile(monkeypatch) -> None:
    import subprocess

    line = '{"optix": 2, "cuda": 2, "compiles": ["9.0"], "other": 7}'
    monkeypatch.setattr(device_module, "DRIVER_PATHS", (os.devnull,))
    monkeypatch.setattr(device_module.subprocess, "run",
                        lambda *a, **k: subprocess.CompletedProcess(a, 0, f"Blender says hello\n{line}\n", ""))
    device_module.probe.cache_clear()
    try:
        assert device_module.probe() == {"optix": 2, "cuda": 2, "compiles": ["9.0"]}
        assert resolve_device("auto") == "optix" and device_module.gpu_count("cuda") == 2
    finally:
        device_module.probe.cache_clear()


def test_a_run_says_once_that_auto_renders_on_the_cpu_and_only_when_it_renders(tmp_path, gpus) -> None:
    from sweep3d.runner.pipeline import _note_device

    auto, cpu = plan_with(tmp_path), plan_with(tmp_path, 'device = "cpu"')
    console = Console(record=True, width=400)
    _note_device([auto], {32: 0}, console)  # everything stored: nothing to say
    _note_device([cpu], {32: 4}, console)  # asked for: nothing to say
    assert console.export_text() == ""
    _note_device([auto, auto], {32: 4}, console)
    (line,) = console.export_text().splitlines()
    assert line == f"note: {device_note(RenderSpec(), 'cpu')}" and 'render.device = "auto"' in line
    assert device_note(RenderSpec(), "optix") is None
    # Mitsuba renders on the CPU whatever auto finds: Cycles' GPU is nothing to it
    assert device_note(RenderSpec(engine="mitsuba"), "cpu") is None


@pytest.mark.parametrize("device, backend", [("cuda", "CUDA"), ("optix", "OptiX")])
def test_plan_says_in_one_line_that_a_gpu_named_outright_is_not_here(tmp_path, gpus, device, backend) -> None:
    """A run would find out only as its first worker starts; plan says so, and what a run would do."""
    from typer.testing import CliRunner

    from sweep3d.cli import app

    spec = write_spec(tmp_path, with_render(f'device = "{device}"'))
    result = CliRunner().invoke(app, ["plan", str(spec)], terminal_width=400)
    assert result.exit_code == 0, result.output  # a plan for another machine is no mistake
    (line,) = [line for line in result.output.splitlines() if "warning:" in line]
    assert line == (f'warning: render.device = "{device}": no {backend} GPU here (Cycles finds none); sweep3d run here '
                    'would stop with an error before its 4 renders; run it on a machine with one, or set device = '
                    '"auto" (the best GPU back-end that works, else the CPU) or "cpu"')
    gpus(TWO_GPUS)
    assert "warning:" not in CliRunner().invoke(app, ["plan", str(spec)], terminal_width=400).output
    assert device_module.missing_gpu_warning("auto", 4) is None and device_module.missing_gpu_warning("cpu", 4) is None
    gpus(NO_GPU)
    assert "every render is cached" in device_module.missing_gpu_warning(device, 0)


def test_a_gpu_blender_ships_no_kernel_for_is_said_before_rendering(tmp_path, gpus) -> None:
    from sweep3d.runner.pipeline import _note_device

    optix = plan_with(tmp_path, 'device = "optix"')
    console = Console(record=True, width=400)
    gpus({"optix": 1, "cuda": 1, "compiles": []})  # a GPU Blender has kernels for: nothing to say
    _note_device([optix], {32: 4}, console)
    assert console.export_text() == ""
    gpus({"optix": 1, "cuda": 1, "compiles": ["9.0"]})
    _note_device([optix], {32: 0}, console)  # nothing to render: nothing compiles
    _note_device([plan_with(tmp_path, 'device = "cpu"')], {32: 4}, console)
    assert console.export_text() == ""
    _note_device([optix], {32: 4}, console)
    (line,) = console.export_text().splitlines()
    assert line.startswith('note: render.device = "optix": Blender ships no CUDA kernel for this GPU (compute '
                           'capability 9.0)') and "CUDA_CACHE_PATH" in line


def test_capabilities_without_a_shipped_cubin_are_the_ones_the_driver_compiles(tmp_path) -> None:
    from sweep3d.stages.render.cycles.gpus import uncompiled

    for name in ("kernel_sm_86.cubin.zst", "kernel_sm_120.cubin.zst", "kernel_compute_75.ptx.zst",
                 "kernel_optix.ptx.zst"):
        (tmp_path / name).write_bytes(b"")
    assert uncompiled(["8.6", "9.0", "12.0", "8.7", "9.0"], tmp_path) == ["8.7", "9.0"]
    assert uncompiled([], tmp_path) == []


@pytest.mark.blender  # starts render pools (their workers import bpy)
def test_a_gpu_workers_first_job_may_compile_kernels_and_its_cache_is_sized(tmp_path, monkeypatch) -> None:
    from sweep3d.stages.render.pool import RenderPool, _Worker

    monkeypatch.delenv("CUDA_CACHE_MAXSIZE", raising=False)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    first, later = _Worker(None, None, 0), _Worker(None, None, 0, rendered=1)
    with RenderPool(RenderSettings(resolution=32), timeout=5) as cpu:
        assert cpu.allowed(first) == cpu.allowed(later) == 5
    assert "CUDA_CACHE_MAXSIZE" not in os.environ
    with RenderPool(RenderSettings(resolution=32, device="optix"), timeout=5) as gpu:
        assert gpu.allowed(first) == 5 + device_module.KERNEL_GRACE and gpu.allowed(later) == 5
    assert os.environ["CUDA_CACHE_MAXSIZE"] == str(4 * 2**30)
    monkeypatch.setenv("CUDA_CACHE_MAXSIZE", "1000")  # the user's own size is kept
    with RenderPool(RenderSettings(resolution=32, device="cuda"), timeout=5):
        assert os.environ["CUDA_CACHE_MAXSIZE"] == "1000"


# -- worker limits -------------------------------------------------------------------------------

def test_worker_limits_are_reached_after_a_job_by_memory_or_by_count() -> None:
    assert WorkerLimits().reached(10**6, 10.0**6) is None
    assert WorkerLimits(memory_mb=100).reached(1, 101.0) == "memory"
    assert WorkerLimits(memory_mb=100).reached(1, 99.0) is None
    assert WorkerLimits(memory_mb=100).reached(1, None) is None  # no /proc: not checked
    assert WorkerLimits(jobs=2).reached(1, 5.0) is None and WorkerLimits(jobs=2).reached(2, 5.0) == "jobs"
    assert WorkerLimits.from_spec(RenderSpec()) == WorkerLimits(memory_mb=4096, jobs=0)


def test_resident_memory_is_read_from_proc() -> None:
    if not Path("/proc/self/statm").exists():
        pytest.skip("no /proc here: the memory limit is not checked")
    assert 1.0 < resident_mb() < 1e6
    assert resident_mb(2**22 + 1) is None  # no such process


def test_the_recycling_note_says_how_many_workers_were_replaced_and_why() -> None:
    spec = RenderSpec(worker_memory=1, worker_jobs=3)
    line = recycled_note(spec, Counter(memory=3, jobs=1))
    assert line.startswith("note: 4 render workers were replaced by a fresh one between jobs ")
    assert "3 holding more than render.worker_memory = 1 MB" in line and "1 after render.worker_jobs = 3 jobs" in line
    assert "\n" not in line


def test_onnx_runtime_asks_for_cuda_first_only_where_it_has_it() -> None:
    from sweep3d.stages.infer.onnx_backend import providers

    assert providers(["CPUExecutionProvider"]) == ["CPUExecutionProvider"]
    assert providers(["CUDAExecutionProvider", "CPUExecutionProvider"]) == ["CUDAExecutionProvider",
                                                                            "CPUExecutionProvider"]


# -- with Blender --------------------------------------------------------------------------------

@pytest.mark.blender
def test_a_gpu_blender_cannot_find_is_one_user_error_naming_render_device(blender_scene) -> None:
    from sweep3d.stages.render.device import use_device

    for device in ("cuda", "optix"):
        if device_module.gpu_count(device):
            continue  # this machine has one
        with pytest.raises(UserError, match=rf'^render\.device = "{device}": Cycles finds no .* "cpu"$'):
            use_device(blender_scene.bpy, blender_scene.scene, device)
        assert blender_scene.scene.cycles.device == "CPU"


@pytest.mark.blender
def test_workers_recycled_between_jobs_render_every_job_once_and_the_same_pixels(tmp_path: Path) -> None:
    from sweep3d.stages.render.pool import RenderPool
    from tests.helpers import write_cube

    cube = str(write_cube(tmp_path))
    colours = [(1.0, 1.0, 1.0), (0.5, 0.5, 0.5), (0.2, 0.4, 0.8), (0.9, 0.3, 0.1)]
    settings = RenderSettings(resolution=32, samples=1, denoise=False)
    pixels = {}
    for name, limits in (("plain", WorkerLimits()), ("memory", WorkerLimits(memory_mb=1)), ("jobs", WorkerLimits(jobs=1))):
        folder = tmp_path / name
        folder.mkdir()
        jobs = [RenderJob(f"k{i}", cube, EnvironmentRef(color=c), blob=str(folder / f"k{i}.png"))
                for i, c in enumerate(colours)]
        with RenderPool(settings, workers=1, timeout=120, limits=limits) as pool:
            replies = list(pool.run([jobs[:3], jobs[3:]]))  # recycled within a list and between lists
            recycled = dict(pool.recycled)
        assert sorted(r.render_key for r in replies) == [j.render_key for j in jobs], name  # each once
        assert all(r.ok for r in replies), [r.error for r in replies]
        assert recycled == ({} if name == "plain" else {name: len(jobs)}), recycled  # after every job
        pixels[name] = np.stack([decode_png(j.blob) for j in jobs])
    for name in ("memory", "jobs"):  # renders in other processes: one 8-bit level apart at most
        assert np.abs(pixels[name] - pixels["plain"]).max() <= 1.5 / 255, name


@pytest.mark.slow
def test_auto_reuses_a_cpu_runs_renders_and_an_absent_gpu_is_one_line_exit_2_rendering_nothing(tiny_copy) -> None:
    from typer.testing import CliRunner

    from sweep3d.cache.store import Store
    from sweep3d.cli import app

    spec = tiny_copy / "spec.toml"
    renders = Store(tiny_copy / "store").keys("renders")
    spec.write_text(spec.read_text().replace("denoise = false\n", 'denoise = false\ndevice = "auto"\n'))
    if device_module.resolve_device("auto") == "cpu":  # no GPU here: the tiny run's renders are auto's
        result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
        assert result.exit_code == 0, result.output
        assert "note:" not in result.output  # nothing rendered: nothing to say about the device
        assert Store(tiny_copy / "store").keys("renders") == renders
    if device_module.gpu_count("cuda"):
        pytest.skip("this machine has a CUDA GPU")
    spec.write_text(spec.read_text().replace('device = "auto"', 'device = "cuda"'))
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    (line,) = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert line.startswith('error: render.device = "cuda": Cycles finds no CUDA GPU') and '"cpu"' in line, line
    assert Store(tiny_copy / "store").keys("renders") == renders  # nothing rendered


def test_the_gpu_benchmark_table_rates_renders_after_the_first_and_compares_pixels_with_the_cpu(tmp_path) -> None:
    """The benchmark's report step, run as its users run it (``python benchmarks/gpu.py report``)."""
    from PIL import Image

    for run, level in (("cpu-1", 100), ("cuda-1", 103)):
        (tmp_path / run).mkdir()
        for key in ("a", "b"):
            Image.fromarray(np.full((4, 4, 4), level, np.uint8)).save(tmp_path / run / f"{key}.png")
        device = run.split("-")[0]
        (tmp_path / f"{run}.json").write_text(
            f'Blender 4.5 says hello\n{{"setup": 2.0, "first": 1.0, "loop": 11.0, "n": 21, "device": "{device}"}}\n')
    out = subprocess.run([sys.executable, str(REPO / "benchmarks" / "gpu.py"), "report", str(tmp_path)],
                         capture_output=True, text=True, check=True, cwd=REPO).stdout
    rows = [line for line in out.splitlines() if line.startswith("| c")]
    assert rows == ["| cpu-1 | 2.0 | 1.00 | 2.0 | 11.0 | – |",
                    "| cuda-1 | 2.0 | 1.00 | 2.0 | 11.0 | 3.00 (max 3.00, 2 frames) |"]
