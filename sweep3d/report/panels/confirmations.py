"""Confirmations: each finding of the run tested again on fresh renders (``sweep3d confirm``).

The page shows them in the findings list (each finding's evidence, a click away; see
:mod:`sweep3d.report.panels.findings`), not as a panel of their own. Once a confirmation has
been recorded for the experiment: every significant failure mode and boundary the run names, marked confirmed, not replicated or unconfirmed (not tested since it
was found), with the fresh twins' accuracy inside and outside and the paired difference (see
:mod:`sweep3d.results.confirmation`).
"""

from __future__ import annotations

from typing import Any

from sweep3d.followups.confirm import boundary_key, read_verdicts, region_key, rule_key
from sweep3d.report.figures import p_text, pct
from sweep3d.report.panel import PanelInputs
from sweep3d.results import UNCONFIRMED, boundary_phrase, named_rules


def build(inputs: PanelInputs) -> dict[str, Any] | None:
    verdicts = read_verdicts(inputs.store, inputs.loaded.name)
    if not verdicts:
        return None
    summary = inputs.summary
    findings = [(region_key(r["column"], r["label"]), f"{r['column']} = {r['label']}") for r in summary.regions]
    for b in summary.boundaries:
        who = "" if b["scope"] == "all" else f"{b[b['scope']]}: "
        findings.append((boundary_key(b), f"{who}{b['parameter']} {boundary_phrase(b)}"))
    findings += [(rule_key(r["key"]), r["text"]) for r in named_rules(summary)]
    if not findings:
        return None
    return {"rows": [{"finding": text, **verdict_row(verdicts.get(key))} for key, text in findings]}


def verdict_row(entry: dict[str, Any] | None) -> dict[str, Any]:
    """What ``sweep3d confirm`` recorded of one finding (its entry of ``read_verdicts``, None when it
    was not tested): status, pairs, fresh accuracy inside and outside, difference, Holm p."""
    v = entry["verdict"] if entry else None
    tested = v is not None and v["pairs"] > 0
    return {
        "status": v["status"] if v else UNCONFIRMED, "pairs": v["pairs"] if v else 0,
        "inside": pct(v["accuracy_inside"], 0) if tested else "", "outside": pct(v["accuracy_outside"], 0)
        if tested else "",
        "difference": (f"{100 * v['difference']:+.0f} pts ({100 * v['difference_low']:+.0f} to "
                       f"{100 * v['difference_high']:+.0f})") if tested else "",
        "p": p_text(v["p_holm"]) if tested else ""}
