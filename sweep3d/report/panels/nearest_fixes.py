"""Nearest fixes: each failure beside the nearest configuration where the model is right, as
``sweep3d explain`` found it, with the change written out ("orientation_yaw +14 makes it a
toaster"), the margin at the fix, whether it is fragile (the stability check's rule) and the
search's resolution, and per parameter how often it is part of the cheapest fix. Shown only once
``explain`` has run (its ``counterfactuals`` views; see
:mod:`sweep3d.results.counterfactuals`)."""

from __future__ import annotations

from typing import Any

from sweep3d.followups.explain import change_words, resolution_words, share_words, trust_words
from sweep3d.report.figures import pct
from sweep3d.report.panel import PanelInputs
from sweep3d.results import has_view

CARDS = 12  # failure | fix pairs shown, nearest first


def build(inputs: PanelInputs) -> dict[str, Any] | None:
    """The pairs (nearest first), the per-parameter counts and what was searched; None before ``explain``."""
    if not has_view(inputs.con, "counterfactuals"):
        return None
    model = inputs.loaded.model.label
    totals = inputs.rows("SELECT count(*) AS searched, count(*) FILTER (WHERE found) AS found, "
                         "count(*) FILTER (WHERE NOT complete) AS cut, any_value(budget) AS budget, "
                         "count(*) FILTER (WHERE found AND fix_fragile) AS fragile, "
                         "count(*) FILTER (WHERE found AND nearest_distance IS NOT NULL) AS sturdier, "
                         "any_value(fragile_threshold) AS threshold, any_value(resolution) AS resolution "
                         "FROM counterfactuals")[0]
    if not totals["searched"]:
        return None
    # the run's failures (as explain counts them: counted, wrong): "all of them", or a sample of how many
    totals["failures"] = inputs.rows("SELECT count(*) AS n FROM results WHERE counted AND NOT correct")[0]["n"]
    pairs = inputs.rows("SELECT * FROM counterfactuals WHERE found ORDER BY distance, failure_job LIMIT ?", [CARDS])
    described = {r.job: inputs.results.describe(r) for r in inputs.results.rows([p["failure_job"] for p in pairs])}
    cards = [_card(inputs, row, described.get(row["failure_job"], f"job {row['failure_job']}")) for row in pairs]
    parameters = [{"parameter": p["parameter"], "cheapest": p["cheapest"], "alone": p["alone"],
                   "share": pct(p["share"], 0), "width": round(100 * (p["share"] or 0)),
                   "median": pct(p["median_share"], 1)}
                  for p in inputs.rows("SELECT * FROM counterfactual_parameters")]
    totals["resolution"] = share_words(totals["resolution"]) if totals["resolution"] is not None else None
    totals["threshold"] = f"{totals['threshold']:.3g}" if totals["threshold"] is not None else None
    return {"cards": cards, "parameters": parameters, "model": model, **totals}


def _card(inputs: PanelInputs, row: dict[str, Any], described: str) -> dict[str, Any]:
    """One failure | fix pair. Each side's caption is what the model said and the probability it
    gave the true class, named as such (``balloon · p(basketball) 19.6 %``); each image's hover
    text names the job and its configuration (``described``: ``job 3 · object = mug · …``), the
    fix's as the failure's with the change."""
    fixed_as = row["fix_label"] or row["true_labels"]
    true = f"p({row['true_labels'] or fixed_as})"
    said = row["failure_label"] or "no prediction"
    moved = "; ".join(f"{p} {a} → {b}" for p, a, b in zip(row["parameters"], row["from_values"], row["to_values"]))
    failure_probability, fix_probability = _pct(row["failure_probability"]), _pct(row["fix_probability"])
    failure_caption = f"{said} · {true} {failure_probability}" if failure_probability else said
    fix_caption = f"{fixed_as} · {true} {fix_probability}" if fix_probability else fixed_as
    return {
        "job": row["failure_job"], "object": row["object"], "environment": row["environment"],
        "failure_thumb": inputs.thumbs.want(row["failure_image_key"]),
        "fix_thumb": inputs.thumbs.want(row["fix_image_key"]),
        "said": said, "fix_label": fixed_as, "true": true,
        "failure_title": f"{described} · predicted {failure_caption} (wrong)",
        "fix_title": f"nearest fix of {described}, with {moved} · predicted {fix_caption} (right)",
        "sentence": f"{change_words(row)} makes it a {fixed_as}",
        "trust": trust_words(row), "fragile": row.get("fix_fragile") is True,
        "resolution": (resolution_words(row.get("resolution"), row["parameters"], row.get("resolutions"))
                       if row.get("nearest_distance") is None else None),
        "failure_probability": failure_probability, "fix_probability": fix_probability,
        "distance": f"{row['distance']:.3f}", "moved": moved,
    }


def _pct(value: float | None) -> str | None:
    return pct(value) if value is not None else None
