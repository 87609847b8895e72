"""A run that found its stages complete remembers it, so that the same run again skips its per-key passes.

A no-op rerun of 10⁶ cached jobs spends most of its time looking each key up: which rows are
stored, which blobs exist and are intact, which predictions are pending (about 10 s of one
core). What a run's passes find is a function of what they read: the plans (the jobs file's
digest, :func:`~sweep3d.runner.pipeline.jobs_digest`, covers every key, the models and the user
plug-ins' code), the spec's text, sweep3d's own source (:func:`source_digest`), the tables'
segment files and the blob files. A run whose passes computed, failed and repaired nothing,
and wrote no table, records a digest of all of these (:func:`fingerprint`) with its outcomes
in ``verified/settled/<experiment>.json``; a run with the same digest takes those outcomes
instead of running the passes.

Files stand in the digest by their state, as the memo of verified blobs takes them
(:func:`~sweep3d.cache.blobs.damaged_blobs`): name, size, mtime, change time and inode. Every
write through the file system moves the change time, which ``touch`` cannot set back, so a
blob flipped in place with its mtime put back, a deleted blob, a new segment or a segment
rewritten is another digest, and the run looks key by key as before (and finds the damage).
The blob states are the ones the run's child takes anyway while the parent plans
(:mod:`sweep3d.cache.snapshot`: one ``stat`` per blob, on the other core), hashed as the child
wrote them: a run with no snapshot (a store of few blobs, a small plan, a child that failed)
has no digest and looks key by key. The blob folders' other files (a truth pass's
``<key>.depth.npz``, which a run checks only for being there) enter the digest by their names;
temp files that killed writers left are removed before the passes and are not part of it. Not covered, as for the memo: damage that
bypasses the file system (bit rot, writes to the raw device); ``sweep3d cache verify`` hashes
every blob. Adaptive policies, whose later rounds are planned from the outcomes, always look.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from sweep3d.cache import Store, atomic_write, safe_filename, scan, table_names
from sweep3d.driver import StageOutcome
from sweep3d.spec import LoadedSpec
from sweep3d.stages.plan import source_digest

FORMAT = b"settled run 1"
#: Tables a run appends to whatever its passes find (its own row): not part of the digest.
NOT_READ = ("runs",)
_COUNTS = ("total", "cached", "skipped")


def fingerprint(store: Store, spec: LoadedSpec, jobs: str | None) -> str | None:
    """The digest of what a run's passes over ``jobs`` (the jobs file's digest) would read, from
    the snapshot of blob states the run took; None where there is none, or no jobs digest."""
    snapshot = store.state_snapshot
    looked = snapshot.head() if snapshot is not None and jobs is not None and not spec.policy.adaptive else None
    if looked is None:
        return None
    others = "\n".join(f"{folder}/{name}" for folder, names in sorted(looked[1].items())
                       for name in sorted(names) if not _temp(name))  # a pass's blob (depth.npz): by its name
    h = hashlib.sha256(FORMAT)
    for part in (source_digest(), jobs, spec.text(), looked[0], others, table_states(store)):
        data = part.encode("utf-8", "surrogatepass")
        h.update(len(data).to_bytes(8, "little") + data)
    return h.hexdigest()


def table_states(store: Store) -> str:
    """Every file of the tables a run's passes read, with its state, as one text."""
    lines = []
    for table in sorted(set(table_names()) - set(NOT_READ)):
        for entry in sorted(scan(store.table_dir(table)), key=lambda e: e.name):
            st = entry.stat(follow_symlinks=False)
            lines.append(f"{table}/{entry.name}\0{st.st_mode} {st.st_size} {st.st_mtime_ns} {st.st_ctime_ns} {st.st_ino}")
    return "\n".join(lines)


def recall(store: Store, spec: LoadedSpec, digest: str | None) -> list[StageOutcome] | None:
    """The outcomes a run recorded under ``digest``; None when it recorded another (or none)."""
    if digest is None:
        return None
    try:
        record = json.loads(_path(store, spec).read_bytes())
        if record["fingerprint"] != digest:
            return None
        return [StageOutcome(str(o["stage"]), **{k: int(o[k]) for k in _COUNTS}) for o in record["outcomes"]]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def remember(store: Store, spec: LoadedSpec, digest: str | None, outcomes: list[StageOutcome]) -> None:
    """Record ``outcomes`` under ``digest`` when the passes computed, failed and repaired nothing
    (call it after they ran, with the digest taken before; a table they wrote changes the states
    :func:`fingerprint` read, so the caller compares them again first)."""
    if digest is None or not outcomes or any(o.computed or o.failed or o.repaired or o.errors for o in outcomes):
        return
    record = {"fingerprint": digest,
              "outcomes": [{"stage": o.stage, **{k: getattr(o, k) for k in _COUNTS}} for o in outcomes]}
    atomic_write(_path(store, spec), json.dumps(record).encode(), durable=False)


def forget(store: Store, spec: LoadedSpec) -> None:
    """Drop the record (a run that found work to do: it would only be read to be refused)."""
    _path(store, spec).unlink(missing_ok=True)


def _temp(name: str) -> bool:
    """Whether ``name`` is a killed writer's temp file (``cache.garbage.TEMP_PATTERN``): the run
    removes it before its passes, whatever the digest says."""
    return name.startswith(".") and name.endswith(".tmp")


def _path(store: Store, spec: LoadedSpec) -> Path:
    return store.root / "verified" / "settled" / f"{safe_filename(spec.name)}.json"
