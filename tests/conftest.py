"""Shared fixtures: tiny specs with generated meshes, and one real end-to-end run per session.

The real run renders with Blender (32×32 pixels, 1 sample) and classifies with the real
pretrained model, so tests that read results exercise the whole pipeline, not a stand-in.

The fast lane (``pytest -m fast``): every test without a ``blender``, ``browser``, ``slow`` or
``torch`` marker is marked ``fast`` here (a test using ``tiny_run``, ``tiny_copy`` or
``blender_scene`` gets those markers from its fixtures). In the lane, importing ``torch`` or
``bpy`` fails the importing test (with its import chain) and the session, starting a render
worker fails the test, and property tests run the ``fast`` Hypothesis profile (those that set
their own ``max_examples`` go through :func:`examples`).

The suite runs in two processes (pytest-xdist, ``-n 2`` in pyproject's addopts; the fast lane too:
each process installs the guard in ``pytest_configure``, before it collects). ``scripts/test.sh`` runs
the lane under its guard, then the rest, as CI does. Once per process: one headless Chromium
(``chromium``); once per test run, whatever the processes: one ONNX export per model
(``_one_onnx_export_per_model``). The ``soak`` lane (the 20-kill soak) is left out of the default
run by pyproject's addopts; ``pytest -m soak`` runs it.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
import traceback
from pathlib import Path

import pytest
from hypothesis import settings as hypothesis_settings

from tests.helpers import CHROMIUM, CHROMIUM_ARGS, REPO, STORE_ALL, TINY_SPEC, write_cube, write_spec

if os.environ.get("PYTEST_XDIST_WORKER"):
    # xdist's workers start with COLUMNS=80 and LINES=24 set, which would fix the width of the CLI's
    # consoles when they are made (at import): tests set the width per call, as a terminal would
    os.environ.pop("COLUMNS", None)
    os.environ.pop("LINES", None)

#: Markers of tests that need more than plain Python (the rest are marked ``fast``).
HEAVY = ("blender", "browser", "slow", "torch")
#: Markers implied by the fixtures a test uses (directly or through other fixtures).
FIXTURE_MARKERS = {
    "tiny_run": ("slow", "blender", "torch"),  # a real `sweep3d run`: renders and classifies
    "tiny_copy": ("slow", "blender", "torch"),
    "ray_cluster": ("slow",),  # a follow-up on --executor ray: a one-node Ray cluster on loopback
    "blender_scene": ("blender",),
    "parts_run": ("slow", "blender", "torch"),  # test_part_visibility: a real run with the UV pass
    "truth_run": ("slow", "blender", "torch"),  # test_truth: a real run with the mask and depth passes
    "export_run": ("slow", "blender", "torch"),  # test_export: a real detection run with the mask pass
    "lite0": ("torch",),  # test_infer: the pretrained model
    "large_report": ("slow",),  # test_report_scale: a synthetic store of 10 000 results and its report
    "chromium": ("browser",),  # the session's headless Chromium
}
#: Modules the fast lane must never import.
LANE_FORBIDDEN = ("torch", "bpy")

hypothesis_settings.register_profile("full")  # Hypothesis' defaults: the strength of a full run
hypothesis_settings.register_profile("fast", max_examples=20)
LANE_SHARE = 0.2  # fast profile's max_examples / the default's 100

#: True while the session selects the fast lane (set in pytest_configure, before test modules import).
LANE = False


def _selects_lane(markexpr: str) -> bool:
    return bool(re.search(r"\bfast\b", markexpr)) and not re.search(r"\bnot\s+fast\b", markexpr)


class _LaneGuard:
    """A ``sys.meta_path`` finder that refuses ``torch`` and ``bpy`` and remembers who asked."""

    def __init__(self) -> None:
        self.test = "(collection)"  # the node id of the running test
        self.imports: dict[str, list[str]] = {}  # test -> what it tried, with the import chain

    def record(self, what: str, chain: str) -> None:
        self.imports.setdefault(self.test, []).append(f"{what}: {chain}")

    def find_spec(self, name, path=None, target=None):
        top = name.partition(".")[0]
        if top not in LANE_FORBIDDEN or not _importing():  # importlib.util.find_spec only locates
            return None
        chain = _chain(traceback.extract_stack()[:-1])
        self.record(f"imported {top}", chain)
        raise ImportError(f"the fast lane does not import {top} (mark the test {'torch' if top == 'torch' else 'blender'}"
                          f" if it needs it); import chain: {chain}", name=name)


def _importing() -> bool:
    """Whether the finder was asked by an import, not by ``importlib.util.find_spec`` (which only locates)."""
    frame = sys._getframe(2)
    while frame is not None:
        code = frame.f_code
        if code.co_name == "_find_and_load_unlocked":
            return True
        if code.co_name == "find_spec" and "importlib" in code.co_filename and "util" in code.co_filename:
            return False
        frame = frame.f_back
    return False


def _chain(stack: traceback.StackSummary) -> str:
    """The frames of this repository (and the direct importer), outermost first."""
    frames = [f for f in stack if "importlib" not in f.filename and "_pytest" not in f.filename
              and "pluggy" not in f.filename]
    keep = [f for f in frames if f.filename.startswith(str(REPO))]
    if frames and (not keep or frames[-1] is not keep[-1]):
        keep.append(frames[-1])
    return " -> ".join(f"{_short(f.filename)}:{f.lineno} {f.name}" for f in keep) or "(unknown)"


def _short(filename: str) -> str:
    path = Path(filename)
    if path.is_relative_to(REPO):
        return str(path.relative_to(REPO))
    parts = path.parts
    return "/".join(parts[parts.index("site-packages") + 1:]) if "site-packages" in parts else filename


def _refuse_workers(guard: _LaneGuard) -> None:
    """Starting a render worker (which imports bpy in a child process) fails the test in the lane;
    a post-processing worker (a :class:`Child` running ``stages.postprocess``' code) is allowed,
    and so is the interpreter ``sweep3d run`` starts ahead (``stages.render.early``, a Child with
    no work yet): only a render pool, refused here, would give it any."""
    import multiprocessing.context

    def refuse(what: str, allowed=None):
        def start(*args, **kwargs):
            if allowed is not None and _post_worker(*args, **kwargs):
                return allowed(*args, **kwargs)
            guard.record(f"started {what}", _chain(traceback.extract_stack()[:-1]))
            pytest.fail(f"the fast lane starts no {what}: render workers import bpy (mark the test blender)",
                        pytrace=False)
        return start

    multiprocessing.context.SpawnProcess.start = refuse("spawned process")
    for module, cls in (("sweep3d.stages.render.child", "Child"), ("sweep3d.stages.render.pool", "RenderPool"),
                        ("sweep3d.stages.render.ray_pool", "RayRenderPool")):
        try:
            target = getattr(__import__(module, fromlist=[cls]), cls)
        except (ImportError, AttributeError):
            continue  # moved: the guards left still cover local workers
        target.__init__ = refuse(cls, target.__init__ if cls == "Child" else None)


def _post_worker(child, target=None, *args, **kwargs) -> bool:
    """Whether a :class:`Child` is to run a post-processing worker (numpy and the post controls, no
    bpy), or nothing yet (started ahead: see :func:`_refuse_workers`)."""
    return target is None or getattr(target, "__module__", "").startswith("sweep3d.stages.postprocess.")


_GUARD = pytest.StashKey[_LaneGuard]()


def pytest_configure(config: pytest.Config) -> None:
    global LANE
    LANE = _selects_lane(config.getoption("markexpr") or "")
    if LANE and not config.getoption("hypothesis_profile", None):
        hypothesis_settings.load_profile("fast")
    if LANE:
        loaded = [m for m in LANE_FORBIDDEN if m in sys.modules]
        if loaded:
            raise pytest.UsageError(f"the fast lane needs a process without {', '.join(loaded)} imported")
        guard = _LaneGuard()
        sys.meta_path.insert(0, guard)
        _refuse_workers(guard)
        config.stash[_GUARD] = guard


@pytest.hookimpl(tryfirst=True)  # before `-m` deselects by marker
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        for fixture, markers in FIXTURE_MARKERS.items():
            if fixture in item.fixturenames:
                for marker in markers:
                    if item.get_closest_marker(marker) is None:
                        item.add_marker(marker)
        if not any(item.get_closest_marker(marker) for marker in HEAVY):
            item.add_marker("fast")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem):
    guard = item.config.stash.get(_GUARD, None)
    if guard is not None:
        guard.test = item.nodeid
    try:
        return (yield)
    finally:
        if guard is not None:
            guard.test = "(between tests)"


@pytest.fixture(autouse=True)
def _lane_guard(request: pytest.FixtureRequest):
    """In the fast lane, a test that tried to import torch or bpy fails even if the ImportError was caught."""
    yield
    guard = request.config.stash.get(_GUARD, None)
    if guard is not None and request.node.nodeid in guard.imports:
        pytest.fail("in the fast lane this test " + "; ".join(guard.imports[request.node.nodeid]), pytrace=False)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    guard = session.config.stash.get(_GUARD, None)
    if guard is not None and guard.imports and exitstatus == 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter, exitstatus: int, config: pytest.Config) -> None:
    guard = config.stash.get(_GUARD, None)
    if guard is None:
        return
    if guard.imports:
        terminalreporter.section("fast lane: torch / bpy / render workers", red=True)
        for test, what in guard.imports.items():
            for line in what:
                terminalreporter.line(f"{test}: {line}")
    else:
        terminalreporter.line("fast lane: no test imported torch or bpy or started a render worker")


@pytest.fixture(scope="session", autouse=True)
def _one_user_cache_per_test_run(tmp_path_factory):
    """The user's cache folder (``SWEEP3D_CACHE``: ONNX exports and their checks) is one folder of
    this test run, shared by its worker processes and the ``python -m sweep3d`` children they
    start: a fresh store then takes its model's export from it, as a user's does (EfficientNet-Lite0's
    export takes 2-3 s on 2 cores), and no test writes into the real ``~/.cache``."""
    base = tmp_path_factory.getbasetemp()
    folder = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "user_cache"
    folder.mkdir(exist_ok=True)
    before = os.environ.get("SWEEP3D_CACHE")
    os.environ["SWEEP3D_CACHE"] = str(folder)
    try:
        yield folder
    finally:
        if before is None:
            os.environ.pop("SWEEP3D_CACHE", None)
        else:
            os.environ["SWEEP3D_CACHE"] = before


@pytest.fixture(scope="session")
def chromium():
    """One headless Chromium per test process (the system's, ``/usr/bin/chromium``, driven by Playwright);
    each page opens in a fresh browser context (its own cookies, storage and cache), see
    ``tests.report.test_report.open_page``. Skips the test where Chromium or Playwright is missing."""
    if not CHROMIUM.exists():
        pytest.skip(f"headless Chromium not found at {CHROMIUM}; install it with: apt-get install chromium")
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
    playwright = sync_api.sync_playwright().start()
    try:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()
    finally:
        playwright.stop()












@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory) -> Path:
    """A folder holding ``spec.toml`` and its store after one real ``sweep3d run`` (8 jobs; every
    image stored)."""
    from typer.testing import CliRunner

    from sweep3d.cli import app

    folder = tmp_path_factory.mktemp("tiny_run")
    spec = write_spec(folder, TINY_SPEC + STORE_ALL)
    result = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert result.exit_code == 0, result.output
    return folder


@pytest.fixture
def tiny_copy(tiny_run: Path, tmp_path: Path) -> Path:
    """A private copy of the tiny run's folder (spec, mesh and store) that a test may change."""
    target = tmp_path / "run"
    shutil.copytree(tiny_run, target)
    return target


@pytest.fixture(scope="session")
def blender_scene(tmp_path_factory):
    """One Blender scene per test session (bpy holds one scene per process), 32×32, 1 sample,
    with ``.cube`` the path of a cube mesh. Tests call ``prepare`` for the object they need."""
    from sweep3d.stages.render.cycles.scene import BlenderScene
    from sweep3d.stages.render.worker_protocol import RenderSettings

    folder = tmp_path_factory.mktemp("scene")
    scene = BlenderScene(RenderSettings(resolution=32, samples=1, denoise=False), folder)
    scene.cube = str(write_cube(folder))
    return scene




@pytest.fixture(scope="module")
def ray_cluster():
    """A one-node Ray cluster bound to 127.0.0.1, for a module's tests (they never talk to another
    address); skipped where Ray is not installed."""
    ray = pytest.importorskip("ray")
    ray.init(_node_ip_address="127.0.0.1", include_dashboard=False, num_cpus=2, log_to_driver=False)
    yield
    ray.shutdown()
