"""Export a run's results (by default its failures) as a dataset: COCO, ImageFolder or Parquet
(Hugging Face's layout), or a user's own format (``module:Name``, a :class:`DatasetWriter`
subclass beside the spec), each with ``design.csv``, the configurations that made them.

Usage::

    from sweep3d.export import export_dataset
    import sweep3d
    export_dataset(sweep3d.load("spec.toml").spec, "coco", output="failures")  # failures/annotations.json, images/
"""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.export.dataset import EXPORT_FORMATS, FORMATS, ExportResult, default_output, export_dataset
    from sweep3d.export.formats import Batch, DatasetWriter, Item
    from sweep3d.export.selection import IMAGE_DIGEST, image_bytes

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
