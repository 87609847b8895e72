"""The content-addressed cache: canonical keys and the Parquet/DuckDB store."""

from __future__ import annotations

__all__ = [
    "ASSETS_FOLDER", "BLOB_TABLES", "DIGEST_COLUMN", "Hole", "KEY_COLUMN", "KeptFiles", "MANIFEST", "MIN_JOBS",
    "OUTPUTS_FOLDER", "STORE_FIX", "SUFFIX", "SegmentWriter", "Store", "StoreWriteError", "TABLES", "TRUTH_BLOBS",
    "TableContract", "Template", "atomic_write", "canonical", "canonical_pieces", "collect_garbage",
    "compact_table", "contract_of", "damaged_blobs", "declare_table_modules", "digest", "digests",
    "file_digest", "files_digest", "float_texts", "full_disk_error", "is_full_disk", "is_select", "load_image",
    "load_pass", "load_pixels", "lock_down", "members", "pack", "read_manifest", "record", "register_store_folder",
    "register_table", "remember_written", "remove_killed_writers_temp_files", "repair", "safe_filename",
    "sha256_bytes", "skip_pandas_probe", "stale", "store_error", "store_folder_problem", "store_stats",
    "table_contract", "table_contracts", "table_names", "unpack", "unregister_table", "utc_now", "verify", "written_from",
]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.cache.blobs import damaged_blobs, load_image, load_pass, load_pixels, sha256_bytes
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
        safe_filename,
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

__getattr__, __dir__ = _exports(__name__, {
    "KeptFiles": ("sweep3d.cache.contracts", "KeptFiles"),
    "TableContract": ("sweep3d.cache.contracts", "TableContract"),
    "contract_of": ("sweep3d.cache.contracts", "contract_of"),
    "table_contracts": ("sweep3d.cache.contracts", "table_contracts"),
    "declare_table_modules": ("sweep3d.cache.declared", "declare_table_modules"),
    "register_store_folder": ("sweep3d.cache.contracts", "register_store_folder"),
    "register_table": ("sweep3d.cache.contracts", "register_table"),
    "table_contract": ("sweep3d.cache.contracts", "table_contract"),
    "table_names": ("sweep3d.cache.contracts", "table_names"),
    "unregister_table": ("sweep3d.cache.contracts", "unregister_table"),
    "ASSETS_FOLDER": ("sweep3d.cache.extracted", "ASSETS_FOLDER"),
    "BLOB_TABLES": ("sweep3d.cache.store_blobs", "BLOB_TABLES"),
    "DIGEST_COLUMN": ("sweep3d.cache.store_blobs", "DIGEST_COLUMN"),
    "Hole": ("sweep3d.cache.hashing", "Hole"),
    "KEY_COLUMN": ("sweep3d.cache.contracts", "KEY_COLUMN"),
    "MANIFEST": ("sweep3d.cache.extracted", "MANIFEST"),
    "MIN_JOBS": ("sweep3d.cache.snapshot", "MIN_JOBS"),
    "STORE_FIX": ("sweep3d.cache.files", "STORE_FIX"),
    "store_error": ("sweep3d.cache.files", "store_error"),
    "OUTPUTS_FOLDER": ("sweep3d.cache.digested", "OUTPUTS_FOLDER"),
    "SUFFIX": ("sweep3d.cache.digested", "SUFFIX"),
    "SegmentWriter": ("sweep3d.cache.store_write", "SegmentWriter"),
    "Store": ("sweep3d.cache.store", "Store"),
    "StoreWriteError": ("sweep3d.cache.files", "StoreWriteError"),
    "TABLES": ("sweep3d.cache.contracts", "TABLES"),
    "TRUTH_BLOBS": ("sweep3d.cache.store_blobs", "TRUTH_BLOBS"),
    "Template": ("sweep3d.cache.hashing", "Template"),
    "atomic_write": ("sweep3d.cache.files", "atomic_write"),
    "canonical": ("sweep3d.cache.hashing", "canonical"),
    "canonical_pieces": ("sweep3d.cache.hashing", "canonical_pieces"),
    "collect_garbage": ("sweep3d.cache.garbage", "collect_garbage"),
    "compact_table": ("sweep3d.cache.compaction", "compact_table"),
    "damaged_blobs": ("sweep3d.cache.blobs", "damaged_blobs"),
    "digest": ("sweep3d.cache.hashing", "digest"),
    "digests": ("sweep3d.cache.hashing", "digests"),
    "file_digest": ("sweep3d.cache.hashing", "file_digest"),
    "files_digest": ("sweep3d.cache.hashing", "files_digest"),
    "float_texts": ("sweep3d.cache.hashing", "float_texts"),
    "full_disk_error": ("sweep3d.cache.files", "full_disk_error"),
    "is_full_disk": ("sweep3d.cache.files", "is_full_disk"),
    "is_select": ("sweep3d.cache.query", "is_select"),
    "load_image": ("sweep3d.cache.blobs", "load_image"),
    "load_pixels": ("sweep3d.cache.blobs", "load_pixels"),
    "load_pass": ("sweep3d.cache.blobs", "load_pass"),
    "lock_down": ("sweep3d.cache.query", "lock_down"),
    "members": ("sweep3d.cache.extracted", "members"),
    "pack": ("sweep3d.cache.digested", "pack"),
    "read_manifest": ("sweep3d.cache.extracted", "read_manifest"),
    "record": ("sweep3d.cache.extracted", "record"),
    "remember_written": ("sweep3d.cache.written", "remember_written"),
    "remove_killed_writers_temp_files": ("sweep3d.cache.garbage", "remove_killed_writers_temp_files"),
    "repair": ("sweep3d.cache.repairs", "repair"),
    "safe_filename": ("sweep3d.cache.files", "safe_filename"),
    "sha256_bytes": ("sweep3d.cache.blobs", "sha256_bytes"),
    "skip_pandas_probe": ("sweep3d.cache.pandas_probe", "skip_pandas_probe"),
    "stale": ("sweep3d.cache.extracted", "stale"),
    "store_folder_problem": ("sweep3d.cache.store_folder", "store_folder_problem"),
    "store_stats": ("sweep3d.cache.stats", "store_stats"),
    "unpack": ("sweep3d.cache.digested", "unpack"),
    "utc_now": ("sweep3d.cache.files", "utc_now"),
    "verify": ("sweep3d.cache.verification", "verify"),
    "written_from": ("sweep3d.cache.written", "written_from"),
})
