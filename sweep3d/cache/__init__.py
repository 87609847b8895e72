"""The content-addressed cache: canonical keys and the Parquet/DuckDB store."""

from __future__ import annotations

__all__ = ["SegmentWriter", "Store", "StoreWriteError", "canonical", "digest", "file_digest", "files_digest"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.lazy import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.cache.keys import canonical, digest, file_digest, files_digest
    from sweep3d.cache.store import SegmentWriter, Store, StoreWriteError

__getattr__, __dir__ = _exports(__name__, {
    'SegmentWriter': ('sweep3d.cache.store', 'SegmentWriter'),
    'Store': ('sweep3d.cache.store', 'Store'),
    'StoreWriteError': ('sweep3d.cache.store', 'StoreWriteError'),
    'canonical': ('sweep3d.cache.keys', 'canonical'),
    'digest': ('sweep3d.cache.keys', 'digest'),
    'file_digest': ('sweep3d.cache.keys', 'file_digest'),
    'files_digest': ('sweep3d.cache.keys', 'files_digest'),
})
