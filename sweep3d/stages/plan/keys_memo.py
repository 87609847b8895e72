"""A plan's keys remembered in the store, so that a rerun of an unchanged plan reads them back.

Writing the canonical texts of 10⁶ jobs and hashing them is most of planning (about 3 s of one
core at 10⁶ jobs: two float texts and two SHA-256 digests per job), and a rerun that finds
everything cached plans the same jobs again. The keys are a pure function of what the planner
writes them from: each scene's key and labels, the inference base, the seed, which keys are
made (parts, truth passes), and per control its id, class, flags (``stochastic``,
``edits_scene``, periods), its neutral jobs, its groups' key parts (holes and all) and its range
numbers as their bytes, or for a control written job by job its texts. The memo is read only
under a fingerprint of all of these and of sweep3d's own source, Python's and numpy's versions:
any other input, or other code, is another fingerprint, and the keys are computed as before and
remembered in place of the old. A file that does not read back whole (page checksums, its row
count) is a miss too.

One file per experiment and model (``cache/plan-keys/``), written by ``run`` (which holds the
lock) for plans of at least :data:`MIN_JOBS` jobs; adaptive rounds are not remembered (each
round is a new plan).
"""

from __future__ import annotations

import hashlib
import os
import sys
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from sweep3d.cache import Store, StoreWriteError, canonical, read_parquet, safe_filename
from sweep3d.stages.plan.batch import ControlBatch

#: Plans smaller than this are planned in well under a second: not worth a file in the store.
MIN_JOBS = 20_000
FORMAT = b"plan keys 1"
_PRINT = b"sweep3d.fingerprint"
_SAME_IMAGES = b"sweep3d.images_are_renders"
COLUMNS = ("render", "image", "pred", "parts", "truth")


class KeysPrint:
    """The fingerprint of a plan's keys, fed scene by scene in plan order."""

    def __init__(self, base: dict[str, Any], seed: int, parts: bool, truth_passes: tuple[str, ...]) -> None:
        self._h = hashlib.sha256(FORMAT + b"\0" + _code_digest().encode())
        self._text(canonical({"base": base, "seed": seed, "parts": parts, "passes": list(truth_passes)}))

    def scene(self, scene: str, truth: list[Any], n: int, rendered: list[ControlBatch], post: list[ControlBatch]) -> None:
        """Add one scene's jobs: ``rendered`` and ``post``, the batches its keys are written from."""
        self._text(canonical({"scene": scene, "truth": truth, "n": n, "rendered": len(rendered), "post": len(post)}))
        for batch in [*rendered, *post]:
            self._batch(batch)

    def hexdigest(self) -> str:
        return self._h.hexdigest()

    def _batch(self, batch: ControlBatch) -> None:
        control = batch.inst.control
        cls = type(control)
        self._text(repr((batch.id, batch.plain, cls.__module__, cls.__qualname__,
                         bool(getattr(control, "stochastic", False)), bool(getattr(control, "edits_scene", False)),
                         sorted(control.periodic.items()))))
        self._array(batch.identity)
        self._array(batch.values.group)
        if batch.plain:
            for group in range(len(batch.values.dumps)):
                self._text(canonical(batch.part(group)))
            for param, numbers in batch.values.numbers.items():
                self._text(param)
                self._array(numbers)
        else:
            self._text(repr(batch.texts.tolist() if batch.texts is not None else None))

    def _text(self, text: str) -> None:
        data = text.encode("utf-8", "surrogatepass")
        self._h.update(len(data).to_bytes(8, "little") + data)

    def _array(self, values: np.ndarray) -> None:
        values = np.asarray(values)
        if values.dtype == object:
            self._text(repr(values.tolist()))
            return
        self._text(f"{values.dtype.str}{values.shape}")
        self._h.update(np.ascontiguousarray(values).tobytes())


@lru_cache(maxsize=1)
def _code_digest() -> str:
    """sweep3d's own source (every module: the planner, the controls' key parts, the key recipes),
    Python's and numpy's versions (how floats are written and wrapped)."""
    root = Path(__file__).resolve().parents[2]
    h = hashlib.sha256(f"{sys.version}\0{np.__version__}".encode())
    for folder, dirs, files in os.walk(root):
        dirs.sort()
        for name in sorted(files):
            if name.endswith(".py"):
                path = Path(folder, name)
                h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def memo_path(store: Store, experiment: str, model: str) -> Path:
    """Where the keys of ``experiment``'s plan for ``model`` (its digest) are remembered."""
    tag = hashlib.sha256(model.encode()).hexdigest()[:16]
    return store.root / "cache" / "plan-keys" / f"{safe_filename(experiment)}-{tag}.parquet"


def read_keys(path: Path, fingerprint: str, n: int) -> dict[str, list[str] | None] | None:
    """The keys remembered at ``path`` under ``fingerprint`` (``n`` jobs), by :data:`COLUMNS`;
    None when there is no such file, it holds another plan's, or it does not read back whole."""
    try:
        table = read_parquet(path, verify=True)
    except (OSError, pa.ArrowException, ValueError):
        return None
    meta = table.schema.metadata or {}
    if meta.get(_PRINT) != fingerprint.encode() or table.num_rows != n:
        return None
    out: dict[str, list[str] | None] = {name: table.column(name).to_pylist() if name in table.column_names else None
                                        for name in COLUMNS}
    if meta.get(_SAME_IMAGES) == b"1":
        out["image"] = list(out["render"])  # type: ignore[arg-type]
    if out["render"] is None or out["image"] is None or out["pred"] is None:
        return None
    return out


def write_keys(store: Store, path: Path, fingerprint: str, keys: dict[str, list[str] | None]) -> None:
    """Remember ``keys`` (by :data:`COLUMNS`, None for keys the plan does not make) at ``path``; a
    store that cannot take the file (a full disk) only plans again next time."""
    same = keys["image"] == keys["render"]
    columns = {name: pa.array(values, type=pa.string()) for name, values in keys.items()
               if values is not None and not (same and name == "image")}
    table = pa.table(columns).replace_schema_metadata({_PRINT: fingerprint.encode(), _SAME_IMAGES: b"1" if same else b"0"})
    try:
        store.write_table_file(path, table)
    except StoreWriteError:
        pass


def source_digest() -> str:
    """What :func:`_code_digest` covers (sweep3d's source, Python's and numpy's versions), for
    another record of the store that holds only while the code that made it is the same."""
    return _code_digest()
