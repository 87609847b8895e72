"""Export a run's results (by default its failures) as a dataset: COCO, ImageFolder or Parquet
(Hugging Face's layout), or a user's own format (``module:Name``, a :class:`DatasetWriter`
subclass beside the spec), each with ``design.csv``, the configurations that made them.

Usage::

    from sweep3d.export import export_dataset
    import sweep3d
    export_dataset(sweep3d.load("spec.toml").spec, "coco", output="failures")  # failures/annotations.json, images/
"""

from __future__ import annotations

__all__ = ["Batch", "DatasetWriter", "EXPORT_FORMATS", "ExportResult", "FORMATS", "Item", "IMAGE_DIGEST", "default_output", "export_dataset", "image_bytes"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.export.dataset import EXPORT_FORMATS, FORMATS, ExportResult, default_output, export_dataset
    from sweep3d.export.formats import Batch, DatasetWriter, Item
    from sweep3d.export.selection import IMAGE_DIGEST, image_bytes

__getattr__, __dir__ = _exports(__name__, {
    "Batch": ("sweep3d.export.formats", "Batch"),
    "DatasetWriter": ("sweep3d.export.formats", "DatasetWriter"),
    "EXPORT_FORMATS": ("sweep3d.export.dataset", "EXPORT_FORMATS"),  # there, the built-ins have registered
    "ExportResult": ("sweep3d.export.dataset", "ExportResult"),
    "FORMATS": ("sweep3d.export.dataset", "FORMATS"),
    "Item": ("sweep3d.export.formats", "Item"),
    "IMAGE_DIGEST": ("sweep3d.export.selection", "IMAGE_DIGEST"),
    "default_output": ("sweep3d.export.dataset", "default_output"),
    "export_dataset": ("sweep3d.export.dataset", "export_dataset"),
    "image_bytes": ("sweep3d.export.selection", "image_bytes"),
})
