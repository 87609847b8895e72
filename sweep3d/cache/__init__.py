"""The content-addressed cache: canonical keys and the Parquet/DuckDB store."""

from sweep3d.cache.keys import canonical, digest, file_digest, files_digest
from sweep3d.cache.store import SegmentWriter, Store, StoreWriteError

__all__ = ["SegmentWriter", "Store", "StoreWriteError", "canonical", "digest", "file_digest", "files_digest"]
