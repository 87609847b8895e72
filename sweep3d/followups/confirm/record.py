"""The verdicts of ``sweep3d confirm``, kept in the store for ``run``'s findings and the report.

``cache/confirm/<experiment>.json`` maps each claim's key (:mod:`sweep3d.followups.confirm.claims`) to its
verdict, the renders and seed it was drawn with, and the fresh jobs' experiment. A later
confirmation replaces the claims it tests and keeps the others. A finding whose key has no entry
is *unconfirmed*: a boundary that moved is a new claim.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from sweep3d.cache import Store, atomic_write, safe_filename
from sweep3d.results import UNCONFIRMED


def record_path(store: Store, experiment: str) -> Path:
    return store.root / "cache" / "confirm" / f"{safe_filename(experiment)}.json"


def read_verdicts(store: Store, experiment: str) -> dict[str, dict[str, Any]]:
    """Claim key → what was recorded of it ({} when nothing was, or the file does not read back)."""
    try:
        stored = json.loads(record_path(store, experiment).read_bytes())
    except (OSError, ValueError):
        return {}
    claims = stored.get("claims") if isinstance(stored, dict) else None
    return claims if isinstance(claims, dict) else {}


def write_verdicts(store: Store, experiment: str, entries: dict[str, dict[str, Any]]) -> None:
    """Record ``entries`` (claim key → entry) over what was recorded before."""
    claims = {**read_verdicts(store, experiment), **entries}
    text = json.dumps({"format": 1, "claims": claims}, sort_keys=True, indent=1, allow_nan=False)
    atomic_write(record_path(store, experiment), text.encode())


def status(verdicts: dict[str, dict[str, Any]], key: str) -> str:
    """``confirmed``, ``not replicated`` or ``unconfirmed`` for the claim ``key``."""
    entry = verdicts.get(key)
    return entry["verdict"]["status"] if entry else UNCONFIRMED


def mark(verdicts: dict[str, dict[str, Any]], key: str) -> str:
    """What ``run`` prints after a finding: `` [confirmed: -42 pts on 20 fresh pairs, p = 0.001]``,
    `` [not replicated ...]`` or `` [unconfirmed: sweep3d confirm tests it]``."""
    entry = verdicts.get(key)
    if not entry:
        return " [unconfirmed: sweep3d confirm tests it on fresh renders]"
    v = entry["verdict"]
    if not v["pairs"]:
        return " [unconfirmed: no fresh configuration could be drawn]"
    return (f" [{v['status']} on {v['pairs']} fresh pairs: {100 * v['difference']:+.0f} pts "
            f"({100 * v['difference_low']:+.0f} to {100 * v['difference_high']:+.0f}), Holm p = {v['p_holm']:.2g}]")
