"""Rules: boxes over several parameters where the model fails more than elsewhere.

A rule is a conjunction of conditions, each on its own parameter: a numeric parameter within an
interval (``camera_elevation > 40``, ``orientation_yaw 80–110``), a listed or text parameter at
one value (``blur_sigma = 3``, ``object = toaster``). "``yaw 80–110 and elevation > 40``: 70 %
wrong of 36, against 20 % of 404 elsewhere".

**Found by subgroup discovery with a beam search over intervals**, not by a decision tree: a tree
partitions *every* result and chooses each split for purity on both sides, so a small region of
failures ends up described by a path of splits made for the rest of the data; subgroup discovery
looks for the regions themselves, lets them overlap, and states each as a box readable on its
own. The search:

1. conditions of one parameter: each value of a parameter with at most :data:`MAX_VALUES` values;
   for a numeric one with more, the intervals between its quantiles (:data:`CUTS` cut points, so
   ``≤ c``, ``> c`` and every ``a < x ≤ b``);
2. rules of one condition, then each rule of the beam (the :data:`BEAM` best) extended by one
   condition on another parameter, to :data:`DEPTH` conditions;
3. quality: weighted relative accuracy of failing, ``(wrong inside - n_inside × overall error) /
   n``: the failures a rule explains beyond the overall rate (large and much worse regions first);
   a rule needs :func:`min_support` results and must beat every rule it extends (a condition that
   does not sharpen the box is left off);
4. the best :data:`TOP` rules, a rule covering mostly the same results as a better one left out.

Each rule has its **support** (results inside, and their share), accuracy inside and elsewhere,
the difference with Newcombe's hybrid score interval, and Fisher's one-sided p-value as
discovery saw it, with its Bonferroni adjustment over every box the search could have formed
(every combination of up to :data:`DEPTH` conditions on distinct parameters)
(``p_adjusted``; ``run`` names a rule only below 0.05). The search kept the best of many boxes, so
the difference and its interval are **optimistic**: a rule is a hypothesis. ``sweep3d confirm`` tests it on fresh renders (twins
inside the box and elsewhere in it, matched on every other parameter).

Only results where every parameter of a rule applies can be inside it; "elsewhere" is every other
counted result.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass
from typing import Any, Sequence

import duckdb
import numpy as np
import pyarrow as pa

from sweep3d.results.confirmation import wilson
from sweep3d.results.measures import NOT_A_MEASURE
from sweep3d.results.quoting import identifier
from sweep3d.results.views import has_view

VIEW = "rules"
BEAM = 12
DEPTH = 2
TOP = 5
CUTS = 11  # quantile cut points of a numeric parameter (12 slices)
MAX_VALUES = 12  # a numeric parameter with more distinct values is cut into intervals
OVERLAP = 0.5  # a rule sharing this much of its results (Jaccard) with a better one is left out
#: Beyond this many counted results the summary leaves rules out (the ``rules`` view still computes them).
SUMMARY_LIMIT = 200_000


@dataclass(frozen=True)
class Condition:
    """``column`` in (low, high] (numeric; None: unbounded) or ``column = value``."""

    column: str
    value: Any = None
    low: float | None = None
    high: float | None = None

    @property
    def numeric(self) -> bool:
        return self.value is None

    def text(self) -> str:
        if not self.numeric:
            return f"{self.column} = {_number(self.value)}"
        if self.low is None:
            return f"{self.column} ≤ {_number(self.high)}"
        if self.high is None:
            return f"{self.column} > {_number(self.low)}"
        return f"{self.column} {_number(self.low)}–{_number(self.high)}"


@dataclass(frozen=True)
class Rule:
    conditions: tuple[Condition, ...]
    n: int
    support: float  # share of the counted results inside
    wrong: int
    accuracy: float
    n_rest: int
    accuracy_rest: float | None
    difference: float | None
    difference_low: float | None
    difference_high: float | None
    quality: float
    p_value: float  # Fisher's one-sided, as discovery saw it (optimistic: see the module)
    p_adjusted: float = 1.0  # p_value × every box the search could form (Bonferroni), at most 1

    def text(self) -> str:
        """``camera_elevation > 40 and blur_sigma = 3: 95% wrong of 40, against 21% of 200 elsewhere``."""
        rest = "" if self.accuracy_rest is None else \
            f", against {1 - self.accuracy_rest:.0%} of {self.n_rest} elsewhere"
        return f"{self.key()}: {1 - self.accuracy:.0%} wrong of {self.n}{rest}"

    def key(self) -> str:
        return " and ".join(c.text() for c in self.conditions)


def find_rules(columns: dict[str, np.ndarray], correct: np.ndarray, beam: int = BEAM, depth: int = DEPTH,
               top: int = TOP) -> list[Rule]:
    """The best rules (see the module) over ``columns`` (name → values per result: numbers as
    floats with NaN where the control does not apply, text as objects with None) and ``correct``."""
    n = len(correct)
    wrong = ~np.asarray(correct, bool)
    if n == 0 or not wrong.any() or wrong.all():
        return []
    conditions = [(c, mask) for name, values in columns.items() for c, mask in _conditions(name, values)]
    least = min_support(n)
    rate = wrong.sum() / n

    def quality(mask: np.ndarray) -> float:
        k = int(mask.sum())
        return math.sqrt(k / n) * (int(wrong[mask].sum()) / k - rate) if k else 0.0

    scored: dict[tuple[Condition, ...], tuple[float, np.ndarray]] = {}
    frontier: list[tuple[tuple[Condition, ...], np.ndarray, float]] = []
    family = _family(conditions, depth)
    for c, mask in conditions:
        if mask.sum() >= least:
            q = quality(mask)
            scored[(c,)] = (q, mask)
            frontier.append(((c,), mask, q))
    for _ in range(depth - 1):
        frontier = sorted(frontier, key=lambda r: (-r[2], _order(r[0])))[:beam]
        grown = []
        for rule, mask, q in frontier:
            used = {c.column for c in rule}
            for c, extra in conditions:
                if c.column in used:
                    continue
                both = mask & extra
                key = tuple(sorted(rule + (c,), key=_condition_order))
                if key in scored or both.sum() < least:
                    continue
                better = quality(both)
                if better <= q or any(better <= scored.get(tuple(x for x in key if x != drop), (-1.0,))[0]
                                      for drop in key):
                    continue
                scored[key] = (better, both)
                grown.append((key, both, better))
        frontier = grown
    ranked = sorted(((q, key, mask) for key, (q, mask) in scored.items() if q > 0),
                    key=lambda r: (-r[0], _order(r[1])))
    kept: list[tuple[tuple[Condition, ...], np.ndarray]] = []
    for _quality, key, mask in ranked:
        if any(_jaccard(mask, other) >= OVERLAP for _, other in kept):
            continue
        kept.append((key, mask))
        if len(kept) == top:
            break
    return [dataclasses.replace(rule, p_adjusted=min(1.0, rule.p_value * family))
            for rule in (_rule(key, mask, wrong, scored[key][0]) for key, mask in kept)]


def _family(conditions: list[tuple[Condition, np.ndarray]], depth: int) -> int:
    """How many boxes of up to ``depth`` conditions on distinct parameters the conditions form
    (the elementary symmetric sums of the conditions per parameter): what the search chose from,
    whatever the beam kept."""
    sizes: dict[str, int] = {}
    for c, _ in conditions:
        sizes[c.column] = sizes.get(c.column, 0) + 1
    sums = [1] + [0] * depth  # sums[d]: boxes of d conditions
    for size in sizes.values():
        for d in range(depth, 0, -1):
            sums[d] += sums[d - 1] * size
    return max(1, sum(sums[1:]))


def min_support(n: int) -> int:
    """The fewest results a rule covers: 5 % of them, at least 10 (never more than all)."""
    return min(n, max(10, math.ceil(0.05 * n)))


def _conditions(name: str, values: np.ndarray):
    """(condition, mask) of each condition on one parameter."""
    if values.dtype.kind == "f":
        known = values[~np.isnan(values)]
        distinct = np.unique(known)
        if len(distinct) <= 1:
            return
        if len(distinct) <= MAX_VALUES:
            for v in distinct:
                yield Condition(name, float(v)), values == v
            return
        cuts = np.unique(np.quantile(known, np.linspace(0, 1, CUTS + 2)[1:-1]))
        edges = [None, *[float(c) for c in cuts], None]
        with np.errstate(invalid="ignore"):
            for i in range(len(edges)):
                for j in range(i + 1, len(edges)):
                    low, high = edges[i], edges[j]
                    if low is None and high is None:
                        continue
                    mask = ~np.isnan(values)
                    if low is not None:
                        mask &= values > low
                    if high is not None:
                        mask &= values <= high
                    yield Condition(name, low=low, high=high), mask
        return
    distinct = sorted({v for v in values.tolist() if v is not None}, key=str)
    if len(distinct) <= 1:
        return
    for v in distinct:
        yield Condition(name, v), np.array([x == v for x in values.tolist()], bool)


def _rule(key: tuple[Condition, ...], mask: np.ndarray, wrong: np.ndarray, quality: float) -> Rule:
    n, n_rest = int(mask.sum()), int((~mask).sum())
    k_wrong, k_rest_wrong = int(wrong[mask].sum()), int(wrong[~mask].sum())
    accuracy = (n - k_wrong) / n
    rest = (n_rest - k_rest_wrong) / n_rest if n_rest else None
    low = high = None
    if n_rest:
        (l1, u1), (l2, u2) = wilson(n - k_wrong, n), wilson(n_rest - k_rest_wrong, n_rest)
        low = accuracy - rest - math.sqrt((accuracy - l1) ** 2 + (u2 - rest) ** 2)
        high = accuracy - rest + math.sqrt((u1 - accuracy) ** 2 + (rest - l2) ** 2)
    return Rule(key, n, n / len(mask), k_wrong, accuracy, n_rest, rest, None if rest is None else accuracy - rest,
                low, high, quality, _fisher_less(n - k_wrong, n, n - k_wrong + n_rest - k_rest_wrong, len(mask)))


def _fisher_less(k: int, draws: int, successes: int, total: int) -> float:
    """P(X <= k), X ~ Hypergeometric(total, successes, draws), in log space."""
    def log_comb(a: int, b: int) -> float:
        return math.lgamma(a + 1) - math.lgamma(b + 1) - math.lgamma(a - b + 1)
    low = max(0, draws - (total - successes))
    terms = [log_comb(successes, j) + log_comb(total - successes, draws - j) - log_comb(total, draws)
             for j in range(low, min(k, successes) + 1)]
    return min(1.0, sum(math.exp(t) for t in terms)) if terms else 0.0


def _jaccard(a: np.ndarray, b: np.ndarray) -> float:
    union = int((a | b).sum())
    return int((a & b).sum()) / union if union else 1.0


def _condition_order(c: Condition) -> tuple:
    return (c.column, str(c.value), -math.inf if c.low is None else c.low, math.inf if c.high is None else c.high)


def _order(key: tuple[Condition, ...]) -> tuple:
    return tuple(_condition_order(c) for c in key)


def _number(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.0f}" if value == round(value) and abs(value) < 1e6 else f"{value:.3g}"
    return str(value)


# -- over a connection --------------------------------------------------------------------------------

_SCHEMA = pa.schema([("rank", pa.int64()), ("rule", pa.string()), ("conditions", pa.int64()), ("n", pa.int64()),
                     ("support", pa.float64()), ("accuracy", pa.float64()), ("n_rest", pa.int64()),
                     ("accuracy_rest", pa.float64()), ("difference", pa.float64()),
                     ("difference_low", pa.float64()), ("difference_high", pa.float64()),
                     ("quality", pa.float64()), ("p_discovery", pa.float64()), ("p_adjusted", pa.float64())])


def rules_of(con: duckdb.DuckDBPyConnection, parameters: Sequence[str] | None = None) -> list[Rule]:
    """The rules of the counted results of ``con``'s ``results`` over ``parameters`` (default:
    ``control_parameters``' own, object and environment included)."""
    if not has_view(con, "results"):
        return []
    if parameters is None:
        if not has_view(con, "control_parameters"):
            return []
        parameters = [r[0] for r in con.execute(f"SELECT parameter FROM control_parameters WHERE levels > 1 "
                                                f"AND {NOT_A_MEASURE} ORDER BY position").fetchall()]
    if not parameters:
        return []
    kinds = {name: kind for name, kind, *_ in con.execute("DESCRIBE results").fetchall()}
    selected = [p for p in parameters if p in kinds]
    picked = ", ".join(f"CAST({identifier(p)} AS DOUBLE) AS c{i}" if _numeric(kinds[p])
                       else f"CAST({identifier(p)} AS VARCHAR) AS c{i}" for i, p in enumerate(selected))
    got = con.execute(f"SELECT correct, {picked} FROM results WHERE counted ORDER BY job").fetchnumpy()
    if not len(got["correct"]):
        return []
    correct = np.asarray(got["correct"], bool)
    columns = {}
    for i, p in enumerate(selected):
        values = got[f"c{i}"]
        if _numeric(kinds[p]):  # a masked array where the control does not apply: NaN there
            columns[p] = np.ma.filled(np.ma.asarray(values, np.float64), np.nan)
        else:
            columns[p] = np.array([None if v is None or v is np.ma.masked else str(v) for v in values.tolist()],
                                  dtype=object)
    return find_rules(columns, correct)


def rules_table(rules: list[Rule]) -> pa.Table:
    return pa.Table.from_pylist([
        {"rank": i, "rule": r.key(), "conditions": len(r.conditions), "n": r.n, "support": r.support,
         "accuracy": r.accuracy, "n_rest": r.n_rest, "accuracy_rest": r.accuracy_rest, "difference": r.difference,
         "difference_low": r.difference_low, "difference_high": r.difference_high, "quality": r.quality,
         "p_discovery": r.p_value, "p_adjusted": r.p_adjusted} for i, r in enumerate(rules, start=1)], schema=_SCHEMA)


def register_rules(con: duckdb.DuckDBPyConnection) -> None:
    """Compute the rules and add them to ``con`` as the relation ``rules``."""
    if has_view(con, "results"):
        con.register(VIEW, rules_table(rules_of(con)))


def names_rules(statement: str) -> bool:
    import re

    return bool(re.search(rf"\b{VIEW}\b", statement, re.I))


def rule_dict(rule: Rule) -> dict[str, Any]:
    """A rule as the summary keeps it (JSON)."""
    out = asdict(rule)
    out["conditions"] = [asdict(c) for c in rule.conditions]
    out["text"] = rule.text()
    out["key"] = rule.key()
    return out


def _numeric(kind: str) -> bool:
    return kind.upper().split("(")[0] in ("TINYINT", "SMALLINT", "INTEGER", "BIGINT", "HUGEINT", "UTINYINT",
                                           "USMALLINT", "UINTEGER", "UBIGINT", "FLOAT", "DOUBLE", "DECIMAL")
