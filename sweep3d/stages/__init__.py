"""The pipeline stages: plan → render → postprocess → infer → aggregate (→ report).

Each stage owns its plug-ins, its key recipe and its table; :mod:`.driver` runs render,
postprocess and infer the same way for every caller. ``load_spec`` here loads a spec against
the built-in catalogue of all the stages' plug-ins.
"""

from sweep3d.stages.catalogue import catalogue, load_spec

__all__ = ["catalogue", "load_spec"]
