"""``sweep3d confirm``: a run's findings tested again on fresh renders.

:mod:`.claims` turns the findings ``run`` prints into regions of the parameters, :mod:`.draw`
draws fresh twin configurations inside and outside each, :mod:`.confirm` renders them through
the normal cached stages and judges them (statistics in
:mod:`sweep3d.stages.aggregate.confirmation`), and :mod:`.record` keeps the verdicts in the store
for ``run``'s findings and the report.
"""
