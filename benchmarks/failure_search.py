"""Adaptive failure search against random search at the same render budget.

Runs specs/failure_search.toml twice, once with its adaptive policy and once with a random
policy drawing the same number of points per scene, and prints distinct failures (failing
images with distinct cache keys) per 100 renders. Both runs use the same store, so a rerun is
answered from the cache.

    .venv/bin/python benchmarks/failure_search.py [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from rich.console import Console
from rich.table import Table

import sweep3d
from sweep3d.cache.store import Store
from sweep3d.results import connect
from sweep3d.runner.pipeline import run
from sweep3d.stages.plan.policies import POLICIES

SPEC = Path(__file__).resolve().parents[1] / "specs" / "failure_search.toml"


def measure(policy_name: str, seed: int, console: Console) -> tuple[int, int, int]:
    """(renders, distinct failing images, images) of one run of the spec under ``policy_name``."""
    loaded = sweep3d.load(SPEC).spec
    budget = loaded.policy.params.samples
    policy_cls = POLICIES.get(policy_name)
    params = loaded.policy.params if policy_name == "adaptive" else policy_cls.Params(samples=budget)
    experiment = loaded.spec.experiment.model_copy(update={"name": f"{loaded.name}-{policy_name}-s{seed}", "seed": seed})
    spec = loaded.spec.model_copy(update={"experiment": experiment})
    loaded = dataclasses.replace(loaded, spec=spec, policy=policy_cls(params))
    result = run(loaded, console)
    con = connect(Store(loaded.store), loaded.name)
    renders, failures, images = con.execute(
        "SELECT count(DISTINCT render_key), count(DISTINCT image_key) FILTER (WHERE valid AND NOT correct), "
        "count(DISTINCT image_key) FROM results").fetchone()
    assert result.failed == 0
    return renders, failures, images


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    args = parser.parse_args()
    console = Console()
    rows = {}
    for seed in args.seeds:
        for policy in ("random", "adaptive"):
            rows[(policy, seed)] = measure(policy, seed, console)
    table = Table(title=f"Failure search on {SPEC.name}: distinct failures per 100 renders")
    for column in ("policy", "seed", "renders", "failing images", "failures / 100 renders", "ratio to random"):
        table.add_column(column, justify="right")
    for (policy, seed), (renders, failures, _) in rows.items():
        rate = 100.0 * failures / renders
        base = rows[("random", seed)]
        base_rate = 100.0 * base[1] / base[0]
        ratio = f"{rate / base_rate:.2f}×" if base_rate else "∞"
        table.add_row(policy, str(seed), str(renders), str(failures), f"{rate:.1f}", ratio)
    console.print(table)


if __name__ == "__main__":
    main()
