"""Search policies: they turn a space's shape into points, knowing nothing of the controls."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Mapping, Sequence

import numpy as np
from pydantic import ConfigDict, Field, StrictBool

from sweep3d.core import Registry, Typed
from sweep3d.spec import Point, Range, SearchSpace, SpaceShape, as_arrays, as_points

if TYPE_CHECKING:
    from sweep3d.spec import ControlInstance


class PolicyParams(Typed):
    model_config = ConfigDict(extra="forbid", frozen=True)


@dataclass(frozen=True)
class Outcome:
    """What the model did on one evaluated point."""

    failed: bool
    loss: float


class Policy:
    """Base of every policy: ``points`` must be a pure function of (shape, seed, history).

    ``history`` holds the outcomes of the points already evaluated in this scene. A fixed policy
    ignores it; an *adaptive* one returns those points followed by its next round, and the
    pipeline calls it again until it proposes nothing new.
    """

    Params: ClassVar[type[PolicyParams]] = PolicyParams
    adaptive: ClassVar[bool] = False
    #: Its draws of each dimension are independent of the others and it returns as many points
    #: whatever the shape: a paired plan may then draw each control from a stream of its own.
    separable: ClassVar[bool] = False
    #: It lists each scene's jobs (:meth:`listed`) instead of drawing points: nothing to pair or cross.
    lists_jobs: ClassVar[bool] = False

    def __init__(self, params: PolicyParams) -> None:
        self.params = params

    def points(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> list[Point]:
        raise NotImplementedError

    def arrays(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`points` as arrays: unit coordinates (n, continuous dims), choices (n, discrete dims).

        The planner reads these; a policy that makes its points as arrays overrides this (and
        builds :meth:`points` from it) so a million points never exist as objects.
        """
        return as_arrays(self.points(shape, seed, history), shape)

    def bind(self, base: Path, controls: Sequence[ControlInstance], objects: Sequence[str],
             environments: Sequence[str]) -> None:
        """Called once when the spec loads, with its folder, controls and scene names: a policy
        that reads them (a design table) checks them here and raises ``SpecError``. Others ignore it."""

    def listed(self, space: SearchSpace, object_name: str, environment: str) -> Listed | None:
        """A scene's jobs with their exact values, for a policy that lists jobs rather than drawing
        points in the unit cube (a design table); None (every other policy): the planner asks
        :meth:`arrays`."""
        return None

    def count(self, shape: SpaceShape) -> int | None:
        """How many points ``points`` returns for ``shape`` (at most, over all rounds of an adaptive
        policy), known without making them, so a plan too big to hold is refused before it is
        expanded. None: this policy cannot say (the planner then counts points as they come).
        """
        return None


@dataclass(frozen=True)
class Listed:
    """A scene's jobs as a listing policy gives them: the points (as :meth:`Policy.arrays` makes
    them) and each range parameter's exact values, (control id, param) → one value per job, which
    the planner takes instead of mapping the unit coordinates back (a round trip that can move the
    last bit)."""

    unit: np.ndarray
    choice: np.ndarray
    exact: dict[tuple[str, str], np.ndarray]


POLICIES: Registry[type[Policy]] = Registry("policy")


def balanced(rng: np.random.Generator, n: int, size: int) -> np.ndarray:
    """``n`` choices among ``size`` options, each taken ⌊n/size⌋ or ⌈n/size⌉ times, in random order:
    every option gets its share, and which ones get one more is drawn too."""
    whole = np.tile(np.arange(size, dtype=np.int64), n // size)
    extra = rng.choice(size, n % size, replace=False).astype(np.int64)
    return rng.permutation(np.concatenate([whole, extra]))


@POLICIES.register("grid")
class GridPolicy(Policy):
    """Every combination: ``samples_per_dim`` evenly spaced values per range (ends included,
    except that a range covering a whole period, like yaw over 360°, leaves out its upper end,
    which is the lower end again), times every option of each list."""

    class Params(PolicyParams):
        samples_per_dim: int = Field(4, ge=1, le=10_000)

    def points(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> list[Point]:
        return as_points(*self.arrays(shape, seed, history))

    def arrays(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> tuple[np.ndarray, np.ndarray]:
        """The product in ``itertools.product`` order: the last dimension varies fastest."""
        n = self.params.samples_per_dim
        ticks = np.array([0.5]) if n == 1 else np.arange(n) / (n - 1)
        around = np.array([0.5]) if n == 1 else np.arange(n) / n
        axes = [around if shape.wrapping(d) else ticks for d in range(shape.n_continuous)]
        sizes = [len(a) for a in axes] + list(shape.choice_sizes)
        if not sizes:
            return np.zeros((1, 0)), np.zeros((1, 0), np.int64)
        index = np.indices(sizes).reshape(len(sizes), -1)  # (dims, points), C order
        unit = np.stack([axis[i] for axis, i in zip(axes, index)], axis=1) if axes else np.zeros((index.shape[1], 0))
        choice = index[len(axes):].T.astype(np.int64)
        return unit, choice

    def count(self, shape: SpaceShape) -> int:
        return self.params.samples_per_dim ** shape.n_continuous * math.prod(shape.choice_sizes)


@POLICIES.register("random")
class RandomPolicy(Policy):
    """``samples`` independent uniform draws per scene, reproducible from the seed. With ``stratify``,
    each list's options are dealt out evenly (each ⌊n/k⌋ or ⌈n/k⌉ times, in random order) instead
    of drawn independently, so a rare option is not left with few samples by chance."""

    separable = True

    class Params(PolicyParams):
        samples: int = Field(16, ge=1, le=10_000_000)
        stratify: StrictBool = False

    def points(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> list[Point]:
        return as_points(*self.arrays(shape, seed, history))

    def arrays(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> tuple[np.ndarray, np.ndarray]:
        rng = np.random.default_rng(seed)
        n = self.params.samples
        unit = rng.random((n, shape.n_continuous))
        draw = balanced if self.params.stratify else lambda rng, n, size: rng.integers(0, size, n)
        choice = [draw(rng, n, size) for size in shape.choice_sizes]
        return unit, np.stack(choice, axis=1).astype(np.int64) if choice else np.zeros((n, 0), np.int64)

    def count(self, shape: SpaceShape) -> int:
        return self.params.samples


@POLICIES.register("sobol")
class SobolPolicy(Policy):
    """``samples`` scrambled Sobol points per scene: quasi-random, so they cover the space more
    evenly than random draws (best with a power of two). Lists are sampled as extra dimensions."""

    class Params(PolicyParams):
        samples: int = Field(16, ge=1, le=10_000_000)

    def points(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> list[Point]:
        return as_points(*self.arrays(shape, seed, history))

    def arrays(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> tuple[np.ndarray, np.ndarray]:
        import warnings

        from scipy.stats import qmc

        n, k = self.params.samples, shape.n_continuous
        dims = k + len(shape.choice_sizes)
        if dims == 0:
            return np.zeros((1, 0)), np.zeros((1, 0), np.int64)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "balance properties" for n not a power of 2
            unit = qmc.Sobol(d=dims, scramble=True, seed=np.random.default_rng(seed)).random(n)
        choice = [np.minimum((unit[:, k + j] * size).astype(int), size - 1) for j, size in enumerate(shape.choice_sizes)]
        return unit[:, :k], np.stack(choice, axis=1).astype(np.int64) if choice else np.zeros((n, 0), np.int64)

    def count(self, shape: SpaceShape) -> int:
        return self.params.samples if shape.n_continuous or shape.choice_sizes else 1


class RoundsPolicy(Policy):
    """An adaptive policy that starts with ``initial`` Sobol points and then proposes rounds of
    ``batch`` points (:meth:`next_round`) from the outcomes so far, up to ``samples`` per scene.

    Its ``Params`` have at least ``samples``, ``initial`` and ``batch``. A round is drawn from
    ``(seed, round index)``, so a plan replays every round from the history alone (a killed run
    resumes); a round that proposes no new point ends the search.
    """

    adaptive = True

    def points(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> list[Point]:
        p = self.params
        first = SobolPolicy(SobolPolicy.Params(samples=min(p.initial, p.samples))).points(shape, seed, history)
        points = list(dict.fromkeys(first))
        round_index = 1
        while len(points) < p.samples and all(q in history for q in points):
            rng = np.random.default_rng([seed, round_index])
            new = self.next_round(shape, points, history, rng, min(p.batch, p.samples - len(points)), round_index)
            seen = set(points)
            fresh = [q for q in dict.fromkeys(new) if q not in seen]
            if not fresh:
                break
            points += fresh
            round_index += 1
        return points

    def next_round(self, shape: SpaceShape, points: list[Point], history: Mapping[Point, Outcome],
                   rng: np.random.Generator, n: int, round_index: int) -> list[Point]:
        """``n`` points to evaluate next (round ``round_index``, from 1), given ``points`` and their outcomes."""
        raise NotImplementedError

    def count(self, shape: SpaceShape) -> int:
        """The budget: the most points its rounds can reach (one in a space with nothing to vary)."""
        return self.params.samples if shape.n_continuous or shape.choice_sizes else 1


@POLICIES.register("adaptive")
class AdaptivePolicy(RoundsPolicy):
    """Failure search under a budget of ``samples`` points per scene.

    Starts with ``initial`` Sobol points; each later round proposes ``batch`` points, most of
    them perturbations of the failures found so far (Gaussian, ``radius`` in unit-cube units,
    shrinking by ``shrink`` each round; lists switch option with probability ``switch``) and
    an ``explore`` share of fresh random points so unseen regions still get looked at. With no
    failure yet, it refines around the points with the highest loss.
    """

    adaptive = True

    class Params(PolicyParams):
        samples: int = Field(64, ge=1, le=1_000_000)
        initial: int = Field(16, ge=1, le=1_000_000)
        batch: int = Field(16, ge=1, le=1_000_000)
        radius: float = Field(0.12, gt=0.0, le=1.0)
        shrink: float = Field(0.8, gt=0.0, le=1.0)
        switch: float = Field(0.2, ge=0.0, le=1.0)
        explore: float = Field(0.25, ge=0.0, le=1.0)

    def next_round(self, shape: SpaceShape, points: list[Point], history: Mapping[Point, Outcome],
                   rng: np.random.Generator, n: int, round_index: int) -> list[Point]:
        return self._round(shape, points, history, rng, n, self.params.radius * self.params.shrink ** (round_index - 1))

    def _round(self, shape: SpaceShape, points: list[Point], history: Mapping[Point, Outcome],
               rng: np.random.Generator, n: int, radius: float) -> list[Point]:
        failures = [q for q in points if history[q].failed]
        parents = failures or sorted(points, key=lambda q: -history[q].loss)[: max(1, len(points) // 4)]
        n_explore = int(round(n * self.params.explore)) if failures else n // 2
        out = []
        for i in range(n):
            if i < n - n_explore:
                parent = parents[int(rng.integers(len(parents)))]
                out.append(self._perturb(shape, parent, rng, radius))
            else:
                unit = tuple(float(u) for u in rng.random(shape.n_continuous))
                out.append(Point(unit, tuple(int(rng.integers(size)) for size in shape.choice_sizes)))
        return out

    def _perturb(self, shape: SpaceShape, parent: Point, rng: np.random.Generator, radius: float) -> Point:
        unit = []
        for d, u in enumerate(parent.unit):
            v = u + rng.normal(0.0, radius)
            unit.append(float(v % 1.0) if shape.wrapping(d) else float(min(max(v, 0.0), 1.0)))
        choice = tuple(int(rng.integers(size)) if rng.random() < self.params.switch else c
                       for c, size in zip(parent.choice, shape.choice_sizes))
        return Point(tuple(unit), choice)


@POLICIES.register("boundary")
class BoundaryPolicy(RoundsPolicy):
    """Failure-boundary search under a budget of ``samples`` points per scene.

    Starts with ``initial`` Sobol points; each later round fits a step to the outcomes so far
    along every continuous dimension that does not wrap (the fit ``failure_boundaries`` makes:
    see :mod:`sweep3d.stages.plan.step_fit`), takes the one with the strongest step (its
    likelihood ratio at least :data:`BoundaryPolicy.EVIDENCE`) and puts ``batch`` points where
    that boundary is still uncertain: its 95 % interval widened by ``margin`` of its width on
    each side, spread evenly across it, the other coordinates and lists drawn at random (so the
    other dimensions are still explored). An ``explore`` share of each round (default none: at
    equal budgets it widened the interval, ``benchmarks/boundaries.py``) is uniform over the
    space; with no step yet, the whole round is.
    """

    #: The likelihood ratio a step needs before a round aims at it (χ²₁'s 95 % point).
    EVIDENCE = 3.84

    class Params(PolicyParams):
        samples: int = Field(64, ge=1, le=1_000_000)
        initial: int = Field(16, ge=1, le=1_000_000)
        batch: int = Field(4, ge=1, le=1_000_000)  # small rounds: each aims at what the last one learned
        margin: float = Field(0.25, ge=0.0, le=10.0)
        explore: float = Field(0.0, ge=0.0, le=1.0)

    def target(self, shape: SpaceShape, points: Sequence[Point],
               history: Mapping[Point, Outcome]) -> tuple[int, float, float] | None:
        """(dimension, low, high): the strongest step's 95 % interval in unit coordinates, or None
        when no dimension shows a step with :data:`EVIDENCE`."""
        from sweep3d.stages.plan.step_fit import fit_step

        if not points:
            return None
        unit = np.array([q.unit for q in points], dtype=np.float64).reshape(len(points), shape.n_continuous)
        passed = np.array([not history[q].failed for q in points])
        best, found = self.EVIDENCE, None
        for d in range(shape.n_continuous):
            if shape.wrapping(d):
                continue
            fit = fit_step(unit[:, d], passed, test=False)
            if fit is not None and fit.lr >= best:
                best, found = fit.lr, (d, fit.interval_low, fit.interval_high)
        return found

    def next_round(self, shape: SpaceShape, points: list[Point], history: Mapping[Point, Outcome],
                   rng: np.random.Generator, n: int, round_index: int) -> list[Point]:
        found = self.target(shape, points, history)
        aimed = n - int(round(n * self.params.explore)) if found else 0
        out = []
        for i in range(n):
            unit = rng.random(shape.n_continuous)
            if i < aimed:
                d, low, high = found
                spread = self.params.margin * (high - low)
                a, b = max(0.0, low - spread), min(1.0, high + spread)
                unit[d] = a + (b - a) * (i + rng.random()) / aimed  # one point per equal slice
            choice = tuple(int(rng.integers(size)) for size in shape.choice_sizes)
            out.append(Point(tuple(float(u) for u in unit), choice))
        return out


@POLICIES.register("table")
class TablePolicy(Policy):
    """The jobs a design table lists, row for row (``file``: CSV or Parquet, relative to the spec):
    columns ``object``, ``environment`` and ``<control id>_<param>`` for each parameter the spec
    varies, as ``sweep3d plan --design`` writes them. Each value is checked against the range or
    list the spec gives; the seed draws nothing."""

    lists_jobs = True

    class Params(PolicyParams):
        file: str = Field(min_length=1)

    def bind(self, base: Path, controls: Sequence[ControlInstance], objects: Sequence[str],
             environments: Sequence[str]) -> None:
        from sweep3d.assets import check_file
        from sweep3d.core import SpecError
        from sweep3d.stages.plan.design import SUFFIXES, read_design

        path = Path(self.params.file).expanduser()
        path = path if path.is_absolute() else base / path
        if path.suffix.lower() not in SUFFIXES:
            raise SpecError(str(path), "", f"a design table is a {' or '.join(SUFFIXES)} file")
        check_file(path, "design table", "paths are relative to the spec file")
        self.rows = read_design(path, controls, objects, environments, base)

    def listed(self, space: SearchSpace, object_name: str, environment: str) -> Listed:
        rows = self.rows.get((object_name, environment))
        n = rows.count if rows else 0
        unit = np.zeros((n, len(space.continuous)))
        choice = np.zeros((n, len(space.discrete)), dtype=np.int64)
        exact = {}
        for d, dim in enumerate(space.continuous):
            values = np.asarray(rows.values[(dim.control_id, dim.param)], dtype=np.float64 if not dim.space.integer
                                else object) if n else np.zeros(0)
            exact[(dim.control_id, dim.param)] = values
            unit[:, d] = _unit_of(dim.space, values.astype(np.float64)) if n else 0.0
        for d, dim in enumerate(space.discrete):
            index = {option: i for i, option in enumerate(dim.space.options)}
            choice[:, d] = [index[v] for v in rows.values[(dim.control_id, dim.param)]] if n else []
        return Listed(unit, choice, exact)

    def arrays(self, shape: SpaceShape, seed: int, history: Mapping[Point, Outcome]) -> tuple[np.ndarray, np.ndarray]:
        raise TypeError("the table policy lists each scene's jobs (Policy.listed); it has no points of its own")

    def count(self, shape: SpaceShape) -> None:
        return None


def _unit_of(space: Range, values: np.ndarray) -> np.ndarray:
    """Where ``values`` lie in the unit cube of ``space`` (what a drawing policy would have given)."""
    if space.log:
        u = (np.log(values) - math.log(space.low)) / (math.log(space.high) - math.log(space.low))
    else:
        u = (values - space.low) / (space.high - space.low)
    return np.clip(u, 0.0, 1.0)
