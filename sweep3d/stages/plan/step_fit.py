"""One change point in a pass/fail rate: where accuracy steps from one level to another along a
numeric control, how sure that place is, and whether there is a step at all.

The model: results at values ``x <= c`` are correct with probability ``a``, those above with
``b``. It is fitted by maximum likelihood over every split between two neighbouring distinct
values (at most :data:`MAX_GROUPS` groups of neighbouring values; more are merged into groups
of about equal counts, and a split then falls between two groups).

Why a step and these statistics (see ``docs/architecture.md``):

- **A deterministic threshold is a step.** A model that always fails below 12° separates the
  results completely: a logistic fit's maximum-likelihood slope is infinite, and a percentile
  bootstrap of its midpoint under-covers. A step's likelihood stays finite, and its estimate
  is the gap between the last failure and the first success, as it should be.
- **The location's interval is a profile-likelihood set**: every split whose log-likelihood is
  within ``CRITICAL / 2`` of the best one. The location of a change is not a regular parameter
  (its likelihood ratio is not χ²₁: its 95 % point would be 3.84 and under-cover); the limit of
  the profile likelihood ratio for a small step is the larger of two independent suprema of
  ``2W(t) - |t|``, each exponential with mean 2, whose 95 % point is
  ``-2 ln(1 - sqrt(0.95))`` = 7.35. For a large step it is conservative (a random walk's
  maximum lies below the Brownian one). The interval is the hull of the accepted splits,
  widened to the whole groups on each side (a true boundary inside a merged group is covered).
- **The step is tested against no change** by its largest likelihood ratio over the splits
  that leave at least :func:`trim` results on each side, with a permutation test of that
  maximum: the search over splits is part of the statistic, so choosing the best split is
  accounted for, and the test is exact for any number of results (no asymptotic table such as
  Andrews' sup-LR values, which need a hundred results or more). Results are permuted within
  strata (scenes), so a design that samples scenes at different values (an adaptive policy)
  does not make a scene effect look like a step. The permutations are drawn as hypergeometric
  counts per group (exactly a permutation of the 0/1 outcomes), so their cost grows with the
  groups, not the results; :data:`PERMUTATIONS` of them, then :data:`MORE_PERMUTATIONS` when
  p < :data:`EXTEND_BELOW`, so small p-values are resolved finely enough for a false discovery
  adjustment over many tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Splits are searched between at most this many groups of neighbouring values.
MAX_GROUPS = 200
#: The test searches the splits between at most this many groups (its cost grows with them).
TEST_GROUPS = 50
#: The 95 % point of the profile likelihood ratio of a change's location (see the module).
CRITICAL = -2.0 * math.log(1.0 - math.sqrt(0.95))
PERMUTATIONS = 999
MORE_PERMUTATIONS = 9999
EXTEND_BELOW = 0.05


@dataclass(frozen=True)
class StepFit:
    """The best step of one group of results.

    ``low_side``/``high_side``: the values either side of the best split (the estimate is
    between them); ``interval_low``/``interval_high``: the 95 % profile-likelihood interval of
    the location; ``accuracy_below``/``accuracy_above``: the fitted accuracy on each side, with
    their counts; ``lr``: twice the log-likelihood ratio of the step against no change;
    ``p_value``: its permutation p-value (with ``permutations`` drawn).
    """

    n: int
    values: int
    low_side: float
    high_side: float
    interval_low: float
    interval_high: float
    accuracy_below: float
    n_below: int
    accuracy_above: float
    n_above: int
    lr: float
    p_value: float
    permutations: int


def trim(n: int) -> int:
    """The fewest results either side of a split the test searches: 5 % of them, at least 2."""
    return max(2, math.ceil(0.05 * n))


def fit_step(x: np.ndarray, correct: np.ndarray, strata: np.ndarray | None = None, seed: int = 0,
             test: bool = True) -> StepFit | None:
    """The step fit of results ``correct`` (bool) at values ``x`` (finite floats), permuted within
    ``strata`` (integer ids; default one stratum) for the test, with permutations from ``seed``
    (``test=False``: no test, p-value 1 and no permutation drawn).

    Returns None when no split leaves :func:`trim` results on each side.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(correct, dtype=bool)
    strata = np.zeros(len(x), np.int64) if strata is None else np.asarray(strata)
    distinct, inverse = np.unique(x, return_inverse=True)
    counts = np.bincount(inverse, minlength=len(distinct))
    group, lows, highs = _groups(distinct, counts, MAX_GROUPS)
    m = len(lows)
    sizes = np.bincount(group, weights=counts, minlength=m).astype(np.int64)
    wins = np.bincount(group[inverse], weights=y, minlength=m).astype(np.int64)
    n_left = np.cumsum(sizes)[:-1]
    k_left = np.cumsum(wins)[:-1]
    n, k = len(y), int(y.sum())
    allowed = (n_left >= trim(n)) & (n - n_left >= trim(n))
    if not allowed.any():
        return None
    table = _xlogx(n)
    lr = _lr(k_left, n_left, k, n, table)
    # the estimate, its interval and the plateaus come from every split (a boundary near an end of
    # the range is where the data put it); only the test keeps to the trimmed ones
    best_value = lr.max()
    ties = np.flatnonzero(lr >= best_value - 1e-9)
    best = int(ties[len(ties) // 2])
    accepted = np.flatnonzero(lr >= best_value - CRITICAL)
    p_value, drawn = 1.0, 0
    if test:
        p_value, drawn = _permutation_p(group[inverse], sizes, y, strata, allowed, lr, seed, table)
    below = int(n_left[best])
    return StepFit(n=n, values=len(distinct), low_side=float(highs[best]), high_side=float(lows[best + 1]),
                   interval_low=float(lows[accepted.min()]), interval_high=float(highs[accepted.max() + 1]),
                   accuracy_below=int(k_left[best]) / below, n_below=below,
                   accuracy_above=(k - int(k_left[best])) / (n - below), n_above=n - below,
                   lr=float(best_value), p_value=p_value, permutations=drawn)


def _groups(values: np.ndarray, counts: np.ndarray, most: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each of the sorted ``values``' group (neighbours merged into at most ``most`` groups of
    about equal ``counts``) and each group's lowest and highest value."""
    if len(values) <= most:
        group = np.arange(len(values))
    else:
        before = np.cumsum(counts) - counts
        group = np.unique(np.floor(before * most / counts.sum()).astype(np.int64), return_inverse=True)[1]
    m = int(group.max()) + 1
    lows = np.full(m, np.inf)
    highs = np.full(m, -np.inf)
    np.minimum.at(lows, group, values)
    np.maximum.at(highs, group, values)
    return group, lows, highs


def _xlogx(n: int) -> np.ndarray:
    """i log i for i = 0..n (0 for 0): a binomial log-likelihood at its maximum is
    xlogx[k] + xlogx[n - k] - xlogx[n], read from this table for integer counts."""
    i = np.arange(n + 1, dtype=np.float64)
    return i * np.log(np.maximum(i, 1.0))


def _lr(k_left: np.ndarray, n_left: np.ndarray, k: int, n: int, table: np.ndarray) -> np.ndarray:
    """Twice the log-likelihood ratio of each split (last axis) against no change, from counts."""
    k_left = np.asarray(k_left, dtype=np.int64)
    n_left = np.asarray(n_left, dtype=np.int64)
    k_right, n_right = k - k_left, n - n_left
    split = (table[k_left] + table[n_left - k_left] - table[n_left]
             + table[k_right] + table[n_right - k_right] - table[n_right])
    whole = table[k] + table[n - k] - table[n]
    return np.maximum(2.0 * (split - whole), 0.0)


def _permutation_p(group: np.ndarray, sizes: np.ndarray, y: np.ndarray, strata: np.ndarray, allowed: np.ndarray,
                   lr: np.ndarray, seed: int, table: np.ndarray) -> tuple[float, int]:
    """The permutation p-value of the largest ratio over the allowed splits between at most
    :data:`TEST_GROUPS` groups (``group``: each result's fine group, of ``sizes``), and the
    permutations drawn."""
    n, k = len(y), int(y.sum())
    coarse, _, _ = _groups(np.arange(len(sizes), dtype=np.float64), sizes, TEST_GROUPS)
    m = int(coarse.max()) + 1
    last = np.flatnonzero(np.diff(coarse)) # fine split after each coarse group but the last
    searched = last[allowed[last]]
    observed = float(lr[searched].max()) if len(searched) else 0.0
    if k in (0, n) or observed <= 1e-12:
        return 1.0, 0
    rng = np.random.default_rng(seed)
    n_left = np.cumsum(np.bincount(coarse, weights=sizes, minlength=m).astype(np.int64))[:-1]
    keep = allowed[last]
    tables = _strata_tables(coarse[group], y, strata, m)
    exceed, drawn = 0, 0
    for total in (PERMUTATIONS, MORE_PERMUTATIONS):
        wins = _permuted_wins(tables, m, total - drawn, rng)
        k_left = np.cumsum(wins, axis=1)[:, :-1][:, keep]
        ratio = _lr(k_left, n_left[keep], k, n, table).max(axis=1)
        exceed += int((ratio >= observed - 1e-9 * max(1.0, observed)).sum())
        drawn = total
        if (1 + exceed) / (1 + drawn) >= EXTEND_BELOW:
            break
    return (1 + exceed) / (1 + drawn), drawn


def _strata_tables(group: np.ndarray, y: np.ndarray, strata: np.ndarray,
                   m: int) -> tuple[list[tuple[np.ndarray, np.ndarray, int]], np.ndarray]:
    """Per stratum with both outcomes: its non-empty groups, their sizes and its successes; and
    the successes per group of the strata that are all right (the same in every permutation)."""
    out = []
    fixed = np.zeros(m, np.int64)
    for s in np.unique(strata):
        mine = strata == s
        k = int(y[mine].sum())
        sizes = np.bincount(group[mine], minlength=m)
        if k == int(mine.sum()):
            fixed += sizes  # all right: every permutation is the same
        elif k:
            where = np.flatnonzero(sizes)
            out.append((where, sizes[where], k))
    return out, fixed


def _permuted_wins(tables: tuple[list[tuple[np.ndarray, np.ndarray, int]], np.ndarray], m: int, batch: int,
                   rng: np.random.Generator) -> np.ndarray:
    """Successes per group (batch, m) of ``batch`` permutations within strata: each stratum's
    successes dealt to its groups as successive hypergeometric draws (a permutation's counts)."""
    varying, fixed = tables
    wins = np.tile(fixed, (batch, 1))
    for where, sizes, k in varying:
        good = np.full(batch, k, np.int64)
        left = int(sizes.sum())
        for g, size in zip(where[:-1].tolist(), sizes[:-1].tolist()):
            drawn = rng.hypergeometric(good, left - good, size) if size < left else good
            wins[:, g] += drawn
            good = good - drawn
            left -= size
        wins[:, where[-1]] += good
    return wins
