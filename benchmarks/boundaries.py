"""The boundary policy against grid and random search at the same render budget, on synthetic outcomes.

A stand-in model fails below a set camera elevation (12° of a 0–60° range), every label flipped
with probability ``noise``; nothing renders. Each policy is driven as the pipeline drives it
(points, outcomes of the new ones, points again until it proposes nothing new) for one scene,
and the boundary is then fitted as ``failure_boundaries`` fits it (a step, 95 %
profile-likelihood interval). Printed per budget, noise and space: the median interval width
over the seeds (in degrees), the width per render ratio against grid and random, and how often
the interval covers the true boundary.

Spaces: ``elevation`` (the one control), and ``+ nuisance`` (elevation, a second range that does
not matter and a two-value list: grid then spends its budget on a √budget × √budget × 2 lattice).

    .venv/bin/python benchmarks/boundaries.py [--seeds 50] [--budgets 32 64] [--noise 0 0.1]
"""

from __future__ import annotations

import argparse
import math
import statistics

import numpy as np
from rich.console import Console
from rich.table import Table

from sweep3d.spec.space import Point, SpaceShape
from sweep3d.stages.plan.policies import BoundaryPolicy, GridPolicy, Outcome, Policy, RandomPolicy
from sweep3d.stages.plan.step_fit import fit_step

LOW, HIGH, THRESHOLD = 0.0, 60.0, 12.0
SPACES = {"elevation": SpaceShape(1, ()), "+ nuisance": SpaceShape(2, (2,))}


def policies(budget: int, shape: SpaceShape) -> dict[str, Policy]:
    """Grid (the largest lattice within the budget), random and boundary at ``budget`` points."""
    per_dim = max(1, int(math.floor((budget / math.prod(shape.choice_sizes)) ** (1 / shape.n_continuous) + 1e-9)))
    return {"grid": GridPolicy(GridPolicy.Params(samples_per_dim=per_dim)),
            "random": RandomPolicy(RandomPolicy.Params(samples=budget)),
            "boundary": BoundaryPolicy(BoundaryPolicy.Params(samples=budget))}  # its defaults: 16 first, rounds of 4


def drive(policy: Policy, shape: SpaceShape, seed: int, noise: float) -> tuple[list[Point], dict[Point, Outcome]]:
    """Rounds as the pipeline runs them: each new point is evaluated once by the stand-in model."""
    rng = np.random.default_rng([seed, 99])
    history: dict[Point, Outcome] = {}
    points: list[Point] = []
    while True:
        points = policy.points(shape, seed, history)
        new = [q for q in points if q not in history]
        if not new:
            return points, history
        for q in new:
            failed = (LOW + q.unit[0] * (HIGH - LOW) < THRESHOLD) != (rng.random() < noise)
            history[q] = Outcome(failed=bool(failed), loss=float(failed))
        if not policy.adaptive:
            return points, history


def measure(policy: Policy, shape: SpaceShape, seed: int, noise: float) -> tuple[int, float, bool]:
    """(renders, interval width in degrees, whether it covers the true boundary)."""
    points, history = drive(policy, shape, seed, noise)
    x = np.array([LOW + q.unit[0] * (HIGH - LOW) for q in points])
    fit = fit_step(x, np.array([not history[q].failed for q in points]), test=False)
    return len(points), fit.interval_high - fit.interval_low, fit.interval_low <= THRESHOLD <= fit.interval_high


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--budgets", type=int, nargs="+", default=[32, 64])
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.1])
    args = parser.parse_args()
    table = Table(title=f"Boundary interval width at equal budgets (stand-in fails below {THRESHOLD:g}° of "
                        f"{LOW:g}–{HIGH:g}°; {args.seeds} seeds; median over seeds)")
    for column in ("space", "budget", "noise", "policy", "renders", "width (°)", "grid / this", "random / this",
                   "covers"):
        table.add_column(column, justify="right")
    for name, shape in SPACES.items():
        for budget in args.budgets:
            for noise in args.noise:
                found = {}
                for label, policy in policies(budget, shape).items():
                    runs = [measure(policy, shape, seed, noise) for seed in range(args.seeds)]
                    found[label] = (statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs),
                                    sum(r[2] for r in runs) / len(runs))
                for label, (renders, width, covers) in found.items():
                    # width per render: a lattice smaller than the budget is charged for its own renders
                    per = width * renders
                    table.add_row(name, str(budget), f"{noise:g}", label, f"{renders:g}", f"{width:.3g}",
                                  f"{found['grid'][1] * found['grid'][0] / per:.3g}×",
                                  f"{found['random'][1] * found['random'][0] / per:.3g}×", f"{covers:.0%}")
    Console(width=150).print(table)


if __name__ == "__main__":
    main()
