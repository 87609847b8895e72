"""Build the report: summary from the store, plotly figures, thumbnails, one HTML file.

The page runs offline. plotly.js is inlined once; each figure travels as JSON in a
``<script type="application/json">`` block that a small boot script draws with
``Plotly.newPlot``; thumbnails are base64 data URIs. A Content-Security-Policy allows only
those two inline scripts (by hash) and data-URI images, so the page can neither load anything
from the network nor run a script smuggled in through a name from a spec or a model.
"""

from __future__ import annotations

import base64
import hashlib
import html
import json
from datetime import datetime, timezone
from functools import lru_cache
from pathlib import Path
from typing import Any

import duckdb
import jinja2
from markupsafe import Markup

from sweep3d.cache.store import Store, atomic_write
from sweep3d.errors import UserError
from sweep3d.spec.loader import LoadedSpec
from sweep3d.stages.aggregate import ControlEffect, Summary, summarise

THUMB_SIZE = 96  # longest side of gallery thumbnails, pixels
STAGES = ("render", "postprocess", "infer")
COLORS = {"correct": "#2e9d5b", "wrong": "#d64545", "invalid": "#9aa0a6", "bar": "#4c72b0"}
FONT = "system-ui, -apple-system, Segoe UI, Roboto, sans-serif"

BOOT_JS = """
document.querySelectorAll('script.fig-data').forEach(function (node) {
  var fig = JSON.parse(node.textContent);
  Plotly.newPlot(node.dataset.target, fig.data, fig.layout,
                 {displaylogo: false, responsive: true, modeBarButtonsToRemove: ['select2d', 'lasso2d']});
});
"""

_JSON_ESCAPES = {"<": "\\u003c", ">": "\\u003e", "&": "\\u0026", "\u2028": "\\u2028", "\u2029": "\\u2029"}


def write_report(loaded: LoadedSpec, output: Path | None = None) -> Path:
    """Write the experiment's HTML report and return its path.

    Args:
        loaded: the experiment's spec.
        output: the HTML file to write; default ``<store>/reports/<experiment>.html``.

    Returns:
        The path written (atomically: a temp file renamed into place).

    Raises:
        UserError: if the store holds no results for the experiment, or the file cannot be written.
    """
    store = Store(loaded.store)
    con = store.connect(loaded.name)
    try:
        context = build_context(loaded, con, store)
    finally:
        con.close()
    path = Path(output) if output is not None else default_path(loaded)
    try:
        atomic_write(path, render_html(context).encode("utf-8"))
    except OSError as exc:
        raise UserError(f"cannot write the report to {path} ({exc.strerror}); pass --output FILE.html") from None
    return path


def default_path(loaded: LoadedSpec) -> Path:
    """``<store>/reports/<experiment>.html``, the name made safe for any file system."""
    return Store(loaded.store).report_path(loaded.name)


def build_context(loaded: LoadedSpec, con: duckdb.DuckDBPyConnection, store: Store) -> dict[str, Any]:
    """Everything the template shows, as plain values (strings are escaped by the template).

    Args:
        loaded: the experiment's spec.
        con: a connection from :meth:`Store.connect` for this experiment.
        store: the store holding the image blobs.

    Raises:
        UserError: if there are no results for the experiment yet.
    """
    if not _count_results(con):
        raise UserError(f"no results for experiment {loaded.name!r} yet; run: sweep3d run {loaded.path}")
    columns = [f"{c.id}_{p}" for c in loaded.controls for p in c.spaces]
    summary = summarise(con, columns)
    labels = {o.name: [str(label) for label in o.labels] for o in loaded.spec.objects}
    figures = {"outcomes": _outcome_figure(summary), "scenes": _scene_figure(summary)}
    return {
        "name": loaded.name,
        "model": loaded.spec.model.name,
        "spec_path": str(loaded.path),
        "store": str(loaded.store),
        "summary": summary,
        "accuracy": _pct(summary.accuracy),
        "wrong": summary.evaluated - summary.invalid - summary.correct,
        "run": _latest_run(con, loaded.name),
        "figures": figures,
        "effects": [(e.column, _effect_figure(e)) for e in summary.effects],
        "failures": _failures(loaded, con, store, summary, columns),
        "per_object": [
            {**row, "accuracy": _pct(row["accuracy"]), "labels": ", ".join(labels.get(row["object"], []))}
            for row in summary.per_object
        ],
    }


def render_html(context: dict[str, Any]) -> str:
    """The report page for a :func:`build_context` result."""
    plotly_js = _plotly_js()
    csp = "; ".join([
        "default-src 'none'",
        f"script-src {_csp_hash(plotly_js)} {_csp_hash(BOOT_JS)}",
        "style-src 'unsafe-inline'",
        "img-src data: blob:",
        "font-src data:",
    ])
    return _environment().get_template("report.html.j2").render(
        **context, plotly_js=Markup(plotly_js), boot_js=Markup(BOOT_JS), csp=csp
    )


def script_json(text: str) -> Markup:
    """JSON text made safe inside ``<script>``: ``<``, ``>`` and ``&`` become ``\\u003c`` etc.

    A name such as ``</script><script>…`` then cannot end the element early, and JSON.parse
    reads the same value back.
    """
    for char, escape in _JSON_ESCAPES.items():
        text = text.replace(char, escape)
    return Markup(text)


# -- data -------------------------------------------------------------------------------------
def _count_results(con: duckdb.DuckDBPyConnection) -> int:
    views = {r[0] for r in con.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal").fetchall()}
    if "results" not in views:
        return 0
    return con.execute("SELECT count(*) FROM results").fetchone()[0]


def _latest_run(con: duckdb.DuckDBPyConnection, experiment: str) -> dict[str, Any] | None:
    """Run time and cache hits of the experiment's latest run (None if none is recorded)."""
    if not con.execute("SELECT count(*) FROM duckdb_views() WHERE view_name = 'runs'").fetchone()[0]:
        return None
    found = con.execute(
        "SELECT to_json(r) FROM (SELECT * EXCLUDE (spec, started_at, created_at), epoch(started_at) AS started "
        "FROM runs WHERE experiment = ? ORDER BY started_at DESC LIMIT 1) r", [experiment]
    ).fetchone()
    if found is None:
        return None
    row = json.loads(found[0])
    stages = [
        {"stage": s, "cached": row[f"{s}_cached"], "total": row[f"{s}_total"]}
        for s in STAGES if row.get(f"{s}_total") is not None
    ]
    started = datetime.fromtimestamp(row["started"], timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return {"id": row["run_id"], "started": started, "seconds": f"{row['seconds']:.1f} s", "stages": stages}


def _failures(loaded: LoadedSpec, con: duckdb.DuckDBPyConnection, store: Store, summary: Summary,
              columns: list[str]) -> list[dict[str, Any]]:
    """Gallery cards of the worst failures: thumbnail, scene, control values, top-k."""
    jobs = [f["job"] for f in summary.failures]
    selected = ", ".join(f'"{c}"' for c in columns)
    extra = {
        r[0]: r[1:]
        for r in con.execute(
            f"SELECT job, topk{', ' + selected if selected else ''} FROM results WHERE list_contains(?, job)", [jobs]
        ).fetchall()
    } if jobs else {}
    thumbs: dict[str, str | None] = {}
    cards = []
    for failure in summary.failures:
        key = failure["image_key"]
        if key not in thumbs:
            thumbs[key] = _thumbnail(store, key)
        topk_ids, *values = extra.get(failure["job"], (None,))
        truth = set(loaded.labels.get(failure["object"], ()))
        names = failure["topk_labels"] or []
        ids = topk_ids or [None] * len(names)
        cards.append({
            "job": failure["job"],
            "object": failure["object"],
            "environment": failure["environment"],
            "thumbnail": thumbs[key],
            "controls": [(c, _fmt(v)) for c, v in zip(columns, values) if v is not None],
            "topk": [
                {"label": name, "prob": _pct(prob), "truth": i in truth or name in truth}
                for name, prob, i in zip(names, failure["topk_probs"] or [], ids)
            ],
            "loss": f"{failure['loss']:.2f}" if failure["loss"] is not None else "",
        })
    return cards


def _thumbnail(store: Store, key: str) -> str | None:
    """A PNG data URI of the blob ``key`` downscaled to THUMB_SIZE (None if the blob is gone)."""
    from sweep3d.pixels import thumbnail_png

    path = store.blob_path(key)
    try:
        data = thumbnail_png(path, THUMB_SIZE)
    except OSError:  # missing or unreadable blob: the card says so instead of failing the report
        return None
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


# -- figures ----------------------------------------------------------------------------------
def _layout(**extra: Any) -> dict[str, Any]:
    base = {
        "template": "plotly_white",
        "font": {"family": FONT, "size": 12},
        "margin": {"l": 56, "r": 16, "t": 40, "b": 48},
        "hoverlabel": {"font": {"family": FONT}},
    }
    return {**base, **extra}


def _outcome_figure(summary: Summary) -> str:
    """One stacked bar: correct, wrong and invalid predictions."""
    import plotly.graph_objects as go

    wrong = summary.evaluated - summary.invalid - summary.correct
    fig = go.Figure(layout=_layout(
        barmode="stack", height=150, margin={"l": 16, "r": 16, "t": 8, "b": 32},
        legend={"orientation": "h", "y": -0.35, "x": 0, "traceorder": "normal"}, yaxis={"visible": False},
        xaxis={"title": None, "range": [0, max(summary.evaluated, 1)]},
    ))
    for name, count in (("correct", summary.correct), ("wrong", wrong), ("invalid", summary.invalid)):
        fig.add_bar(
            name=name, y=["jobs"], x=[count], orientation="h", marker_color=COLORS[name],
            text=[count] if count else [""], textposition="inside",
            hovertemplate=f"{name}: %{{x}}<extra></extra>",
        )
    return fig.to_json()


def _effect_figure(effect: ControlEffect) -> str:
    """Accuracy at each value (or bin) of one control parameter, job counts in the hover."""
    import plotly.graph_objects as go

    fig = go.Figure(
        go.Bar(
            x=[_plot_text(label) for label in effect.labels], y=effect.accuracy, customdata=effect.count,
            marker_color=COLORS["bar"], texttemplate="%{y:.0%}", textposition="outside", cliponaxis=False,
            hovertemplate="%{x}<br>accuracy %{y:.1%}<br>%{customdata} jobs<extra></extra>",
        ),
        layout=_layout(
            title={"text": _plot_text(effect.column), "x": 0.02, "font": {"size": 14}}, height=300,
            xaxis={"type": "category"},
            yaxis={"range": [0, 1.12], "tickformat": ".0%", "title": {"text": "accuracy"}},
        ),
    )
    return fig.to_json()


def _scene_figure(summary: Summary) -> str:
    """Object × environment accuracy heatmap, with accuracy and job count in each cell."""
    import plotly.graph_objects as go

    text = [
        [f"{acc:.0%}<br>n={n}" if acc is not None else "" for acc, n in zip(accs, counts)]
        for accs, counts in zip(summary.scene_accuracy, summary.scene_count)
    ]
    fig = go.Figure(
        go.Heatmap(
            z=summary.scene_accuracy, x=[_plot_text(e) for e in summary.environments],
            y=[_plot_text(o) for o in summary.objects], zmin=0, zmax=1, colorscale="RdYlGn",
            text=text, texttemplate="%{text}", customdata=summary.scene_count, xgap=2, ygap=2,
            colorbar={"tickformat": ".0%", "title": {"text": "accuracy"}},
            hovertemplate="%{y} · %{x}<br>accuracy %{z:.1%}<br>%{customdata} jobs<extra></extra>",
        ),
        layout=_layout(
            height=max(260, 120 + 44 * len(summary.objects)),
            margin={"l": 16, "r": 16, "t": 16, "b": 48},
            xaxis={"type": "category", "title": {"text": "environment"}, "automargin": True},
            yaxis={"type": "category", "title": {"text": "object"}, "autorange": "reversed", "automargin": True},
        ),
    )
    return fig.to_json()


# -- helpers ----------------------------------------------------------------------------------
def _plot_text(value: Any) -> str:
    """Text for plotly, which reads a small HTML subset in labels: escape so names show literally."""
    return html.escape(str(value), quote=False)


def _pct(value: float | None) -> str:
    return "–" if value is None else f"{value:.1%}"


def _fmt(value: Any) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def _csp_hash(script: str) -> str:
    digest = hashlib.sha256(script.encode("utf-8")).digest()
    return "'sha256-" + base64.b64encode(digest).decode("ascii") + "'"


@lru_cache(maxsize=1)
def _plotly_js() -> str:
    from plotly.offline import get_plotlyjs

    # The HTML parser turns CR LF into LF; hash and emit the text the browser will see.
    return get_plotlyjs().replace("\r\n", "\n").replace("\r", "\n")


@lru_cache(maxsize=1)
def _environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("sweep3d.report", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters["script_json"] = script_json
    return env
