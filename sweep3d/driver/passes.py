"""Which render passes a run needs: asked of everything that may consume one.

A pass is rendered only when something declared it: the spec (``[evaluator] passes``), the
evaluator class (its ``passes``), a rendered or post control (its ``passes``) or a report panel
(``[report] part_visibility`` needs the UV pass). Passes leave the RGB image alone, so none is
in the render key: the truth passes are keyed by ``truth_key`` (render key + the truth passes),
the UV pass by ``parts_key``.
"""

from __future__ import annotations

from sweep3d.core import PASSES, TRUTH_PASSES
from sweep3d.spec import LoadedSpec


def needed_passes(spec: LoadedSpec) -> tuple[str, ...]:
    """Every pass the spec's consumers need, sorted ("depth", "mask", "uv"); () for none.

    Any truth pass brings the mask: the ground-truth columns (box, visible fraction) come from it.
    """
    wanted = set(spec.evaluator.passes)
    evaluator = _evaluator(spec)
    wanted.update(getattr(evaluator, "passes", ()))
    for inst in spec.controls:
        wanted.update(getattr(inst.control, "passes", ()))
    if spec.report.part_visibility:
        wanted.add("uv")
    unknown = wanted - set(PASSES)
    if unknown:
        raise ValueError(f"unknown render passes {sorted(unknown)}; known: {list(PASSES)}")
    if wanted & set(TRUTH_PASSES):
        wanted.add("mask")
    return tuple(sorted(wanted))


def truth_passes(spec: LoadedSpec) -> tuple[str, ...]:
    """The truth passes of :func:`needed_passes` (they make a ``truths`` row); () for none."""
    return tuple(p for p in needed_passes(spec) if p in TRUTH_PASSES)


def visibility_gated(spec: LoadedSpec) -> bool:
    """Whether ``evaluable`` is decided by ``[evaluator] min_visible``: when the evaluation asked
    for a truth pass (``[evaluator] passes`` or the evaluator's own), not when only a control did
    (fog reads the depth pass: adding it must not change which results are counted)."""
    asked = set(spec.evaluator.passes) | set(getattr(_evaluator(spec), "passes", ()))
    return bool(asked & set(TRUTH_PASSES))


def _evaluator(spec: LoadedSpec):
    """The evaluator class ``[evaluator] kind`` names, from the registries the spec was loaded with."""
    assert spec.catalogue is not None, "a spec from the loader carries its catalogue"
    return spec.catalogue.evaluators.get(spec.evaluator.kind)
