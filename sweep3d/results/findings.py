"""Every finding of a run, listed once, with its grade: the ``findings`` view.

A *finding* is a failure mode (``occluder = half``), a failure boundary (``camera_elevation fails
at 5 against 35``) or a box over several parameters (``yaw in 80–90 and blur ≥ 2``), as the summary
names them (:func:`listed_findings`: all of them, the boundaries the console leaves to the report
included). Each is kept as a row of the ``finding_grades`` table with a *grade* saying whether to
trust it (``sweep3d grade`` decides it; until then *untested*, and why):

``solid``
    replicated on fresh renders, reproduced by the second renderer, and not fragile;
``renderer-sensitive``
    replicated on fresh renders, but the second renderer bounds the effect below what matters;
``fragile``
    replicated, but not once the verdicts that a change no eye sees could flip are set aside;
``not replicated``
    fresh renders bound the effect below what matters;
``inconclusive``
    the budget ended before a check decided;
``untested``
    no check could be made, or none was yet (the evidence says which).

A *listing* is the set of findings one summary names (its ``listing`` column: a digest of their
keys and texts). ``run`` records its listing with every finding untested; ``grade`` writes the same
listing's rows again with their grades (the newest row of a key counts). The ``findings`` view
shows each model's latest listing, in the order the findings are printed.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Iterable, Mapping

import pyarrow as pa

from sweep3d.results.quoting import literal

if TYPE_CHECKING:
    import duckdb

    from sweep3d.cache import Store
    from sweep3d.results.summary import Summary

#: The store's table of findings and their grades (declared in :mod:`sweep3d.results.findings_table`).
FINDINGS_TABLE = "finding_grades"

SOLID = "solid"
RENDERER_SENSITIVE = "renderer-sensitive"
FRAGILE = "fragile"
NOT_REPLICATED_GRADE = "not replicated"
INCONCLUSIVE_GRADE = "inconclusive"
UNTESTED = "untested"
#: The grades, most trustworthy first (the report's order and colours follow it).
GRADES = (SOLID, RENDERER_SENSITIVE, FRAGILE, NOT_REPLICATED_GRADE, INCONCLUSIVE_GRADE, UNTESTED)

FAILURE_MODE, BOUNDARY, BOX = "failure mode", "boundary", "box"
#: The views over the grades (``findings`` once ``run`` listed its findings).
GRADE_VIEWS = ("findings", "failure_grades")

SCHEMA = pa.schema([
    ("finding_grade_key", pa.string()), ("experiment", pa.string()), ("model", pa.string()),
    ("listing", pa.string()), ("listed_at", pa.timestamp("us", tz="UTC")), ("rank", pa.int64()),
    ("kind", pa.string()), ("finding", pa.string()), ("text", pa.string()),
    ("grade", pa.string()), ("evidence", pa.string()),
    ("run_difference", pa.float64()),  # the run's accuracy inside less outside (None for a boundary's two sides)
    ("pairs", pa.int64()), ("effect", pa.float64()), ("effect_low", pa.float64()), ("effect_high", pa.float64()),
    ("engine", pa.string()), ("engine_pairs", pa.int64()), ("engine_effect", pa.float64()),
    ("fragile_set_aside", pa.int64()),  # fresh wrong verdicts set aside as fragile
    ("details", pa.string()),  # JSON: each check's verdict as recorded
    ("created_at", pa.timestamp("us", tz="UTC")),
])


def region_key(column: str, label: str) -> str:
    """The key of the failure mode ``column = label``."""
    return f"value {column} = {label}"


def boundary_key(row: Mapping[str, Any]) -> str:
    """The key of a significant boundary (a ``failure_boundaries`` row): its parameter, group, side
    and place (to 6 digits: a boundary that moved is another finding)."""
    who = "" if row["scope"] == "all" else f" {row['scope']} {row[row['scope']]}"
    return f"boundary {row['parameter']}{who} fails {row['fails']} {row['boundary']:.6g}"


def rule_key(key: str) -> str:
    """The key of a rule (its conditions as ``rules`` writes them)."""
    return f"rule {key}"


@dataclass(frozen=True)
class Finding:
    """One finding as the summary names it; ``source`` is the summary's row (a region, a boundary
    or a rule), for the check that tests it."""

    key: str
    kind: str
    text: str
    rank: int
    source: Mapping[str, Any]
    run_difference: float | None = None


def boundary_text(row: Mapping[str, Any]) -> str:
    """``toaster: camera_elevation fails below 12.1`` (plain text)."""
    from sweep3d.results.boundaries import boundary_phrase  # it reads the views, which make this module's

    who = "" if row["scope"] == "all" else f"{row[row['scope']]}: "
    return f"{who}{row['parameter']} {boundary_phrase(row)}"


def listed_findings(summary: Summary) -> list[Finding]:
    """Every finding of ``summary``: each significant failure mode, each significant boundary (those
    the console leaves to the report included), each significant box over several parameters."""
    from sweep3d.results.summary import named_rules

    out: list[Finding] = []
    for region in summary.regions:
        out.append(Finding(region_key(region["column"], region["label"]), FAILURE_MODE,
                           f"{region['column']} = {region['label']}", len(out), region, region.get("difference")))
    for row in [*summary.boundaries, *summary.boundaries_more]:
        out.append(Finding(boundary_key(row), BOUNDARY, boundary_text(row), len(out), row, _boundary_gap(row)))
    for rule in named_rules(summary, limit=len(summary.rules)):
        out.append(Finding(rule_key(rule["key"]), BOX, rule["text"], len(out), rule, rule.get("difference")))
    return out


def _boundary_gap(row: Mapping[str, Any]) -> float | None:
    below, above = row.get("accuracy_below"), row.get("accuracy_above")
    if below is None or above is None:
        return None
    return (below - above) if row["fails"] == "below" else (above - below)


#: The row that stands for a listing of no finding (the ``findings`` view leaves it out).
NO_FINDING = Finding("", "none", "", -1, {})


def listing_of(findings: Iterable[Finding]) -> str:
    """The digest naming a set of findings (their keys and texts, in order)."""
    text = json.dumps([[f.key, f.text] for f in findings], ensure_ascii=False)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def finding_grade_key(experiment: str, model: str, listing: str, finding: str) -> str:
    """A row's key: which finding of which listing it grades."""
    return hashlib.sha256("\0".join((experiment, model, listing, finding)).encode()).hexdigest()


def grade_row(experiment: str, model: str, listing: str, listed_at: Any, finding: Finding, grade: str,
              evidence: str, **values: Any) -> dict[str, Any]:
    """One ``finding_grades`` row (``values``: the SCHEMA's optional columns)."""
    from sweep3d.cache import utc_now

    unknown = set(values) - set(SCHEMA.names)
    if unknown:
        raise ValueError(f"not columns of {FINDINGS_TABLE}: {sorted(unknown)}")
    if grade not in GRADES:
        raise ValueError(f"not a grade: {grade!r}")
    row = {name: None for name in SCHEMA.names}
    row.update(values)
    row.update(finding_grade_key=finding_grade_key(experiment, model, listing, finding.key), experiment=experiment,
               model=model, listing=listing, listed_at=listed_at, rank=finding.rank, kind=finding.kind,
               finding=finding.key, text=finding.text, grade=grade, evidence=evidence,
               run_difference=finding.run_difference, created_at=utc_now())
    return row


def not_graded(spec_path: Any) -> str:
    """The evidence of a finding no grading has looked at yet."""
    return f"not graded yet: sweep3d grade {spec_path} grades it"


def stored_rows(store: Store, experiment: str, model: str) -> list[dict[str, Any]]:
    """The newest row of each key of ``experiment``'s ``model`` in the table (any listing)."""
    table = store.table(FINDINGS_TABLE)
    if table is None:
        return []
    newest: dict[str, dict[str, Any]] = {}
    for row in table.to_pylist():
        if row.get("experiment") != experiment or row.get("model") != model:
            continue
        old = newest.get(row["finding_grade_key"])
        if old is None or row["created_at"] >= old["created_at"]:
            newest[row["finding_grade_key"]] = row
    return list(newest.values())


def latest_listing(rows: list[dict[str, Any]]) -> str | None:
    """The listing of the newest ``listed_at`` among ``rows`` (None without rows)."""
    if not rows:
        return None
    return max(rows, key=lambda r: (r["listed_at"], r["created_at"]))["listing"]


def record_listing(store: Store, experiment: str, model: str, findings: list[Finding], spec_path: Any) -> str:
    """Make ``findings`` the latest listing of ``experiment``'s ``model``; returns its digest.

    Nothing is written when it already is. A listing recorded before (the findings came back)
    is written again as it was graded; a new one with every finding untested."""
    from sweep3d.cache import utc_now

    listing = listing_of(findings)
    rows = stored_rows(store, experiment, model)
    if latest_listing(rows) == listing or (not findings and not rows):
        return listing
    now = utc_now()
    earlier = {r["finding"]: r for r in rows if r["listing"] == listing}
    fresh = []
    for finding in findings or [NO_FINDING]:  # none now: one marker row makes the empty listing the latest
        old = earlier.get(finding.key)
        if old is not None:
            fresh.append({**old, "listed_at": now, "created_at": now})
        else:
            fresh.append(grade_row(experiment, model, listing, now, finding, UNTESTED, not_graded(spec_path)))
    store.append(FINDINGS_TABLE, fresh, SCHEMA)
    return listing


VIEW_COLUMNS = ("model", "rank", "kind", "finding", "text", "grade", "evidence", "run_difference", "pairs",
                "effect", "effect_low", "effect_high", "engine", "engine_pairs", "engine_effect",
                "fragile_set_aside", "created_at")


def register_findings_view(con: duckdb.DuckDBPyConnection, experiment: str | None) -> bool:
    """Create ``findings`` (each model's latest listing, in printed order) when the store has rows
    of ``experiment`` in ``finding_grades`` (its view exists on ``con``); False when not."""
    if experiment is None:
        return False
    have = con.execute("SELECT count(*) FROM duckdb_views() WHERE view_name = ?", [FINDINGS_TABLE]).fetchone()[0]
    if not have:
        return False
    mine = f"SELECT * FROM {FINDINGS_TABLE} WHERE experiment = {literal(experiment)}"
    if not con.execute(f"SELECT count(*) FROM ({mine})").fetchone()[0]:
        return False
    con.execute(f"""CREATE OR REPLACE VIEW findings AS
        WITH mine AS ({mine}),
        latest AS (SELECT model, arg_max(listing, listed_at) AS listing FROM mine GROUP BY model)
        SELECT {', '.join(VIEW_COLUMNS)} FROM mine JOIN latest USING (model, listing)
        WHERE finding <> '' ORDER BY model, rank""")
    return True


# -- failure images ---------------------------------------------------------------------------------

#: The store's table of graded failure images: one row per (experiment, model, prediction).
IMAGES_TABLE = "image_grades"
IMAGE_SCHEMA = pa.schema([
    ("image_grade_key", pa.string()), ("experiment", pa.string()), ("model", pa.string()),
    ("pred_key", pa.string()), ("grade", pa.string()), ("evidence", pa.string()),
    ("created_at", pa.timestamp("us", tz="UTC")),
])


def image_grade_row(experiment: str, model: str, pred_key: str, grade: str, evidence: str) -> dict[str, Any]:
    """One ``image_grades`` row: a failure image's grade and why."""
    from sweep3d.cache import utc_now

    if grade not in GRADES:
        raise ValueError(f"not a grade: {grade!r}")
    key = hashlib.sha256("\0".join((experiment, model, pred_key)).encode()).hexdigest()
    return {"image_grade_key": key, "experiment": experiment, "model": model, "pred_key": pred_key, "grade": grade,
            "evidence": evidence, "created_at": utc_now()}


def register_failure_grades_view(con: duckdb.DuckDBPyConnection, experiment: str | None) -> bool:
    """Create ``failure_grades``: every counted failure of ``results`` with its grade (``untested``
    where no grading checked it); False (nothing made) without results."""
    have = {r[0] for r in con.execute("SELECT view_name FROM duckdb_views()").fetchall()}
    if experiment is None or "results" not in have:
        return False
    graded = (f"(SELECT pred_key, grade, evidence FROM {IMAGES_TABLE} WHERE experiment = {literal(experiment)})"
              if IMAGES_TABLE in have else "(SELECT NULL::VARCHAR AS pred_key, NULL::VARCHAR AS grade, "
                                            "NULL::VARCHAR AS evidence WHERE false)")
    columns = {r[0] for r in con.execute("DESCRIBE results").fetchall()}
    if not {"job", "object", "environment", "pred_key", "image_key", "valid", "correct"} <= columns:
        return False  # a results view made by hand, without what a failure is
    counted = "r.counted" if "counted" in columns else "r.valid"
    con.execute(f"""CREATE OR REPLACE VIEW failure_grades AS
        SELECT r.job, r.object, r.environment, r.pred_key, r.image_key,
               coalesce(g.grade, {literal(UNTESTED)}) AS grade,
               coalesce(g.evidence, 'not in a graded sample: sweep3d grade checks a sample of the failures') AS evidence
        FROM results r LEFT JOIN {graded} g USING (pred_key)
        WHERE {counted} AND NOT r.correct ORDER BY r.job""")
    return True


def _declare() -> None:
    from sweep3d.cache import TableContract, register_table

    register_table(TableContract(FINDINGS_TABLE, key="finding_grade_key", columns=tuple(SCHEMA.names),
                                 merge="newest"))
    register_table(TableContract(IMAGES_TABLE, key="image_grade_key", columns=tuple(IMAGE_SCHEMA.names),
                                 merge="newest"))


_declare()  # the package root names this module (``declare_table_modules``): every command sees the table
