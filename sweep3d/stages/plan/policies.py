"""Search policies: they turn a space's shape into points, knowing nothing of the controls."""

from __future__ import annotations

import itertools
from typing import ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from sweep3d.registry import Registry
from sweep3d.spec.space import Point, SpaceShape


class PolicyParams(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Policy:
    """Base of every policy: ``points`` must be a pure function of the shape and the seed."""

    Params: ClassVar[type[PolicyParams]] = PolicyParams

    def __init__(self, params: PolicyParams) -> None:
        self.params = params

    def points(self, shape: SpaceShape, seed: int) -> list[Point]:
        raise NotImplementedError


POLICIES: Registry[type[Policy]] = Registry("policy")


@POLICIES.register("grid")
class GridPolicy(Policy):
    """Every combination: ``samples_per_dim`` evenly spaced values per range (ends included,
    except that a range covering a whole period, like yaw over 360°, leaves out its upper end,
    which is the lower end again), times every option of each list."""

    class Params(PolicyParams):
        samples_per_dim: int = Field(4, ge=1, le=10_000)

    def points(self, shape: SpaceShape, seed: int) -> list[Point]:
        n = self.params.samples_per_dim
        ticks = [0.5] if n == 1 else [i / (n - 1) for i in range(n)]
        around = [0.5] if n == 1 else [i / n for i in range(n)]
        axes = [around if shape.wrapping(d) else ticks for d in range(shape.n_continuous)]
        choices = [range(size) for size in shape.choice_sizes]
        out = []
        for combo in itertools.product(*axes, *choices):
            unit = tuple(float(u) for u in combo[: shape.n_continuous])
            out.append(Point(unit, tuple(int(c) for c in combo[shape.n_continuous :])))
        return out


@POLICIES.register("random")
class RandomPolicy(Policy):
    """``samples`` independent uniform draws per scene, reproducible from the seed."""

    class Params(PolicyParams):
        samples: int = Field(16, ge=1, le=10_000_000)

    def points(self, shape: SpaceShape, seed: int) -> list[Point]:
        rng = np.random.default_rng(seed)
        n = self.params.samples
        unit = rng.random((n, shape.n_continuous))
        choice = [rng.integers(0, size, n) for size in shape.choice_sizes]
        return [
            Point(tuple(float(u) for u in unit[i]), tuple(int(c[i]) for c in choice)) for i in range(n)
        ]


@POLICIES.register("sobol")
class SobolPolicy(Policy):
    """``samples`` scrambled Sobol points per scene: quasi-random, so they cover the space more
    evenly than random draws (best with a power of two). Lists are sampled as extra dimensions."""

    class Params(PolicyParams):
        samples: int = Field(16, ge=1, le=10_000_000)

    def points(self, shape: SpaceShape, seed: int) -> list[Point]:
        import warnings

        from scipy.stats import qmc

        n, k = self.params.samples, shape.n_continuous
        dims = k + len(shape.choice_sizes)
        if dims == 0:
            return [Point((), ())]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "balance properties" for n not a power of 2
            unit = qmc.Sobol(d=dims, scramble=True, seed=np.random.default_rng(seed)).random(n)
        choice = [np.minimum((unit[:, k + j] * size).astype(int), size - 1) for j, size in enumerate(shape.choice_sizes)]
        return [Point(tuple(float(u) for u in unit[i, :k]), tuple(int(c[i]) for c in choice)) for i in range(n)]
