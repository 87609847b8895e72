"""The report's panels, in page order.

Adding a panel: write ``build(inputs: PanelInputs) -> dict | None`` in a module here and a
template ``templates/panels/<name>.html.j2`` that draws ``data`` (figures as
:class:`~sweep3d.report.figures.Figure`, drawn by the page with the ``figure`` macro of
``templates/_macros.html.j2``; images through ``inputs.thumbs.want(key)`` or ``inputs.tile(row)``),
then list it below. A panel whose data may be absent returns None and is left out of the page.

The explorer is ``late``: built after the others, it fills the image budget they leave.

``OPTIONAL_PANELS`` is where such panels go: the jobs that are not evaluable (only when there
are some: out of frame, or too little of the object visible), box and mask outcomes (only for
tasks whose results have an ``outcome`` or ``iou``), the model comparison (only when the spec
tests several models), the paired comparisons (only when the spec is paired: ``[policy]
paired``), the failure boundaries (only where a numeric parameter has enough results to fit) and
the part-visibility panel (accuracy conditioned on which parts of the object's
surface are visible, from a UV render pass) returns None when the spec did not ask for the pass;
the realism panel (agreement with photographs or another renderer) only once ``sweep3d realism
score`` has stored another source's verdicts; the nearest fixes (failure beside fix) only once
``sweep3d explain`` has run.
"""

from __future__ import annotations

from sweep3d.report.panel import Panel
from sweep3d.report.panels import (
    aggregate,
    boundaries,
    compare,
    explorer,
    failure_modes,
    failures,
    findings,
    nearest_fixes,
    not_evaluable,
    objects,
    outcomes,
    overall,
    paired,
    part_visibility,
    realism,
)

#: The first screen (open): the findings, graded, driving the explorer; every other panel is folded.
CORE_PANELS: tuple[Panel, ...] = (
    Panel("findings", "Findings", "panels/findings.html.j2", findings.build, open=True),
    Panel("explorer", "Explorer", "panels/explorer.html.j2", explorer.build, late=True, open=True),
    Panel("overall", "Overall accuracy", "panels/overall.html.j2", overall.build),
    Panel("failure-modes", "Failure modes", "panels/failure_modes.html.j2", failure_modes.build),
    Panel("failures", "Worst failures", "panels/failures.html.j2", failures.build),
    Panel("objects", "Per object", "panels/objects.html.j2", objects.build),
    Panel("aggregate", "Aggregate", "panels/aggregate.html.j2", aggregate.build),
)

NOT_EVALUABLE = Panel("not-evaluable", "Not evaluable", "panels/not_evaluable.html.j2", not_evaluable.build)
OUTCOMES = Panel("outcomes", "Boxes and masks", "panels/outcomes.html.j2", outcomes.build)
BOUNDARIES = Panel("boundaries", "Failure boundaries", "panels/boundaries.html.j2", boundaries.build)

#: Panels shown only when their data exists (their ``build`` returns None otherwise).
OPTIONAL_PANELS: tuple[Panel, ...] = (
    NOT_EVALUABLE,
    BOUNDARIES,
    OUTCOMES,
    Panel("compare", "Model comparison", "panels/compare.html.j2", compare.build),
    Panel("paired", "Paired comparisons", "panels/paired.html.j2", paired.build),
    Panel("part-visibility", "Part visibility", "panels/part_visibility.html.j2", part_visibility.build),
    Panel("realism", "Realism", "panels/realism.html.j2", realism.build),
    Panel("nearest-fixes", "Nearest fixes", "panels/nearest_fixes.html.j2", nearest_fixes.build),  # after explain
)

#: Page order: the findings and the explorer they drive, then (folded) the overall accuracy with what
#: was left out of it right after it, failure boundaries after the failure modes, box and mask outcomes
#: after the aggregate plots. What ``sweep3d confirm`` recorded shows in the findings list
#: (:func:`~sweep3d.report.panels.confirmations.verdict_row`), not in a panel of its own.
PANELS: tuple[Panel, ...] = (*CORE_PANELS[:3], NOT_EVALUABLE, CORE_PANELS[3], BOUNDARIES, *CORE_PANELS[4:],
                             *OPTIONAL_PANELS[2:])

__all__ = ["CORE_PANELS", "OPTIONAL_PANELS", "PANELS"]
