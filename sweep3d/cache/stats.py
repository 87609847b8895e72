"""``sweep3d cache stats``: files, rows, keys and bytes per table and per kind of file."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sweep3d.cache.contracts import contract_of, table_contracts, table_names
from sweep3d.cache.files import store_files
from sweep3d.cache.garbage import _blob_files, _is_temp
from sweep3d.cache.store import Store
from sweep3d.cache.store_blobs import blob_key
from sweep3d.cache.verification import jobs_files, kept_names


@dataclass
class TableStats:
    name: str
    files: int
    rows: int
    keys: int
    bytes: int


def store_stats(root: Path) -> list[TableStats]:
    """Files, rows, distinct keys and bytes per table, then blobs, each table's kept files (keys:
    those its rows name), temp files and quarantine."""
    store = Store(root, quarantine=False, warn=False)
    out = []
    for table in table_names():
        paths = store.segments(table)
        data = store.table(table, [contract_of(table).key])
        rows = data.num_rows if data is not None else 0
        keys = len(set(data.column(0).to_pylist())) if data is not None else 0
        out.append(TableStats(table, len(paths), rows, keys, sum(_size(p) for p in paths)))
    jobs = jobs_files(root)
    out.append(TableStats("jobs", len(jobs), sum(_rows(store, p) for p in jobs), len(jobs), sum(_size(p) for p in jobs)))
    blobs = [Path(e.path) for folder, e in _blob_files(root / "blobs") if blob_key(e.name, folder) is not None]
    out.append(TableStats("blobs", len(blobs), len(blobs), len(blobs), sum(_size(p) for p in blobs)))
    replaced = [store.table_dir(t) / n for t in table_names() for _, names, _ in store.superseded(t) for n in names]
    replaced = [p for p in replaced if p.is_file()]
    out.append(TableStats("compacted away", len(replaced), 0, 0, sum(_size(p) for p in replaced)))
    for contract in table_contracts():
        if contract.kept is not None:
            files = [Path(e.path) for e in store_files(root.joinpath(*contract.kept.folder)) if not _is_temp(e.name)]
            out.append(TableStats(f"kept {contract.kept.noun}s", len(files), len(files),
                                  len(kept_names(store, contract)), sum(_size(p) for p in files)))
    temp = [p for p in root.rglob(".*.tmp")] if root.is_dir() else []
    out.append(TableStats("temp files", len(temp), 0, 0, sum(_size(p) for p in temp)))
    quarantine = [p for p in (root / "quarantine").rglob("*") if p.is_file()] if (root / "quarantine").is_dir() else []
    out.append(TableStats("quarantine", len(quarantine), 0, 0, sum(_size(p) for p in quarantine)))
    return out


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _rows(store: Store, path: Path) -> int:
    data = store.read_segment(path, ["job"])
    return data.num_rows if data is not None else 0
