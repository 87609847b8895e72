"""The spec: pydantic models of the TOML file, its loader, and the search space it defines.

This layer imports no stage: the plug-ins a spec names come in through a :class:`Catalogue`.
"""

from __future__ import annotations

__all__ = [
    "CLASS_NAMES_METADATA", "Catalogue", "Choice", "Column", "ControlInstance",
    "DROP_FRAGILE_METADATA", "ENGINES", "Fixed", "Framing", "JOB_COLUMNS", "KeyLightSpec", "LoadedSpec",
    "MIN_VISIBLE_METADATA", "MIN_VISIBLE_OFF", "MODELS_METADATA", "MODEL_NAME_COLUMNS", "MaterialSpec",
    "ModelSpec", "NameClash", "ObjectSpec", "PARAMETERS_METADATA", "PREDICTION_COLUMNS",
    "PROTOCOL_METADATA", "Point", "PointError", "PolicySpec", "Range", "RenderSpec", "SearchSpace",
    "Space", "SpaceShape", "Spec", "as_arrays", "as_points", "contract", "normal_name",
    "parameter_column", "plugin_folder", "read_spec", "spec_class_names", "unknown_name"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
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

__getattr__, __dir__ = _exports(__name__, {
    "CLASS_NAMES_METADATA": ("sweep3d.spec.columns", "CLASS_NAMES_METADATA"),
    "Catalogue": ("sweep3d.spec.catalogue", "Catalogue"),
    "Choice": ("sweep3d.spec.params", "Choice"),
    "Column": ("sweep3d.spec.space", "Column"),
    "ControlInstance": ("sweep3d.spec.loader", "ControlInstance"),
    "DROP_FRAGILE_METADATA": ("sweep3d.spec.columns", "DROP_FRAGILE_METADATA"),
    "ENGINES": ("sweep3d.spec.models", "ENGINES"),
    "Fixed": ("sweep3d.spec.params", "Fixed"),
    "Framing": ("sweep3d.spec.framing", "Framing"),
    "JOB_COLUMNS": ("sweep3d.spec.columns", "JOB_COLUMNS"),
    "KeyLightSpec": ("sweep3d.spec.models", "KeyLightSpec"),
    "LoadedSpec": ("sweep3d.spec.loader", "LoadedSpec"),
    "MIN_VISIBLE_METADATA": ("sweep3d.spec.columns", "MIN_VISIBLE_METADATA"),
    "MIN_VISIBLE_OFF": ("sweep3d.spec.columns", "MIN_VISIBLE_OFF"),
    "MODELS_METADATA": ("sweep3d.spec.columns", "MODELS_METADATA"),
    "MODEL_NAME_COLUMNS": ("sweep3d.spec.columns", "MODEL_NAME_COLUMNS"),
    "MaterialSpec": ("sweep3d.spec.models", "MaterialSpec"),
    "ModelSpec": ("sweep3d.spec.models", "ModelSpec"),
    "NameClash": ("sweep3d.spec.class_names", "NameClash"),
    "ObjectSpec": ("sweep3d.spec.models", "ObjectSpec"),
    "PARAMETERS_METADATA": ("sweep3d.spec.columns", "PARAMETERS_METADATA"),
    "PREDICTION_COLUMNS": ("sweep3d.spec.columns", "PREDICTION_COLUMNS"),
    "PROTOCOL_METADATA": ("sweep3d.spec.columns", "PROTOCOL_METADATA"),
    "Point": ("sweep3d.spec.space", "Point"),
    "PointError": ("sweep3d.spec.space", "PointError"),
    "PolicySpec": ("sweep3d.spec.models", "PolicySpec"),
    "Range": ("sweep3d.spec.params", "Range"),
    "RenderSpec": ("sweep3d.spec.models", "RenderSpec"),
    "SearchSpace": ("sweep3d.spec.space", "SearchSpace"),
    "Space": ("sweep3d.spec.params", "Space"),
    "SpaceShape": ("sweep3d.spec.space", "SpaceShape"),
    "Spec": ("sweep3d.spec.models", "Spec"),
    "as_arrays": ("sweep3d.spec.space", "as_arrays"),
    "as_points": ("sweep3d.spec.space", "as_points"),
    "contract": ("sweep3d.spec.space", "contract"),
    "normal_name": ("sweep3d.spec.class_names", "normal_name"),
    "parameter_column": ("sweep3d.spec.columns", "parameter_column"),
    "plugin_folder": ("sweep3d.spec.loader", "plugin_folder"),
    "read_spec": ("sweep3d.spec.sources", "read_spec"),
    "spec_class_names": ("sweep3d.spec.class_names", "spec_class_names"),
    "unknown_name": ("sweep3d.spec.looks", "unknown_name"),
})
