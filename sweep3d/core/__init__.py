"""The vocabulary every layer uses: errors, typed values, the plug-in registry, the control and
evaluation contracts, pixels, CSV text, ground truth and UV cells. Imports nothing of sweep3d's."""

from __future__ import annotations

__all__ = [
    "AZIMUTH_PARTS", "BLOB_SUFFIX", "Control", "ControlParams", "EDITED_TRUTH_VERSION",
    "ELEVATION_PARTS", "EVALUATOR_METADATA", "EvaluatorParams", "EvaluatorRecord", "OUTCOMES", "PARTS",
    "PARTS_LAYOUT", "PASSES", "PLUGIN_FAILURES", "PluginError", "Registry", "RenderError", "Roles",
    "SpecError", "SpecPath", "StoreBusyError", "TRUTH_PASSES", "TRUTH_VERSION", "Typed", "UV_MAP",
    "UserError", "blamed", "box", "code_identity", "control_label", "csv_text", "declaration_problem",
    "decode_depth", "decode_mask", "decode_png", "decode_png8", "encode_depth", "encode_mask", "encode_png",
    "encode_png8", "exports", "from_uint8", "ground_truth", "is_spec_path", "is_user_plugin",
    "linear_to_srgb", "loop_uvs", "part_bounds", "part_counts", "plugin_failure", "png_size",
    "printable", "read_record", "srgb_to_linear", "to_uint8", "wrap_periodic_many"
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles; from outside the package, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.core.control import (
        Control,
        ControlParams,
        SpecPath,
        blamed,
        control_label,
        is_spec_path,
        wrap_periodic_many,
    )
    from sweep3d.core.csv_format import csv_text
    from sweep3d.core.errors import (
        PLUGIN_FAILURES,
        PluginError,
        RenderError,
        SpecError,
        StoreBusyError,
        UserError,
        plugin_failure,
    )
    from sweep3d.core.evaluation import (
        EVALUATOR_METADATA,
        OUTCOMES,
        EvaluatorParams,
        EvaluatorRecord,
        Roles,
        declaration_problem,
        read_record,
    )
    from sweep3d.core.lazy import exports
    from sweep3d.core.pixels import (
        decode_png,
        decode_png8,
        encode_png,
        encode_png8,
        from_uint8,
        linear_to_srgb,
        png_size,
        srgb_to_linear,
        to_uint8,
    )
    from sweep3d.core.registry import Registry, code_identity, is_user_plugin
    from sweep3d.core.truth import (
        BLOB_SUFFIX,
        EDITED_TRUTH_VERSION,
        PASSES,
        TRUTH_PASSES,
        TRUTH_VERSION,
        box,
        decode_depth,
        decode_mask,
        encode_depth,
        encode_mask,
        ground_truth,
    )
    from sweep3d.core.typed import Typed, printable
    from sweep3d.core.uv_cells import (
        AZIMUTH_PARTS,
        ELEVATION_PARTS,
        PARTS,
        PARTS_LAYOUT,
        UV_MAP,
        loop_uvs,
        part_bounds,
        part_counts,
    )

__getattr__, __dir__ = _exports(__name__, {
    "AZIMUTH_PARTS": ("sweep3d.core.uv_cells", "AZIMUTH_PARTS"),
    "BLOB_SUFFIX": ("sweep3d.core.truth", "BLOB_SUFFIX"),
    "Control": ("sweep3d.core.control", "Control"),
    "ControlParams": ("sweep3d.core.control", "ControlParams"),
    "EDITED_TRUTH_VERSION": ("sweep3d.core.truth", "EDITED_TRUTH_VERSION"),
    "ELEVATION_PARTS": ("sweep3d.core.uv_cells", "ELEVATION_PARTS"),
    "EVALUATOR_METADATA": ("sweep3d.core.evaluation", "EVALUATOR_METADATA"),
    "EvaluatorParams": ("sweep3d.core.evaluation", "EvaluatorParams"),
    "EvaluatorRecord": ("sweep3d.core.evaluation", "EvaluatorRecord"),
    "OUTCOMES": ("sweep3d.core.evaluation", "OUTCOMES"),
    "PARTS": ("sweep3d.core.uv_cells", "PARTS"),
    "PARTS_LAYOUT": ("sweep3d.core.uv_cells", "PARTS_LAYOUT"),
    "PASSES": ("sweep3d.core.truth", "PASSES"),
    "PLUGIN_FAILURES": ("sweep3d.core.errors", "PLUGIN_FAILURES"),
    "PluginError": ("sweep3d.core.errors", "PluginError"),
    "Registry": ("sweep3d.core.registry", "Registry"),
    "RenderError": ("sweep3d.core.errors", "RenderError"),
    "Roles": ("sweep3d.core.evaluation", "Roles"),
    "SpecError": ("sweep3d.core.errors", "SpecError"),
    "SpecPath": ("sweep3d.core.control", "SpecPath"),
    "StoreBusyError": ("sweep3d.core.errors", "StoreBusyError"),
    "TRUTH_PASSES": ("sweep3d.core.truth", "TRUTH_PASSES"),
    "TRUTH_VERSION": ("sweep3d.core.truth", "TRUTH_VERSION"),
    "Typed": ("sweep3d.core.typed", "Typed"),
    "UV_MAP": ("sweep3d.core.uv_cells", "UV_MAP"),
    "UserError": ("sweep3d.core.errors", "UserError"),
    "blamed": ("sweep3d.core.control", "blamed"),
    "box": ("sweep3d.core.truth", "box"),
    "code_identity": ("sweep3d.core.registry", "code_identity"),
    "control_label": ("sweep3d.core.control", "control_label"),
    "csv_text": ("sweep3d.core.csv_format", "csv_text"),
    "declaration_problem": ("sweep3d.core.evaluation", "declaration_problem"),
    "decode_depth": ("sweep3d.core.truth", "decode_depth"),
    "decode_mask": ("sweep3d.core.truth", "decode_mask"),
    "decode_png": ("sweep3d.core.pixels", "decode_png"),
    "decode_png8": ("sweep3d.core.pixels", "decode_png8"),
    "encode_depth": ("sweep3d.core.truth", "encode_depth"),
    "encode_mask": ("sweep3d.core.truth", "encode_mask"),
    "encode_png": ("sweep3d.core.pixels", "encode_png"),
    "encode_png8": ("sweep3d.core.pixels", "encode_png8"),
    "exports": ("sweep3d.core.lazy", "exports"),
    "from_uint8": ("sweep3d.core.pixels", "from_uint8"),
    "ground_truth": ("sweep3d.core.truth", "ground_truth"),
    "is_spec_path": ("sweep3d.core.control", "is_spec_path"),
    "is_user_plugin": ("sweep3d.core.registry", "is_user_plugin"),
    "linear_to_srgb": ("sweep3d.core.pixels", "linear_to_srgb"),
    "loop_uvs": ("sweep3d.core.uv_cells", "loop_uvs"),
    "part_bounds": ("sweep3d.core.uv_cells", "part_bounds"),
    "part_counts": ("sweep3d.core.uv_cells", "part_counts"),
    "plugin_failure": ("sweep3d.core.errors", "plugin_failure"),
    "png_size": ("sweep3d.core.pixels", "png_size"),
    "printable": ("sweep3d.core.typed", "printable"),
    "read_record": ("sweep3d.core.evaluation", "read_record"),
    "srgb_to_linear": ("sweep3d.core.pixels", "srgb_to_linear"),
    "to_uint8": ("sweep3d.core.pixels", "to_uint8"),
    "wrap_periodic_many": ("sweep3d.core.control", "wrap_periodic_many"),
})
