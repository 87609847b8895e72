"""A report panel: one section of the page, built from the store by one function.

A panel is data plus a template: ``build(inputs)`` returns what ``templates/<template>`` shows
(as ``data``), or None when the experiment has nothing for it, and then the page leaves the
panel out. Optional panels (e.g. part visibility, which needs a UV render pass) use this to show
only when their data exists; see :data:`sweep3d.report.panels.OPTIONAL_PANELS`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import duckdb

from sweep3d.cache.store import Store
from sweep3d.report.results import OUTCOME_NAMES, ResultTable
from sweep3d.report.thumbs import Thumbnails
from sweep3d.spec.loader import LoadedSpec
from sweep3d.stages.aggregate import Summary


@dataclass(frozen=True)
class PanelInputs:
    """What every panel may read.

    Attributes:
        loaded: the experiment's spec.
        con: a connection from ``aggregate.connect`` (``results`` and the aggregate views).
        summary: counts, the worst failures and per-control effects.
        table: every result with its parameter levels.
        thumbs: the page's images; ``thumbs.want(image_key)`` gives an index for a template.
        min_count: the fewest valid results a region needs to be ranked as a failure mode.
        store: the experiment's store (panels that cache what they draw keep it there).
    """

    loaded: LoadedSpec
    con: duckdb.DuckDBPyConnection
    summary: Summary
    table: ResultTable
    thumbs: Thumbnails
    min_count: int
    store: Store

    def rows(self, sql: str, params: list[Any] | None = None) -> list[dict[str, Any]]:
        """The rows of a query on :attr:`con`, each as a dict by column name."""
        cursor = self.con.execute(sql, params or [])
        names = [d[0] for d in cursor.description]
        return [dict(zip(names, row)) for row in cursor.fetchall()]

    def tile(self, row: int) -> dict[str, Any]:
        """A gallery tile for result ``row`` of :attr:`table`: thumbnail, outcome, prediction, details."""
        table = self.table
        outcome = OUTCOME_NAMES[int(table.outcome[row])]
        values = " · ".join(f"{p.name} = {p.labels[level]}" for p, level in zip(table.parameters, table.levels[:, row])
                            if level >= 0)
        prediction = table.prediction[row] or "no prediction"
        return {"thumb": self.thumbs.want(table.image_key[row]), "outcome": outcome, "caption": prediction,
                "title": f"job {int(table.job[row])} · {values} · predicted {prediction} ({outcome})"}


@dataclass(frozen=True)
class Panel:
    """One section of the report.

    Attributes:
        id: the section's HTML id (also its anchor in the page's navigation).
        title: the section's heading and navigation label.
        template: the Jinja template under ``templates/`` that draws ``data``.
        build: returns the template's ``data``, or None to leave the panel out.
    """

    id: str
    title: str
    template: str
    build: Callable[[PanelInputs], dict[str, Any] | None]


@dataclass(frozen=True)
class BuiltPanel:
    """A panel with its data, ready for the page template."""

    id: str
    title: str
    template: str
    data: dict[str, Any]


def build_panels(panels: tuple[Panel, ...], inputs: PanelInputs) -> list[BuiltPanel]:
    """Build ``panels`` in order, leaving out those whose ``build`` returns None."""
    built = []
    for panel in panels:
        data = panel.build(inputs)
        if data is not None:
            built.append(BuiltPanel(panel.id, panel.title, panel.template, data))
    return built
