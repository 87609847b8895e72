"""The verdicts of ``sweep3d confirm``, kept in the store for ``run``'s findings and the report.

They are rows of the store's ``confirmations`` table (:mod:`.stored`): one per (experiment,
claim key, :mod:`sweep3d.followups.confirm.claims`) with its verdict, the renders and seed it was
drawn with, and the fresh jobs' experiment. A later confirmation replaces the claims it tests and
keeps the others (the newest row of a claim counts). A finding whose key has no row is
*unconfirmed*: a boundary that moved is a new claim.

Stores written before the table kept them in ``cache/confirm/<experiment>.json``: that file is
read as a fallback (the table's rows win), and the next ``confirm`` of the experiment, which
holds the writer lock, moves its claims into the table and removes it; a reader never changes it.
"""

from __future__ import annotations

import json
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pyarrow as pa

from sweep3d.cache import Store, safe_filename, utc_now
from sweep3d.followups.confirm.stored import CONFIRMATIONS, SCHEMA, VERDICT_FIELDS, confirmation_key
from sweep3d.results import UNCONFIRMED

Entry = dict[str, Any]  # {"text", "verdict": {Verdict's fields}, "renders", "seed", "drawn", "experiment"}


def legacy_path(store: Store, experiment: str) -> Path:
    """Where ``confirm`` kept an experiment's verdicts before the ``confirmations`` table."""
    return store.root / "cache" / "confirm" / f"{safe_filename(experiment)}.json"


def read_verdicts(store: Store, experiment: str) -> dict[str, Entry]:
    """Claim key → what was recorded of it ({} when nothing was): the table's newest row of each
    claim, over a store's older JSON file (a segment that does not read is skipped with a warning)."""
    return {**(_legacy(store, experiment) or {}), **{row["claim"]: _entry(row) for row in _rows(store, experiment)}}


def write_verdicts(store: Store, experiment: str, entries: dict[str, Entry]) -> None:
    """Record ``entries`` (claim key → entry) over what was recorded before, as one segment; call it
    holding the store's writer lock. The claims of an older JSON file the table lacks go in too
    (dated as the file), and the file is then removed."""
    now = utc_now()
    have = {row["claim"] for row in _rows(store, experiment)}
    found = _legacy(store, experiment)
    legacy = {claim: entry for claim, entry in (found or {}).items() if claim not in have and claim not in entries}
    path = legacy_path(store, experiment)
    dated = _mtime(path) if legacy else now
    moved = [row for claim, entry in legacy.items() if (row := _legacy_row(experiment, claim, entry, dated))]
    rows = moved + [_row(experiment, claim, entry, now) for claim, entry in entries.items()]
    store.append(CONFIRMATIONS, rows, SCHEMA)
    if found is not None and len(moved) == len(legacy):  # every claim the file held is in the table now
        path.unlink(missing_ok=True)


def status(verdicts: dict[str, Entry], key: str) -> str:
    """``confirmed``, ``not replicated`` or ``unconfirmed`` for the claim ``key``."""
    entry = verdicts.get(key)
    return entry["verdict"]["status"] if entry else UNCONFIRMED


def mark(verdicts: dict[str, Entry], key: str) -> str:
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


def _rows(store: Store, experiment: str) -> list[dict[str, Any]]:
    """The newest row of each of ``experiment``'s claims in the table."""
    data = store.table(CONFIRMATIONS)
    if data is None:
        return []
    newest: dict[str, dict[str, Any]] = {}
    for row in data.to_pylist():
        if row.get("experiment") != experiment:
            continue
        known = newest.get(row["confirmation_key"])
        if known is None or _when(row) >= _when(known):  # a later segment wins a tie, as it was written after
            newest[row["confirmation_key"]] = row
    return list(newest.values())


def _when(row: dict[str, Any]) -> datetime:
    at = row.get("created_at")
    if at is None:
        return datetime.min.replace(tzinfo=timezone.utc)
    return at if at.tzinfo else at.replace(tzinfo=timezone.utc)


def _entry(row: dict[str, Any]) -> Entry:
    return {"text": row.get("text"), "verdict": {name: row.get(name) for name in VERDICT_FIELDS.names},
            "renders": row.get("renders"), "seed": row.get("seed"), "drawn": row.get("drawn"),
            "experiment": row.get("fresh_experiment")}


def _row(experiment: str, claim: str, entry: Entry, at: datetime) -> dict[str, Any]:
    verdict = entry.get("verdict") or {}
    return {"confirmation_key": confirmation_key(experiment, claim), "experiment": experiment, "claim": claim,
            "text": entry.get("text"), **{name: verdict.get(name) for name in VERDICT_FIELDS.names},
            "renders": entry.get("renders"), "seed": entry.get("seed"), "drawn": entry.get("drawn"),
            "fresh_experiment": entry.get("experiment"), "created_at": at}


def _legacy(store: Store, experiment: str) -> dict[str, Entry] | None:
    """The claims of the experiment's JSON file from before the table (None when there is none, or
    it does not read back: a file that does not is left as it is)."""
    try:
        stored = json.loads(legacy_path(store, experiment).read_bytes())
    except (OSError, ValueError):
        return None
    claims = stored.get("claims") if isinstance(stored, dict) else None
    if not isinstance(claims, dict):
        return None
    return {k: v for k, v in claims.items() if isinstance(v, dict) and isinstance(v.get("verdict"), dict)}


def _legacy_row(experiment: str, claim: str, entry: Entry, at: datetime) -> dict[str, Any] | None:
    """A JSON entry as a row of the table; None when one of its values is not of its column's type
    (the file is then kept, and read as before)."""
    row = _row(experiment, claim, entry, at)
    try:
        pa.Table.from_pylist([row], schema=SCHEMA)
    except (pa.ArrowException, TypeError, ValueError, OverflowError):
        return None
    return row


def _mtime(path: Path) -> datetime:
    try:
        return datetime.fromtimestamp(path.stat().st_mtime, timezone.utc).replace(tzinfo=None)
    except OSError:
        return utc_now()
