"""Render throughput on Ray with 1 and 2 actors against the local pool, on this machine.

    .venv/bin/python benchmarks/ray_scaling.py [--renders 24]

Each configuration renders the same jobs into its own fresh store (224², 4 spp + OIDN fast, two
scenes); each worker gets cores / workers Cycles threads. Ray runs a local cluster on 127.0.0.1.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
from pathlib import Path

from rich.console import Console
from rich.table import Table

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SPEC = """
[experiment]
name = "ray-bench"
store = "store"

[render]
resolution = 224
samples = 4

[[objects]]
name = "basketball"
mesh = "/usr/share/sweethome3d/furniture/BlendSwap-CC-0.sh3f#blendswap-cc-0/basketball/basketball.obj"
labels = ["basketball"]

[[environments]]
name = "forest"
hdri = "builtin:forest"

[[environments]]
name = "studio"
hdri = "builtin:studio"

[[controls]]
type = "orientation"
yaw = { range = [-180, 180] }

[policy]
type = "grid"
samples_per_dim = {per_scene}
"""


def render_rate(folder: Path, renders: int, executor, workers: int) -> float:
    import sweep3d
    from sweep3d.runner.pipeline import run

    folder.mkdir(parents=True)
    (folder / "spec.toml").write_text(SPEC.replace("{per_scene}", str(renders // 2)))
    loaded = sweep3d.load(folder / "spec.toml").spec
    threads = max(1, (os.cpu_count() or 1) // workers)
    render = loaded.spec.render.model_copy(update={"workers": workers, "threads": threads})
    loaded = dataclasses.replace(loaded, spec=loaded.spec.model_copy(update={"render": render}))
    result = run(loaded, executor=executor)
    outcome = result.outcome("render")
    assert result.failed == 0 and outcome.computed == renders, result.outcomes
    return renders / outcome.seconds


def main() -> None:
    import ray

    from sweep3d.stages.render.render_stage import LOCAL, Executor

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--renders", type=int, default=24)
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="sweep3d-ray-bench-") as tmp:
        tmp = Path(tmp)
        rows.append(("local pool, 1 worker × all cores", render_rate(tmp / "local1", args.renders, LOCAL, 1)))
        rows.append(("local pool, 2 workers", render_rate(tmp / "local2", args.renders, LOCAL, 2)))
        ray.init(_node_ip_address="127.0.0.1", include_dashboard=False, log_to_driver=False)
        rows.append(("ray, 1 actor", render_rate(tmp / "ray1", args.renders, Executor("ray"), 1)))
        rows.append(("ray, 2 actors", render_rate(tmp / "ray2", args.renders, Executor("ray"), 2)))
        ray.shutdown()
    base = rows[0][1]
    table = Table(title=f"Render throughput, {args.renders} renders, {os.cpu_count()} cores (render stage wall)")
    for column in ("executor", "images/s", "vs local pool"):
        table.add_column(column, justify="right" if column != "executor" else "left")
    for name, rate in rows:
        table.add_row(name, f"{rate:.2f}", f"{rate / base:.2f}×")
    Console().print(table)


if __name__ == "__main__":
    main()
