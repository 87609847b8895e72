"""The spec: pydantic models of the TOML file, its loader, and the search space it defines.

This layer imports no stage: the plug-ins a spec names come in through a :class:`Catalogue`.
"""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.spec.catalogue import Catalogue
    from sweep3d.spec.class_names import NameClash, normal_name, spec_class_names
    from sweep3d.spec.columns import (
        CLASS_NAMES_METADATA,
        DROP_FRAGILE_METADATA,
        JOB_COLUMNS,
        MIN_VISIBLE_METADATA,
        MIN_VISIBLE_OFF,
        MODEL_NAME_COLUMNS,
        MODELS_METADATA,
        PARAMETERS_METADATA,
        PREDICTION_COLUMNS,
        PROTOCOL_METADATA,
        parameter_column,
    )
    from sweep3d.spec.framing import Framing
    from sweep3d.spec.loader import ControlInstance, LoadedSpec, plugin_folder
    from sweep3d.spec.looks import unknown_name
    from sweep3d.spec.models import (
        ENGINES,
        KeyLightSpec,
        MaterialSpec,
        ModelSpec,
        ObjectSpec,
        PolicySpec,
        RenderSpec,
        Spec,
    )
    from sweep3d.spec.params import Choice, Fixed, Range, Space
    from sweep3d.spec.sources import read_spec
    from sweep3d.spec.space import Column, Point, PointError, SearchSpace, SpaceShape, as_arrays, as_points, contract

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
