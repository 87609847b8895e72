"""Damage control in the store: an unreadable file is reported once and skipped (moved to
``quarantine/`` by the lock's holder), an answer that would leave its rows out is refused, and
rows whose files are damaged are dropped so they are computed again."""

from __future__ import annotations

import errno
import logging
import os
import re
import time
import uuid
from pathlib import Path
from typing import Callable

import pyarrow as pa
import pyarrow.compute as pc

from sweep3d.cache.contracts import contract_of
from sweep3d.cache.files import FIXES, StoreReadError, _blocked, _relative
from sweep3d.cache.store_blobs import BLOB_EXT, TRUTH_BLOBS
from sweep3d.cache.store_read import SUPERSEDED_GRACE

log = logging.getLogger("sweep3d.store")


class DamageControl:
    """:class:`~sweep3d.cache.store.Store`'s damage control."""

    root: Path
    warn: bool
    holds_lock: bool
    _bad: dict[str, str]  # unreadable files already reported -> why
    table_dir: Callable[[str], Path]  # the store's, and its reads and writes:
    superseded: Callable[..., list[tuple[Path, list[str], float]]]
    readable_segments: Callable[[str], list[Path]]
    read_segment: Callable[..., pa.Table | None]
    write_table_file: Callable[..., bool]
    blob_path: Callable[..., Path]

    def sweep_superseded(self, table: str, older_than: float = SUPERSEDED_GRACE) -> int:
        """Delete segments that a compaction older than ``older_than`` seconds replaced; call it
        holding the writer lock. Returns how many files went."""
        removed = 0
        for record, names, at in self.superseded(table):
            if time.time() - at < older_than:
                continue
            for name in names:
                try:
                    (self.table_dir(table) / name).unlink()
                    removed += 1
                except FileNotFoundError:
                    pass
            record.unlink(missing_ok=True)
        return removed

    @property
    def unreadable(self) -> dict[str, str]:
        """Files this store object found unreadable (path → why), each reported once."""
        return dict(self._bad)

    def require_readable(self, spec: str | Path) -> None:
        """Refuse an answer that would leave out the rows of a file this store object found
        unreadable (a reader reads around it with a warning, which a query's or a summary's
        numbers would not show): one line naming the file, or the folder that denies it, and the fix.

        Args:
            spec: the spec's path, for the command that repairs a damaged file.

        Raises:
            StoreReadError: a file read so far could not be read.
        """
        if not self._bad:
            return
        path, why = next(iter(self._bad.items()))
        denied = why.endswith(f"; {FIXES[errno.EACCES]}")
        reason, fix = ((why.removesuffix(f"; {FIXES[errno.EACCES]}"), FIXES[errno.EACCES]) if denied else
                       (why, f"run: sweep3d cache verify {_spec_arg(spec)} --repair (it moves the file aside; the next run "
                             "computes its rows again)"))
        others = f" (and {len(self._bad) - 1} more)" if len(self._bad) > 1 else ""
        raise StoreReadError(f"cannot read {_blocked(Path(path)) if denied else path} ({reason}){others}: no answer "
                             f"is given, as one without its rows would be partial; {fix}")

    def _report_bad(self, path: Path, why: str, move: bool, repairable: bool = True) -> None:
        """Warn once that ``path`` is unreadable (``why``), moving it to ``quarantine/`` when ``move``
        and this object holds the lock. ``repairable``: ``cache verify --repair`` would move it aside
        (not a file the OS refused to read, which may be intact)."""
        if str(path) in self._bad:
            return
        why = re.sub(r"^(\w+: )Could not open Parquet input source '[^']*': ", r"\1", why.replace(str(path), path.name))
        self._bad[str(path)] = why
        where = _relative(path, self.root)
        moved = move and self.holds_lock and self.quarantine(path) is not None
        if not self.warn:
            return
        if moved:
            log.warning(f"warning: {where} is unreadable ({why}); moved it to quarantine/, its rows will be "
                        "recomputed")
        elif repairable:
            log.warning(f"warning: {where} is unreadable ({why}); skipping it (sweep3d cache verify --repair "
                        "moves it aside)")
        else:
            log.warning(f"warning: {where} is unreadable ({why}); skipping it")

    def quarantine(self, path: Path) -> Path | None:
        """Move a damaged file under ``quarantine/`` (same relative path); None if it could not be moved."""
        target = self.root / "quarantine" / _relative(path, self.root)
        if target.exists():
            target = target.with_name(f"{target.name}.{uuid.uuid4().hex[:8]}")
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(path, target)
        except OSError:
            return None
        return target

    def drop_rows(self, table: str, keys: set[str] | list[str]) -> int:
        """Remove every row of ``keys`` from ``table``, rewriting the segments that hold them.

        Each segment is replaced atomically, so a reader sees it with or without the rows, never
        half; call it holding the writer lock. Returns the number of rows removed.
        """
        keys = set(keys)
        if not keys:
            return 0
        column = contract_of(table).key
        value_set = pa.array(sorted(keys), type=pa.string())
        removed = 0
        for path in self.readable_segments(table):
            data = self.read_segment(path)
            if data is None:
                continue
            hit = pc.fill_null(pc.is_in(data.column(column), value_set=value_set), False)
            count = pc.sum(hit).as_py() or 0
            if not count:
                continue
            kept = data.filter(pc.invert(hit))
            if kept.num_rows:
                self.write_table_file(path, kept)
            else:
                path.unlink(missing_ok=True)
            removed += count
        return removed

    def discard(self, table: str, keys: set[str] | list[str], why: str) -> None:
        """Forget ``keys`` of a blob table whose blobs are missing or damaged, so they are recomputed:
        their rows are dropped and their blobs moved to ``quarantine/`` (one warning per call)."""
        keys = set(keys)
        if not keys:
            return
        self.drop_rows(table, keys)
        suffixes = TRUTH_BLOBS if table == "truths" else (BLOB_EXT,)  # a truth key owns its pass blobs
        for key in keys:
            for suffix in suffixes:
                blob = self.blob_path(key, suffix)
                if blob.exists():
                    self.quarantine(blob)
        sample = ", ".join(sorted(k[:12] for k in keys)[:3])
        log.warning(f"warning: {len(keys)} {table} blob(s) {why} ({sample}{', …' if len(keys) > 3 else ''}); "
                    "recomputing them")


def _spec_arg(spec: str | Path) -> str:
    """``spec`` as a command names it: SPEC for one loaded from no file (``<dict>``, ``<string>``)."""
    return "SPEC" if str(spec).startswith("<") else str(spec)
