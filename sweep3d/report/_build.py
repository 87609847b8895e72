"""Build the report: read the store, build each panel, write one self-contained HTML file.

The page runs offline: plotly.js and the report's scripts are inlined, figures and the
explorer's counts travel as JSON, a sample of thumbnails as data URIs (see
:mod:`sweep3d.report.page` for the Content-Security-Policy that keeps it so). What the page
carries grows with the numbers of parameter levels, not of results (see
:mod:`sweep3d.report.panels.explorer` and :mod:`sweep3d.report.thumbs`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import duckdb

from sweep3d.cache import STORE_FIX, Store, atomic_write
from sweep3d.core import UserError
from sweep3d.report.figures import pct
from sweep3d.report.overlays import read_overlays
from sweep3d.report.page import render_page
from sweep3d.report.panel import BuiltPanel, Panel, PanelInputs, build_panels
from sweep3d.report.panels import PANELS
from sweep3d.report.reading import Results, materialise_views
from sweep3d.report.thumbs import Thumbnails
from sweep3d.results import (
    COUNTERFACTUAL_VIEWS,
    GRADE_VIEWS,
    MACROS,
    MEASURES,
    VIEWS,
    PlannedStore,
    Summary,
    connect,
    has_view,
    no_results,
    numeric_scales,
    plan_protocol,
    region_min_count,
    register_failure_boundaries,
    results_store,
    summarise,
)
from sweep3d.results import VIEW as BOUNDARIES_VIEW
from sweep3d.runner import write_unstored_images
from sweep3d.spec import LoadedSpec
from sweep3d.stages.infer import measure_of

STAGES = ("render", "postprocess", "infer")


def write_report(loaded: LoadedSpec, output: Path | None = None, model: str | None = None) -> Path:
    """Write the experiment's HTML report and return its path.

    Args:
        loaded: the experiment's spec.
        output: the HTML file to write; default ``<store>/reports/<experiment>.html`` (with
            ``-<model>`` before the suffix for a model other than the spec's first).
        model: the model whose results the page shows (default: the spec's first); a spec with
            several models gets the comparison panel either way.

    Returns:
        The path written (atomically: a temp file renamed into place).

    Raises:
        UserError: if the store holds no results for the experiment, or the file cannot be written.
    """
    with results_store(loaded) as store:
        con = connect(store, loaded.name, model=model, read_once=True)
        try:
            context = build_context(loaded, con, store, model=model)
        finally:
            con.close()
    path = Path(output) if output is not None else default_path(loaded, model)
    # a page the user placed outside the store: moving the store would not help it
    fix = "write it to another disk with --output FILE.html" if output is not None else STORE_FIX
    try:
        atomic_write(path, render_html(context).encode("utf-8"), fix=fix)
    except OSError as exc:
        raise UserError(f"cannot write the report to {path} ({exc.strerror}); pass --output FILE.html") from None
    return path


def default_path(loaded: LoadedSpec, model: str | None = None) -> Path:
    """``<store>/reports/<experiment>.html`` (``<experiment>-<model>.html`` for a model other than
    the first), the name made safe for any file system."""
    name = loaded.name if model in (None, loaded.model.label) else f"{loaded.name}-{model}"
    return Store(loaded.store).report_path(name)


def build_context(loaded: LoadedSpec, con: duckdb.DuckDBPyConnection, store: Store,
                  panels: tuple[Panel, ...] = PANELS, model: str | None = None) -> dict[str, Any]:
    """Everything the page shows, as plain values (strings are escaped by the templates).

    Args:
        loaded: the experiment's spec.
        con: a connection from ``results.connect`` for this experiment (the views the report
            reads often are computed once on it: see :func:`~sweep3d.report.reading.materialise_views`).
        store: the store holding the image blobs.
        panels: the panels to build, in page order (those whose data is absent are left out).
        model: the model ``con`` shows (default: the spec's first).

    Raises:
        UserError: if there are no results for the experiment yet.
    """
    page = gather(loaded, con, store, panels)
    summary, thumbs = page.summary, page.thumbs
    shown = thumbs.keys()[:thumbs.limit]
    write_unstored_images(loaded, store, shown)  # images the run made in memory only ([postprocess] store)
    uris = thumbs.data_uris(overlays=read_overlays(con, store, shown))
    return {
        "name": loaded.name,
        "model": model or loaded.model.label,
        "protocol": plan_protocol(store.jobs_path(loaded.name), model or loaded.model.label),
        "spec_path": str(loaded.path),
        "store": str(loaded.store),
        "summary": summary,
        "accuracy": pct(summary.accuracy),
        "measure": measure_of(loaded.spec.evaluator),
        "wrong": summary.wrong,
        "run": _latest_run(con, loaded.name, loaded.text() if isinstance(store, PlannedStore) else None),
        "panels": page.panels,
        "fixed": page.fixed,
        "thumbs": json.dumps(uris, separators=(",", ":")),
        "thumb_problems": json.dumps(thumbs.problems, separators=(",", ":")),
        "thumb_size": thumbs.size,
        "images": {"shown": len(uris) - thumbs.missing - thumbs.damaged - thumbs.left_out, "of": page.images,
                   "missing": thumbs.missing, "damaged": thumbs.damaged, "left_out": thumbs.left_out},
        "views": [v for v in (*VIEWS, BOUNDARIES_VIEW, *COUNTERFACTUAL_VIEWS, *GRADE_VIEWS) if has_view(con, v)],
        "macros": MACROS,
    }


@dataclass(frozen=True)
class Gathered:
    """The page's panels before its images are encoded."""

    summary: Summary
    panels: list[BuiltPanel]
    thumbs: Thumbnails  # the images the panels asked for
    images: int  # distinct images in the results
    fixed: list[tuple[str, str]]  # parameters with one value: the header states them, no image card repeats them


def gather(loaded: LoadedSpec, con: duckdb.DuckDBPyConnection, store: Store,
           panels: tuple[Panel, ...] = PANELS) -> Gathered:
    """Read the store and build ``panels`` (see :func:`build_context`); no image is read yet."""
    if not has_view(con, "results") or not con.execute("SELECT count(*) FROM results").fetchone()[0]:
        raise no_results(store, loaded.name, loaded.path)
    materialise_views(con)
    columns = loaded.parameter_columns
    scales = numeric_scales(loaded.controls)
    register_failure_boundaries(con, scales)  # once: the summary's findings and the panel read it
    summary = summarise(con, columns, scales=scales)
    results = Results(con, ["object", "environment", *columns], MEASURES)
    images = con.execute("SELECT count(DISTINCT image_key) FROM results").fetchone()[0]
    thumbs = Thumbnails(store, images)
    inputs = PanelInputs(loaded, con, summary, results, thumbs, min_count(summary), store)
    return Gathered(summary, build_panels(panels, inputs), thumbs, images, results.fixed())


def image_keys(loaded: LoadedSpec, panels: tuple[Panel, ...] = PANELS) -> list[str]:
    """The image keys whose thumbnails the report of ``loaded`` embeds, in page order.

    A bounded sample, whatever the number of results; a tool that writes a synthetic store
    (``benchmarks/report_scale.py``) needs image blobs for these only.
    """
    with results_store(loaded) as store:
        con = connect(store, loaded.name, read_once=True)
        try:
            thumbs = gather(loaded, con, store, panels).thumbs
        finally:
            con.close()
    return thumbs.keys()[:thumbs.limit]


def render_html(context: dict[str, Any]) -> str:
    """The report page for a :func:`build_context` result."""
    return render_page(context)


def min_count(summary: Summary) -> int:
    """The fewest counted results a failure mode, or a value in the per-object sensitivity, needs:
    5 % of them, between 2 and 10 (as the printed findings)."""
    return region_min_count(summary.counted)


def _latest_run(con: duckdb.DuckDBPyConnection, experiment: str, spec: str | None = None) -> dict[str, Any] | None:
    """Run time and cache hits of the experiment's latest run (None if none is recorded); ``spec``:
    of its latest run of that spec text (the experiment last ran another version of it)."""
    if not has_view(con, "runs"):
        return None
    found = con.execute(
        "SELECT to_json(r) FROM (SELECT * EXCLUDE (spec, started_at, created_at), epoch(started_at) AS started "
        "FROM runs WHERE experiment = $experiment AND ($spec IS NULL OR spec = $spec) "
        "ORDER BY started_at DESC) r", {"experiment": experiment, "spec": spec}
    ).fetchall()
    if not found:
        return None
    runs = [json.loads(f[0]) for f in found]
    row = runs[0]
    stages = [
        {"stage": s, "cached": row[f"{s}_cached"], "total": row[f"{s}_total"]}
        for s in STAGES if row.get(f"{s}_total") is not None
    ]
    out = {"label": "latest run", "id": row["run_id"], "started": _when(row), "seconds": f"{row['seconds']:.1f} s",
           "stages": stages, "rerun": None}
    if _all_cached(row):  # a cached rerun's 0.2 s is not what the results cost: show the run that computed them
        rerun = f"rerun {_when(row)} in {row['seconds']:.1f} s, everything cached"
        made = next((r for r in runs if not _all_cached(r)), None)
        if made is None:
            return {**out, "rerun": "everything was cached (computed by another run's jobs)"}
        out.update(label="run time", id=made["run_id"], started=_when(made), seconds=f"{made['seconds']:.1f} s",
                   rerun=rerun)
    return out


def _all_cached(run: dict[str, Any]) -> bool:
    """Whether every stage of a ``runs`` row found all its keys cached (a rerun that made nothing)."""
    counts = [(run.get(f"{s}_cached"), run.get(f"{s}_total")) for s in STAGES if run.get(f"{s}_total") is not None]
    return bool(counts) and all(cached == total for cached, total in counts)


def _when(run: dict[str, Any]) -> str:
    return datetime.fromtimestamp(run["started"], timezone.utc).strftime("%Y-%m-%d %H:%M UTC")

