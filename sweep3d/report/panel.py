"""A report panel: one section of the page, built from the store by one function.

A panel is data plus a template: ``build(inputs)`` returns what ``templates/<template>`` shows
(as ``data``), or None when the experiment has nothing for it, and then the page leaves the
panel out. Optional panels (e.g. part visibility, which needs a UV render pass) use this to show
only when their data exists; see :data:`sweep3d.report.panels.OPTIONAL_PANELS`. A ``late`` panel
is built after the others, whatever its place on the page: the explorer fills the image budget
the others leave.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import duckdb

from sweep3d.cache import Store
from sweep3d.report.reading import OUTCOME_NAMES, Parameter, ResultRow, Results
from sweep3d.report.thumbs import Thumbnails
from sweep3d.results import Summary
from sweep3d.spec import LoadedSpec


@dataclass(frozen=True)
class PanelInputs:
    """What every panel may read.

    Attributes:
        loaded: the experiment's spec.
        con: a connection from ``results.connect`` (``results`` and the aggregate views).
        summary: counts, the worst failures and per-control effects.
        results: every result with its parameter levels (kept by DuckDB; ask it for examples
            or counts, never for every row).
        thumbs: the page's images; ``thumbs.want(image_key)`` gives an index for a template.
        min_count: the fewest valid results a region needs to be ranked as a failure mode.
        store: the experiment's store (panels that cache what they draw keep it there).
    """

    loaded: LoadedSpec
    con: duckdb.DuckDBPyConnection
    summary: Summary
    results: Results
    thumbs: Thumbnails
    min_count: int
    store: Store

    def rows(self, sql: str, params: list[Any] | None = None) -> list[dict[str, Any]]:
        """The rows of a query on :attr:`con`, each as a dict by column name."""
        cursor = self.con.execute(sql, params or [])
        names = [d[0] for d in cursor.description]
        return [dict(zip(names, row)) for row in cursor.fetchall()]

    @property
    def parameters(self) -> list[Parameter]:
        """The parameters (object, environment, then the spec's controls) with their levels."""
        return self.results.parameters

    def tile(self, row: ResultRow) -> dict[str, Any]:
        """A gallery tile for one result: thumbnail, outcome, prediction, details."""
        outcome = OUTCOME_NAMES[row.outcome]
        prediction = row.prediction or "no prediction"
        caption = f"{prediction} · {row.why}" if row.why else prediction
        return {"thumb": self.thumbs.want(row.image_key), "outcome": outcome, "caption": caption,
                "title": f"{self.results.describe(row)} · predicted {caption} ({outcome})"}


@dataclass(frozen=True)
class Panel:
    """One section of the report.

    Attributes:
        id: the section's HTML id (also its anchor in the page's navigation).
        title: the section's heading and navigation label.
        template: the Jinja template under ``templates/`` that draws ``data``.
        build: returns the template's ``data``, or None to leave the panel out.
        late: build it after the panels that are not (it uses what they leave, e.g. images).
        open: shown on the page's first screen; the others are folded under their title (a click
            opens one), so the page before any click answers where the model fails, and no more.
    """

    id: str
    title: str
    template: str
    build: Callable[[PanelInputs], dict[str, Any] | None]
    late: bool = False
    open: bool = False


@dataclass(frozen=True)
class BuiltPanel:
    """A panel with its data, ready for the page template."""

    id: str
    title: str
    template: str
    data: dict[str, Any]
    open: bool = False


def build_panels(panels: tuple[Panel, ...], inputs: PanelInputs) -> list[BuiltPanel]:
    """Build ``panels`` (``late`` ones last), in page order, leaving out those whose ``build`` returns None."""
    data = {i: panels[i].build(inputs) for i in sorted(range(len(panels)), key=lambda i: panels[i].late)}
    return [BuiltPanel(panel.id, panel.title, panel.template, data[i], panel.open)
            for i, panel in enumerate(panels) if data[i] is not None]
