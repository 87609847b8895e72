"""Planning, no-op reruns and queries at up to 10⁶ jobs (issue: planning and reruns at scale).

Prints one table: for each size, `sweep3d plan` (CLI wall and peak RSS, and `make_plan` alone
in-process), then a no-op `sweep3d run` over a store holding every job cached (the first
rerun, and the second: the steady state, which reads back the findings and, where the
checkout has them, the outcomes the first stored), a GROUP BY over the results view, and in-process the
findings computed afresh (`summarise`) and read back (`stored_summary`).

    .venv/bin/python benchmarks/plan_scale.py [--plan 1e4 1e5 1e6] [--noop 1e6] [--repo PATH]

The first no-op run is the first after the store was written: where the checkout's passes
record the blobs they write as verified, the synthetic store's blobs are recorded so too (so the
first run hashes none); the second finds its outcomes read back (``runner.settled``).

``--repo`` times another checkout of sweep3d (e.g. an older commit unpacked with `git archive`);
its CLI runs with that checkout first on PYTHONPATH. The plan spec: 2 objects × 2 environments,
yaw, elevation, log zoom and horizontal position as ranges (some jobs land out of frame), blur
with 2 values; the grid's samples per dimension are picked for the nearest count to the target.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

SPEC = """
[experiment]
name = "scale"
seed = 0
store = "store"
max_jobs = 20000000

[render]
resolution = 64
samples = 1

[[objects]]
name = "cube"
mesh = "cube.obj"
labels = ["basketball"]
{more_objects}
[[environments]]
name = "white"
color = [1.0, 1.0, 1.0]
{more_environments}
[[controls]]
type = "orientation"
yaw = {{ range = [-180, 180] }}
{pitch}
{grid_controls}
[policy]
{policy}
"""

GRID_CONTROLS = """
[[controls]]
type = "camera"
elevation = { range = [-30, 60] }
zoom = { range = [0.5, 4], log = true }

[[controls]]
type = "position"
x = { range = [-1.5, 1.5] }

[[controls]]
type = "blur"
sigma = [0.0, 2.0]
"""

MORE_OBJECTS = '\n[[objects]]\nname = "cube2"\nmesh = "cube.obj"\nlabels = ["soccer ball"]\n'
MORE_ENVIRONMENTS = '\n[[environments]]\nname = "grey"\ncolor = [0.5, 0.5, 0.5]\n'
CUBE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"

#: Runs the CLI in a child and reports its peak resident memory on the last line of stderr.
CLI = """
import resource, runpy, sys
sys.argv = ["sweep3d", *sys.argv[1:]]
try:
    runpy.run_module("sweep3d", run_name="__main__")
except SystemExit as exc:
    code = exc.code
else:
    code = 0
usage = resource.getrusage(resource.RUSAGE_SELF)
print("MAXRSS", usage.ru_maxrss, code, usage.ru_utime + usage.ru_stime, file=sys.stderr)
"""

#: Times make_plan (and the jobs table it writes) in a fresh child, apart from start-up.
IN_PROCESS = """
import json, resource, sys, time
from sweep3d.runner.pipeline import plan_spec
import sweep3d
spec = sweep3d.load(sys.argv[1]).spec
t, c = time.perf_counter(), time.process_time()
plan = plan_spec(spec)
planned, planned_cpu = time.perf_counter() - t, time.process_time() - c
t = time.perf_counter()
table = plan.table()
tabled = time.perf_counter() - t
print(json.dumps({"jobs": table.num_rows, "in_frame": len(plan.jobs), "plan": planned, "plan_cpu": planned_cpu, "table": tabled,
                  "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def grid_spec(target: int) -> tuple[str, int]:
    """A grid spec of about ``target`` jobs, and its exact count (4 scenes × n⁴ × 2 blurs)."""
    n = max(1, round((target / 8) ** 0.25))
    policy = f'type = "grid"\nsamples_per_dim = {n}'
    text = SPEC.format(more_objects=MORE_OBJECTS, more_environments=MORE_ENVIRONMENTS, pitch="",
                       grid_controls=GRID_CONTROLS, policy=policy)
    return text, 8 * n ** 4


def noop_spec(jobs: int) -> str:
    """One scene, yaw and pitch drawn at random, no post control: ``jobs`` renders and predictions."""
    return SPEC.format(more_objects="", more_environments="", pitch="pitch = { range = [-90, 90] }",
                       grid_controls="", policy=f'type = "random"\nsamples = {jobs}')


def child_env(repo: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(repo)}


def cli(repo: Path, folder: Path, *args: str) -> dict:
    """Wall seconds and peak RSS (MB) of one ``sweep3d`` command in a fresh interpreter."""
    started = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", CLI, *args], cwd=folder, env=child_env(repo),
                         capture_output=True, text=True)
    wall = time.perf_counter() - started
    last = out.stderr.strip().splitlines()[-1].split()
    if last[0] != "MAXRSS" or last[2] not in ("0", "None"):
        raise RuntimeError(f"sweep3d {' '.join(args)} failed:\n{out.stdout[-2000:]}\n{out.stderr[-3000:]}")
    return {"wall": wall, "cpu": float(last[3]), "maxrss_mb": int(last[1]) / 1024, "stdout": out.stdout}


def measure_plan(repo: Path, folder: Path, target: int) -> dict:
    text, jobs = grid_spec(target)
    (folder / "cube.obj").write_text(CUBE)
    (folder / "spec.toml").write_text(text)
    inside = subprocess.run([sys.executable, "-c", IN_PROCESS, "spec.toml"], cwd=folder, env=child_env(repo),
                            capture_output=True, text=True, check=True)
    result = json.loads(inside.stdout.strip().splitlines()[-1])
    assert result["jobs"] == jobs, (result, jobs)
    return {**result, "cli": cli(repo, folder, "plan", "spec.toml")}


def synthesise_store(folder: Path, jobs: int) -> None:
    """A store in which every job of :func:`noop_spec` is cached: tiny blobs, their rows, predictions."""
    import numpy as np
    import pyarrow as pa

    import sweep3d
    from sweep3d.cache.blobs import sha256_bytes
    from sweep3d.cache.store import DIGEST_COLUMN, Store, utc_now
    from sweep3d.core.pixels import encode_png
    from sweep3d.runner.pipeline import plan_spec
    from sweep3d.stages.infer import ClassificationEvaluator
    from sweep3d.stages.infer.infer_stage import predictions_schema
    from sweep3d.stages.render.render_stage import RENDERS_SCHEMA

    (folder / "cube.obj").write_text(CUBE)
    (folder / "spec.toml").write_text(noop_spec(jobs))
    plan = plan_spec(sweep3d.load(folder / "spec.toml").spec)
    store = Store(folder / "store")
    png = encode_png(np.zeros((8, 8, 3), np.float32))
    renders = [j.render_key for j in plan.jobs]
    for key in renders:  # plain writes: the store's fsync per blob would take minutes here
        path = store.blob_path(key)
        path.parent.mkdir(exist_ok=True, parents=True)
        path.write_bytes(png)
    now = utc_now()
    n = len(renders)
    store.write_table_file(store.table_dir("renders") / "seed.parquet", pa.table({
        "render_key": renders, "width": pa.array([8] * n, pa.int32()), "height": pa.array([8] * n, pa.int32()),
        "valid": [True] * n, "seconds": [0.0] * n, "created_at": pa.array([now] * n, pa.timestamp("us")),
        DIGEST_COLUMN: [sha256_bytes(png)] * n}, schema=RENDERS_SCHEMA))
    schema = predictions_schema(ClassificationEvaluator())
    columns = {"pred_key": [j.pred_key for j in plan.jobs], "image_key": renders, "model": ["m"] * n,
               "valid": [True] * n, "correct": [i % 3 != 0 for i in range(n)], "top1_label": ["basketball"] * n,
               "loss": [0.1] * n, "created_at": [now] * n}
    data = pa.table({name: pa.array(columns.get(name, [None] * n), schema.field(name).type) for name in schema.names},
                    schema=schema)
    store.write_table_file(store.table_dir("predictions") / "seed.parquet", data)
    try:  # as a run's passes record the blobs they write (absent in older checkouts: the first run hashes them)
        from sweep3d.cache.blobs import remember_verified, verified_now
    except ImportError:
        return
    remember_verified(store, "renders", {key: verified_now(store.blob_file(key)) for key in renders})


GROUP_BY = ("SELECT orientation_yaw > 0 AS right_side, count(*) AS jobs, avg(correct::INT) AS accuracy "
            "FROM results GROUP BY right_side ORDER BY right_side")

QUERY = """
import json, sys, time
from sweep3d.cache.store import Store
import sweep3d
from sweep3d.results import connect
spec = sweep3d.load("spec.toml").spec
t = time.perf_counter()
con = connect(Store(spec.store), spec.name, read_only=True)
opened = time.perf_counter() - t
t = time.perf_counter()
rows = con.execute(sys.argv[1]).fetchall()
queried = time.perf_counter() - t
from sweep3d.results import summarise
from sweep3d.results.views import stored_parameters
columns = stored_parameters(Store(spec.store).jobs_path(spec.name))
t, c = time.perf_counter(), time.process_time()
summarise(connect(Store(spec.store), spec.name), columns)
summary, summary_cpu = time.perf_counter() - t, time.process_time() - c
try:  # what `run` prints its findings from (absent in older checkouts)
    from sweep3d.results import stored_summary
except ImportError:
    stored = None
else:
    t = time.perf_counter()
    stored_summary(Store(spec.store), spec.name, columns)
    stored = time.perf_counter() - t
print("RESULT", json.dumps({"open": opened, "query": queried, "rows": sum(r[1] for r in rows),
                            "summary": summary, "summary_cpu": summary_cpu, "stored": stored}))
"""


def measure_noop(repo: Path, folder: Path, jobs: int, first_run: bool = True) -> dict:
    started = time.perf_counter()
    if not (folder / "store").exists():  # a --keep folder from an earlier run is used again
        synthesise_store(folder, jobs)
    setup = time.perf_counter() - started
    first = None
    if first_run:
        # The first rerun after the run that wrote the store: the blobs it wrote are in the memo of
        # verified blobs where the checkout's stages record them (else it hashes every blob), and
        # no run has found the store settled yet (it looks key by key).
        records = folder / "store" / "verified"
        if (Path(repo) / "sweep3d" / "runner" / "settled.py").exists():
            shutil.rmtree(records / "settled", ignore_errors=True)
        else:
            shutil.rmtree(records, ignore_errors=True)
        first = cli(repo, folder, "run", "spec.toml", "--no-report")
    second = cli(repo, folder, "run", "spec.toml", "--no-report")
    print("no-op run:", {k: v for k, v in second.items() if k != "stdout"}, flush=True)
    assert f"{jobs} jobs" in second["stdout"], second["stdout"]
    query = cli(repo, folder, "query", "spec.toml", GROUP_BY)
    inside = subprocess.run([sys.executable, "-c", QUERY, GROUP_BY], cwd=folder, env=child_env(repo),
                            capture_output=True, text=True, check=True)
    out = inside.stdout  # after DuckDB's progress bars, which end without a new line
    timing = json.loads(out[out.rindex("RESULT ") + 7:].splitlines()[0])
    assert timing["rows"] == jobs, timing
    return {"setup": setup, "first": first, "second": second, "query_cli": query, "query": timing}


def _usage(result: dict) -> tuple[str, str, str]:
    return f"{result['wall']:.1f} s", f"{result['cpu']:.1f} s", f"{result['maxrss_mb']:,.0f} MB"


#: The no-op rerun's goal at 10⁶ cached jobs (issue 46, item 4): first and steady, process start to exit.
NOOP_GOAL_S = 5.0


def _goal(result: dict, jobs: int) -> str:
    """The run's wall and CPU (the stat child's not counted) against the goal, which is set at 10⁶ jobs only."""
    if jobs != 1_000_000:
        return "goal set at 10⁶ jobs only"
    return f"{result['wall'] / NOOP_GOAL_S:.2f}× wall, {result['cpu'] / NOOP_GOAL_S:.2f}× CPU of the {NOOP_GOAL_S:g} s goal"


def count(text: str) -> int:
    return int(float(text))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plan", nargs="*", type=count, default=[10_000, 100_000, 1_000_000], help="plan sizes")
    parser.add_argument("--noop", nargs="*", type=count, default=[1_000_000], help="no-op rerun sizes")
    parser.add_argument("--repo", type=Path, default=REPO, help="the sweep3d checkout to time")
    parser.add_argument("--steady-only", action="store_true",
                        help="skip the first no-op run (the first after the store was written) on a kept store")
    parser.add_argument("--keep", type=Path, default=None,
                        help="keep the stores in this folder (and use those already there) instead of a temp folder")
    args = parser.parse_args()
    repo = args.repo.resolve()
    sys.path.insert(0, str(repo))
    rows = []
    with tempfile.TemporaryDirectory(prefix="sweep3d-scale-") as tmp:
        scratch = args.keep or Path(tmp)
        for target in args.plan:
            folder = scratch / f"plan{target}"
            folder.mkdir(parents=True, exist_ok=True)
            r = measure_plan(repo, folder, target)
            rows.append((f"`plan`, grid of {r['jobs']:,} jobs ({r['jobs'] - r['in_frame']:,} out of frame)",
                         *_usage(r["cli"]), f"make_plan {r['plan']:.1f} s (CPU {r['plan_cpu']:.1f} s), "
                                            f"jobs table {r['table']:.1f} s"))
            print(rows[-1], flush=True)
        for jobs in args.noop:
            folder = scratch / f"noop{jobs}"
            folder.mkdir(parents=True, exist_ok=True)
            r = measure_noop(repo, folder, jobs, not args.steady_only)
            if r["first"] is not None:
                rows.append((f"no-op `run` of {jobs:,} cached jobs, first after the store was written",
                             *_usage(r["first"]), f"{_goal(r['first'], jobs)}; store made in {r['setup']:.0f} s"))
            stored = r["query"]["stored"]
            rows.append((f"no-op `run` of {jobs:,} cached jobs, again", *_usage(r["second"]),
                         f"{_goal(r['second'], jobs)}; its findings computed (`summarise` over the aggregate views): {r['query']['summary']:.1f} s "
                         f"(CPU {r['query']['summary_cpu']:.1f} s)"
                         + (f"; read back as the run does (`stored_summary`): {stored:.2f} s" if stored is not None
                            else "")))
            rows.append((f"GROUP BY over {jobs:,} results (`sweep3d query`)", *_usage(r["query_cli"]),
                         f"in-process: open {r['query']['open']:.2f} s, query {r['query']['query']:.2f} s"))
            print(rows[-3:], flush=True)
    print(f"\nsweep3d at {repo}\n")
    print("| measure | wall | CPU | peak RSS | notes |\n|---|---|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
