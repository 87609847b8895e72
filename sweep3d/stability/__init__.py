"""The stability check (``sweep3d stability``): which verdicts changes no eye sees can flip.

:mod:`~sweep3d.stability.changes` makes the changes and computes margins from logits;
:mod:`~sweep3d.stability.check` samples a run's results, re-infers and stores the rows. The views that
turn the rows into flip rates and the ``fragile`` column are :mod:`sweep3d.stages.aggregate.fragile`.
"""
