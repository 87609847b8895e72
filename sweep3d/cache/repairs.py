"""``sweep3d cache verify --repair``: fix what :func:`~sweep3d.cache.verification.verify` found,
through atomic renames under the writer lock, so a reader sees every row exactly once before,
during and after."""

from __future__ import annotations

from pathlib import Path

from sweep3d.cache import extracted
from sweep3d.cache.store import Store
from sweep3d.cache.store_blobs import BLOB_TABLES, TRUTH_BLOBS
from sweep3d.cache.verification import Verification


def repair(root: Path, report: Verification) -> int:
    """Fix what :func:`verify` found; call it holding the writer lock. Returns problems fixed.

    Corrupt segments and jobs tables go to ``quarantine/`` (their rows are recomputed by the
    next run); rows whose blob is missing or corrupt are dropped and the blob quarantined, so
    the next run renders or postprocesses them again. A file the OS would not let sweep3d read
    (``unreadable …``) is left where it is, with its rows: it may be intact.
    """
    store = Store(root)
    fixed = 0
    problems = report.repairable  # not a file the OS would not let us read: it may be intact
    for problem in problems:
        if problem.kind in ("corrupt segment", "corrupt jobs table"):
            if store.quarantine(problem.path) is not None:
                fixed += 1
    for table in BLOB_TABLES:
        keys = {p.key for p in problems if p.table == table and p.key is not None}
        if keys:
            store.drop_rows(table, keys)
            for key in keys:
                blob = store.blob_path(key)
                if blob.exists():
                    store.quarantine(blob)
            fixed += len(keys)
    for problem in problems:  # a kept model output (the next run runs the model again) or a table's kept
        # file (its row then names none: its writer keeps it anew when it writes the row again)
        if problem.kind.startswith("corrupt kept ") and store.quarantine(problem.path) is not None:
            fixed += 1
    for name in {p.key for p in problems if p.kind == "corrupt extracted asset" and p.key is not None}:
        fixed += store.quarantine(root / extracted.ASSETS_FOLDER / name) is not None
    truths = {p.key for p in problems if p.table == "truths" and p.key is not None}
    if truths:  # the next run that needs them renders the passes again
        store.drop_rows("truths", truths)
        for key in truths:
            for suffix in TRUTH_BLOBS:
                blob = store.blob_path(key, suffix)
                if blob.exists():
                    store.quarantine(blob)
        fixed += len(truths)
    return fixed
