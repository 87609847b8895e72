"""The built-in catalogue: every stage's plug-in registries, for the spec loader.

The spec layer imports no stage; this module, one layer up, hands it the stages' registries.
"""

from __future__ import annotations

from functools import lru_cache

from sweep3d.core import Registry
from sweep3d.spec import Catalogue
from sweep3d.stages.infer import EVALUATORS, MODELS, builtin_labels
from sweep3d.stages.plan import POLICIES
from sweep3d.stages.postprocess import POST_CONTROLS
from sweep3d.stages.render import BACKENDS, RENDERED_CONTROLS


@lru_cache(maxsize=1)
def builtin_catalogue() -> Catalogue:
    """The built-in controls, policies, models and evaluators (users' own come by ``module:Name``),
    and the registered engines."""
    controls = Registry.union("control", RENDERED_CONTROLS, POST_CONTROLS)
    return Catalogue(controls, POLICIES, MODELS, EVALUATORS, builtin_labels, BACKENDS)

