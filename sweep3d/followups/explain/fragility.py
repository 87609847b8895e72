"""The stability check's rule, as ``explain`` reads it: the fragile threshold of the model it
searches and the images that flipped in the check (the ``fragile_threshold`` and
``stability_images`` views of :mod:`sweep3d.results.fragile`). One rule everywhere: a fix is
fragile exactly when a run's result with its margin would be."""

from __future__ import annotations

from dataclasses import dataclass, field

from sweep3d.cache import Store
from sweep3d.followups.explain.further import is_fragile
from sweep3d.results import connect, has_view, results_store
from sweep3d.spec import LoadedSpec


@dataclass(frozen=True)
class Rule:
    """``threshold``: ``|margin|`` below it is fragile (None: no stability check of the model yet);
    ``flipped``: prediction keys whose image flipped in the check."""

    threshold: float | None = None
    flipped: frozenset[str] = field(default_factory=frozenset)

    def fragile(self, margin: float | None, pred_key: str | None = None) -> bool | None:
        return is_fragile(margin, self.threshold, pred_key in self.flipped)


def read_rule(spec: LoadedSpec) -> Rule:
    """The rule for the spec's first model (the one ``explain`` searches); an empty rule before any
    stability check, or for an evaluator without a margin."""
    with results_store(spec) as reading:
        return _rule(reading, spec.name)


def _rule(store: Store, experiment: str) -> Rule:
    con = connect(store, experiment, views="results")
    try:
        if not has_view(con, "fragile_threshold"):
            return Rule()
        have = {row[0] for row in con.execute("DESCRIBE results").fetchall()}
        model = con.execute("SELECT any_value(model) FROM results").fetchone()[0] if "model" in have else None
        found = con.execute("SELECT threshold FROM fragile_threshold WHERE model IS NOT DISTINCT FROM ?",
                            [model]).fetchone()
        if found is None:
            return Rule()
        flipped = con.execute("SELECT pred_key FROM stability_images WHERE flipped AND model IS NOT DISTINCT FROM ?",
                              [model]).fetchall()
    finally:
        con.close()
    return Rule(float(found[0]), frozenset(row[0] for row in flipped))
