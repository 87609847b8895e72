"""Agreement of the simulation's verdicts with another source of images of the same jobs.

A *source* is another way of seeing a job's configuration: ``photo`` (photographs of the scene
recreated in a real room, ``sweep3d realism score``) or ``engine:<name>`` (the same
configuration rendered by another renderer). Its verdicts are rows of the store's ``verdicts``
table (``tables/verdicts/<segment>.parquet``, :data:`VERDICT_SCHEMA`): one per (source,
experiment, job, model) (its :func:`verdict_key`), the latest written winning, so scoring again
replaces a verdict.

Views (made by :func:`register_agreement_views` when the store holds verdicts of the experiment):

``source_verdicts``
    the latest verdict per (source, job, model) of the experiment, beside the simulation's:
    ``sim_correct`` (the run's ``correct``), ``source_correct``, both top-1 classes, the job's
    object and image key, and the source's file (``photo``) where it has one. Only results the
    run counts (``counted``) and valid source verdicts take part.
``agreement``
    per source × model × object, and per source × model over every object (``object`` NULL,
    ``overall`` true): ``n`` (jobs), ``n_agree``, ``agreement`` with its exact-edged 95 % Wilson
    interval (the ``wilson_low``/``wilson_high`` macros), ``n_sim_right``/``ppv`` (of the jobs the
    simulation got right, the share the source got right too), ``n_sim_wrong``/``npv`` (of those
    it got wrong, the share the source got wrong), and Cohen's κ on right/wrong. A ratio with no
    jobs under it is NULL, never NaN; κ is NULL where it is undefined (both sources gave one
    verdict on every job: chance agreement is then 1).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Sequence

import duckdb
import pyarrow as pa

from sweep3d.cache import Store
from sweep3d.results.quoting import literal

#: The store's table of other sources' verdicts (``tables/verdicts``; its contract is declared
#: by :mod:`sweep3d.followups.realism.stored`, which writes it).
VERDICTS = "verdicts"
#: Where ``realism score`` keeps each photograph it scored (framed as its render, a small JPEG
#: named by the SHA-256 of the photograph's file, recorded in its verdicts' ``photo_sha256``).
PHOTOS_FOLDER = ("realism", "photos")
AGREEMENT_VIEWS = ("source_verdicts", "agreement")
#: One source's verdict on one job for one model.
VERDICT_SCHEMA = pa.schema([
    ("verdict_key", pa.string()),   # names what the verdict is of: :func:`verdict_key`
    ("source", pa.string()),        # "photo", "engine:mitsuba"
    ("experiment", pa.string()),
    ("job", pa.int64()),
    ("model", pa.string()),         # the model's id in the spec (what results call it)
    ("valid", pa.bool_()),
    ("correct", pa.bool_()),
    ("top1_label", pa.string()),
    ("label_prob", pa.float64()),
    ("photo", pa.string()),         # the photograph's file name (photo source), else NULL
    ("photo_sha256", pa.string()),  # its bytes' SHA-256 (what was scored)
    ("image_key", pa.string()),     # the other engine's image key (engine sources), else NULL
    ("preprocess", pa.string()),    # how the source's image was brought to the model, in words
    ("created_at", pa.timestamp("us", tz="UTC")),
])




def verdict_key(source: str, experiment: str, job: int, model: str) -> str:
    """The ``verdicts`` table's key: what the verdict is of (a source's view of one job for one
    model), so the store's housekeeping (``cache compact``, ``stats``) keeps one per key, the
    newest (the table's contract merges by "newest"): scoring again replaces a verdict."""
    return hashlib.sha256(json.dumps([source, experiment, int(job), model]).encode()).hexdigest()


def photo_path(store: Store, sha256: str) -> Path:
    """The kept copy of the photograph whose file has the SHA-256 ``sha256``: as the model saw it
    (framed as its render, a small JPEG), for the report's render | photo pairs; under the
    store's ``realism/photos/``, which ``cache verify``, ``gc`` and ``stats`` know (the verdicts
    table's kept files)."""
    return store.root.joinpath(*PHOTOS_FOLDER, f"{sha256}.jpg")


def verdict_files(store: Store) -> list[Path]:
    """The readable segments of the store's ``verdicts`` table (unreadable ones are reported once)."""
    return [path for path in store.segments(VERDICTS) if store.read_segment(path, ["source"]) is not None]


def register_agreement_views(con: duckdb.DuckDBPyConnection, files: Sequence[Path], experiment: str | None) -> bool:
    """Create ``source_verdicts`` and ``agreement`` on ``con`` (which has ``results_all`` and the
    Wilson macros) over the verdict segments ``files``; False (nothing made) without verdicts,
    results or an experiment."""
    if not files or experiment is None or not _has(con, "results_all"):
        return False
    listing = ", ".join(literal(str(p)) for p in files)
    columns = {name for name, *_ in con.execute("DESCRIBE results_all").fetchall()}
    if not {"job", "object", "correct", "counted"} <= columns:
        return False
    model = "r.model = v.model" if "model" in columns else "true"
    top1 = "r.top1_label" if "top1_label" in columns else "NULL::VARCHAR"
    image = "r.image_key" if "image_key" in columns else "NULL::VARCHAR"
    con.execute(f"""CREATE OR REPLACE VIEW verdicts AS
        SELECT * FROM read_parquet([{listing}], union_by_name = true)
        WHERE experiment = {literal(experiment)}
        QUALIFY row_number() OVER (PARTITION BY source, job, model ORDER BY created_at DESC) = 1""")
    con.execute(f"""CREATE OR REPLACE VIEW source_verdicts AS
        SELECT v.source, v.model, v.job, r.object, r.environment, r.correct AS sim_correct,
               v.correct AS source_correct, {top1} AS sim_top1, v.top1_label AS source_top1,
               {image} AS image_key, v.image_key AS source_image_key, v.photo, v.photo_sha256, v.preprocess
        FROM verdicts v JOIN results_all r ON r.job = v.job AND {model}
        WHERE r.counted AND v.valid AND v.correct IS NOT NULL AND r.correct IS NOT NULL
        ORDER BY v.source, v.model, v.job""")
    con.execute("""CREATE OR REPLACE VIEW agreement AS
        WITH counts AS (
            SELECT source, model, object, GROUPING(object) = 1 AS overall, count(*) AS n,
                   count(*) FILTER (WHERE sim_correct = source_correct) AS n_agree,
                   count(*) FILTER (WHERE sim_correct) AS n_sim_right,
                   count(*) FILTER (WHERE NOT sim_correct) AS n_sim_wrong,
                   count(*) FILTER (WHERE source_correct) AS n_source_right,
                   count(*) FILTER (WHERE sim_correct AND source_correct) AS n_both_right,
                   count(*) FILTER (WHERE NOT sim_correct AND NOT source_correct) AS n_both_wrong
            FROM source_verdicts GROUP BY GROUPING SETS ((source, model, object), (source, model))),
        chance AS (
            SELECT *, n_agree / nullif(n, 0) AS observed,
                   (n_sim_right * n_source_right + n_sim_wrong * (n - n_source_right)) / nullif(n::DOUBLE * n, 0)
                       AS expected
            FROM counts)
        SELECT source, model, object, overall, n, n_agree, n_agree / nullif(n, 0) AS agreement,
               wilson_low(n_agree, n) AS wilson_low, wilson_high(n_agree, n) AS wilson_high,
               n_sim_right, n_both_right / nullif(n_sim_right, 0) AS ppv,
               n_sim_wrong, n_both_wrong / nullif(n_sim_wrong, 0) AS npv,
               (observed - expected) / nullif(1 - expected, 0) AS kappa
        FROM chance ORDER BY source, model, overall DESC, object""")
    return True


def _has(con: duckdb.DuckDBPyConnection, name: str) -> bool:
    return bool(con.execute("SELECT count(*) FROM duckdb_views() WHERE view_name = ?", [name]).fetchone()[0])
