"""The vocabulary every layer uses: errors, typed values, the plug-in registry, the control and
evaluation contracts, pixels, CSV text, ground truth and UV cells. Imports nothing of sweep3d's."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used. From outside, import through here.
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

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
