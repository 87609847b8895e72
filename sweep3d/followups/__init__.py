"""The follow-ups of a finished run, side by side: each asks whether a failure is real, hands the
runner plans (so keys, cache, resumption, the lock and ``--executor ray`` are a run's) and keeps its
results under a contract the store knows only by declaration (docs/architecture/followups.md).

- ``stability``: which verdicts a change no eye sees flips. Plan: the sampled jobs; postprocess,
  then its own ``StabilityStage``. Keeps: the ``stability`` table (``stability/stored.py``).
- ``explain``: the nearest change that fixes each failure. Plan: one per search round (its
  probes). Keeps: the ``counterfactuals`` table (``explain/stored.py``).
- ``confirm``: each finding tested on fresh twin renders. Plan: the twins as the explicit jobs of
  ``<name>-confirm``. Keeps: the ``confirmations`` table (``confirm/stored.py``).
- ``realism``: agreement with photographs or another engine. Plan: ``score --engine``, the kit's
  jobs as a run of that engine. Keeps: the ``verdicts`` table and kept photos
  (``realism/stored.py``).
- ``grade``: one grade per finding (solid, renderer-sensitive, fragile, not replicated,
  inconclusive, untested) from the stability check, ``confirm``'s twins and the same twins
  rendered by the second renderer, under one budget. Keeps: the ``finding_grades`` table
  (declared in ``sweep3d.results.findings``; ``run`` writes its untested listing), read as the
  ``findings`` view.

This package imports nothing: each follow-up is its own unit of the layers
(tests/test_import_layers.py), reached through its own ``__init__``.
"""
