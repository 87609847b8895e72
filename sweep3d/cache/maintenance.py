"""Store upkeep behind ``sweep3d cache``, one module per command: verify
(:mod:`~sweep3d.cache.verification`), repair (:mod:`~sweep3d.cache.repairs`), gc
(:mod:`~sweep3d.cache.garbage`), compact (:mod:`~sweep3d.cache.compaction`) and stats
(:mod:`~sweep3d.cache.stats`), each working from the declared tables' contracts
(:mod:`~sweep3d.cache.contracts`). Their names, gathered here for the code that long imported them
from this module.
"""

from __future__ import annotations

from sweep3d.cache.compaction import Compacted, compact_table
from sweep3d.cache.files import store_files
from sweep3d.cache.garbage import (
    LOCKED_FOLDERS,
    TEMP_AGE,
    TEMP_PATTERN,
    Collected,
    collect_garbage,
    locked_folders,
    remove_killed_writers_temp_files,
)
from sweep3d.cache.repairs import repair
from sweep3d.cache.stats import TableStats, store_stats
from sweep3d.cache.verification import (
    UNREADABLE,
    Problem,
    Verification,
    cannot_open,
    evaluated_columns_lacking,
    jobs_files,
    kept_names,
    verify,
)

__all__ = [
    "LOCKED_FOLDERS", "TEMP_AGE", "TEMP_PATTERN", "UNREADABLE", "Collected", "Compacted", "Problem", "TableStats",
    "Verification", "cannot_open", "collect_garbage", "compact_table", "evaluated_columns_lacking", "jobs_files",
    "kept_names", "locked_folders", "remove_killed_writers_temp_files", "repair", "store_files", "store_stats",
    "verify",
]
