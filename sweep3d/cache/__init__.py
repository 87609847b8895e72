"""The content-addressed cache: canonical keys and the Parquet/DuckDB store."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.cache.blobs import (
        Verified,
        damaged_blobs,
        load_image,
        load_pass,
        load_pixels,
        remember_verified,
        sha256_bytes,
        verified_now,
    )
    from sweep3d.cache.compaction import compact_table
    from sweep3d.cache.contracts import (
        KEY_COLUMN,
        TABLES,
        KeptFiles,
        TableContract,
        contract_of,
        register_store_folder,
        register_table,
        table_contract,
        table_contracts,
        table_names,
        unregister_table,
    )
    from sweep3d.cache.declared import declare_table_modules
    from sweep3d.cache.digested import OUTPUTS_FOLDER, SUFFIX, pack, unpack
    from sweep3d.cache.extracted import ASSETS_FOLDER, MANIFEST, members, read_manifest, record, stale
    from sweep3d.cache.files import (
        STORE_FIX,
        StoreWriteError,
        atomic_write,
        full_disk_error,
        is_full_disk,
        read_parquet,
        safe_filename,
        scan,
        store_error,
        utc_now,
    )
    from sweep3d.cache.garbage import collect_garbage, remove_killed_writers_temp_files
    from sweep3d.cache.hashing import (
        Hole,
        Template,
        canonical,
        canonical_pieces,
        digest,
        digests,
        file_digest,
        files_digest,
        float_texts,
    )
    from sweep3d.cache.pandas_probe import skip_pandas_probe
    from sweep3d.cache.query import is_select, lock_down
    from sweep3d.cache.repairs import repair
    from sweep3d.cache.snapshot import MIN_JOBS
    from sweep3d.cache.stats import store_stats
    from sweep3d.cache.store import Store
    from sweep3d.cache.store_blobs import BLOB_TABLES, DIGEST_COLUMN, TRUTH_BLOBS
    from sweep3d.cache.store_folder import store_folder_problem
    from sweep3d.cache.store_write import SegmentWriter
    from sweep3d.cache.verification import verify
    from sweep3d.cache.written import remember_written, written_from

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
