"""The stage driver with stand-in stages (no Blender, no torch): overlapped passes record what a
sequential run records, downstream stages compute while upstream ones still run, outcomes count
what they counted before, and whenever a pass stops, a row on disk has its upstream rows on disk."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Iterator

import numpy as np
import pyarrow as pa
import pytest

from sweep3d.cache.blobs import sha256_bytes
from sweep3d.cache.store import DIGEST_COLUMN, Store, atomic_write
from sweep3d.core.errors import UserError
from sweep3d.core.pixels import encode_png
from sweep3d.driver import loop as driver
from sweep3d.driver.jobs import Job, Plan
from sweep3d.driver.loop import Computed, Feed, run_stages
from sweep3d.driver.progress import RunProgress

BLOB = pa.schema([("key", pa.string()), ("valid", pa.bool_()), (DIGEST_COLUMN, pa.string())])
RENDERS = pa.schema([("render_key", pa.string()), ("valid", pa.bool_()), (DIGEST_COLUMN, pa.string())])
IMAGES = pa.schema([("image_key", pa.string()), ("render_key", pa.string()), ("valid", pa.bool_()),
                    (DIGEST_COLUMN, pa.string())])
PREDICTIONS = pa.schema([("pred_key", pa.string()), ("image_key", pa.string()), ("valid", pa.bool_())])


def make_plan(n: int = 12) -> Plan:
    """``n`` renders, each seen as rendered and post-processed (as the quickstart's two blurs):
    ``n`` renders, ``n`` images and ``2 n`` predictions; inference reads renders and images."""
    jobs = []
    for i in range(n):
        render = f"r{i:03d}"
        jobs += [Job(2 * i + t, "box", "white", {}, render, (render, f"i{i:03d}")[t], f"p{i:03d}{t}") for t in (0, 1)]
    return Plan(spec=None, jobs=jobs, model_digest="m")  # type: ignore[arg-type]  (the stand-ins read no spec)


def write_blob(store: Store, key: str, level: float) -> str:
    data = encode_png(np.full((4, 4, 3), level, np.float32))
    atomic_write(store.blob_path(key), data)
    return sha256_bytes(data)


class Render:
    """Writes a blob per render key; ``gate`` makes it wait after its first render (for overlap)."""

    name, table, owns_blobs, side_tables = "render", "renders", True, {}

    def __init__(self, fail: set[str] = frozenset(), gate: threading.Event | None = None,
                 stop_after: int | None = None) -> None:
        self.fail, self.gate, self.stop_after = fail, gate, stop_after
        self.closed = threading.Event()

    def schema(self, plan: Plan) -> pa.Schema:
        return RENDERS

    def key(self, job: Job) -> str:
        return job.render_key

    def upstream(self, job: Job) -> None:
        return None

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        return set()

    def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
        try:
            for n, job in enumerate(todo):
                if self.stop_after is not None and n == self.stop_after:
                    raise KeyboardInterrupt
                if job.render_key in self.fail:
                    yield Computed(job.render_key, error="boom")
                    continue
                digest = write_blob(store, job.render_key, int(job.render_key[1:]) / 100)
                yield Computed(job.render_key, {"render_key": job.render_key, "valid": True, DIGEST_COLUMN: digest})
                if self.gate is not None and n == 2:  # three renders in: a batch of three to infer
                    assert self.gate.wait(20), "the downstream stages did not compute while this one ran"
        finally:
            self.closed.set()


class Post:
    """Reads its render (through the feed's rows) and writes an image; reports the renders in
    ``damaged`` as damaged the first time it reads them (as if damaged after the pass began)."""

    name, table, owns_blobs, side_tables = "postprocess", "images", True, {}

    def __init__(self, damaged: set[str] = frozenset()) -> None:
        self.damaged = set(damaged)

    def schema(self, plan: Plan) -> pa.Schema:
        return IMAGES

    def key(self, job: Job) -> str | None:
        return job.image_key if job.image_key != job.render_key else None

    def upstream(self, job: Job) -> tuple[str, str]:
        return ("renders", job.render_key)

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        return set()

    def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
        valid, digests = todo.column("renders", "valid"), todo.digests("renders")
        for job in todo:
            assert valid[job.render_key] is True and digests[job.render_key]
            if job.render_key in self.damaged:
                self.damaged.remove(job.render_key)
                yield Computed(job.image_key, damaged=("renders", job.render_key))
                continue
            digest = write_blob(store, job.image_key, 0.5)
            yield Computed(job.image_key, {"image_key": job.image_key, "render_key": job.render_key, "valid": True,
                                           DIGEST_COLUMN: digest})


class Infer:
    """Predicts in batches of 3; ``started`` is set once it has yielded its first prediction;
    ``damaged`` as :class:`Post`'s."""

    name, table, owns_blobs, side_tables = "infer", "predictions", False, {}

    def __init__(self, raises: bool = False, damaged: set[str] = frozenset()) -> None:
        self.started = threading.Event()
        self.raises = raises
        self.damaged = set(damaged)

    def schema(self, plan: Plan) -> pa.Schema:
        return PREDICTIONS

    def key(self, job: Job) -> str:
        return job.pred_key

    def upstream(self, job: Job) -> tuple[str, str]:
        return ("renders" if job.image_key == job.render_key else "images", job.image_key)

    def incomplete(self, plan: Plan, store: Store, cached: set[str]) -> set[str]:
        return set()

    def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
        batch: list[Job] = []
        for job in todo:
            if self.raises:
                raise UserError("the model raised")
            batch.append(job)
            if len(batch) == 3:
                yield from self._rows(batch)
                batch = []
        yield from self._rows(batch)

    def _rows(self, batch: list[Job]) -> Iterator[Computed]:
        for job in batch:
            if job.image_key in self.damaged:
                self.damaged.remove(job.image_key)
                yield Computed(job.pred_key, damaged=("renders", job.image_key))
                continue
            yield Computed(job.pred_key, {"pred_key": job.pred_key, "image_key": job.image_key, "valid": True})
            self.started.set()


def overlapped(stages: list, plan: Plan, store: Store, strict: bool = False) -> list:
    """``run_stages`` as a run calls it: the stages overlapped."""
    return run_stages(stages, plan, store, RunProgress(None), strict=strict, overlap=True)


def stored(store: Store) -> dict[str, list[tuple]]:
    """Every committed row of each table, duplicates included, sorted."""
    out = {}
    for table in ("renders", "images", "predictions"):
        data = store.table(table)
        out[table] = sorted(tuple(r.values()) for r in data.to_pylist()) if data is not None else []
    return out


def counts(outcomes) -> dict[str, tuple[int, int, int, int, int]]:
    return {o.stage: (o.total, o.cached, o.computed, o.failed, o.skipped) for o in outcomes}


def test_an_overlapped_run_records_what_a_sequential_run_records(tmp_path: Path) -> None:
    plan = make_plan()
    results = {}
    for overlap in (False, True):
        store = Store(tmp_path / str(overlap))
        outcomes = run_stages([Render(fail={"r005"}), Post(), Infer()], plan, store, RunProgress(None), overlap=overlap)
        results[overlap] = (stored(store), counts(outcomes))
    assert results[True] == results[False]
    rows, outcome = results[True]
    assert outcome == {"render": (12, 0, 11, 1, 0), "postprocess": (12, 0, 11, 0, 1), "infer": (24, 0, 22, 0, 2)}
    assert len(rows["predictions"]) == 22


def test_downstream_stages_compute_while_the_first_stage_still_runs(tmp_path: Path) -> None:
    gate = threading.Event()
    infer = Infer()
    threading.Thread(target=lambda: infer.started.wait(20) and gate.set(), daemon=True).start()
    store = Store(tmp_path)
    outcomes = overlapped([Render(gate=gate), Post(), infer], make_plan(), store)
    assert gate.is_set()  # the render stage waited after its first render until a prediction came
    assert counts(outcomes)["infer"] == (24, 0, 24, 0, 0)


def test_a_rerun_counts_what_is_cached_and_computes_nothing(tmp_path: Path) -> None:
    store, plan = Store(tmp_path), make_plan()
    overlapped([Render(), Post(), Infer()], plan, store)
    outcomes = overlapped([Render(), Post(), Infer()], plan, store)
    assert counts(outcomes) == {"render": (12, 12, 0, 0, 0), "postprocess": (12, 12, 0, 0, 0),
                                "infer": (24, 24, 0, 0, 0)}


def test_strict_turns_a_failed_key_into_a_user_error(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="1 render jobs failed: render r005"):
        overlapped([Render(fail={"r005"}), Post(), Infer()], make_plan(), Store(tmp_path), strict=True)


def test_an_error_in_a_later_stage_stops_the_first_and_every_thread(tmp_path: Path) -> None:
    render = Render()
    before = threading.active_count()
    with pytest.raises(UserError, match="the model raised"):
        overlapped([render, Post(), Infer(raises=True)], make_plan(40), Store(tmp_path))
    assert render.closed.is_set()  # its generator was closed (a real render pool shuts its workers down)
    assert threading.active_count() == before


@pytest.mark.parametrize("stop_after", [1, 4, 9])
def test_an_interrupted_pass_keeps_upstream_rows_first_and_the_rerun_completes_it(tmp_path: Path, monkeypatch,
                                                                                   stop_after: int) -> None:
    monkeypatch.setattr(driver, "FLUSH_ROWS", 2)  # many flushes: a stop lands between them
    store, plan = Store(tmp_path), make_plan()
    appended: list[dict[str, set[str]]] = []
    append = Store.append

    def checked_append(self, table, rows, schema=None):
        path = append(self, table, rows, schema)
        on_disk = {t: self.keys(t) for t in ("renders", "images")}
        for row in rows:  # every row's input is on disk before it
            if table == "images":
                assert row["render_key"] in on_disk["renders"]
            if table == "predictions":
                assert row["image_key"] in on_disk["renders"] | on_disk["images"]
        appended.append(on_disk)
        return path

    monkeypatch.setattr(Store, "append", checked_append)
    with pytest.raises(KeyboardInterrupt):
        overlapped([Render(gate=None, stop_after=stop_after), Post(), Infer()], plan, store)
    first = stored(store)
    outcomes = overlapped([Render(), Post(), Infer()], plan, store)
    done = stored(store)
    for table, rows in done.items():
        assert len(rows) == len(set(rows)), f"duplicate {table} rows"
        assert set(first[table]) <= set(rows)
    assert len(done["predictions"]) == 24
    assert counts(outcomes)["render"][1] == len(first["renders"])  # what the stop left is cached
    assert appended


def test_a_damaged_input_found_by_two_stages_is_discarded_once_and_redone_in_the_run(tmp_path: Path) -> None:
    store, plan = Store(tmp_path), make_plan(4)
    stages = [Render(), Post(damaged={"r001"}), Infer(damaged={"r001"})]
    render, post, infer = overlapped(stages, plan, store)
    assert (post.repaired, infer.repaired) == (1, 0)  # counted once, by the first stage that found it
    assert (render.computed, post.computed, infer.computed) == (5, 4, 8)  # r001 again, then what read it
    assert not (render.failed or post.failed or infer.failed)
    rows = stored(store)
    assert len(rows["predictions"]) == 8 and len(rows["renders"]) == 4  # its first row went with its blob


def test_a_stage_s_feed_names_the_stages_before_it_that_compute_in_the_pass(tmp_path: Path) -> None:
    """What inference's thread count is chosen from (one thread beside renders, every core beside
    post-processing alone): fixed at the pass's start, by what each stage before had to do."""
    seen: dict[str, tuple[str, ...]] = {}

    class Noting(Infer):
        def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
            seen.setdefault("infer", todo.computing)
            yield from super().compute(todo, plan, store)

    store = Store(tmp_path)
    overlapped([Render()], make_plan(), store)  # renders stored: post-processing alone computes next
    overlapped([Render(), Post(), Noting()], make_plan(), store)
    assert seen.pop("infer") == ("postprocess",)
    overlapped([Render(), Post(), Noting()], make_plan(), Store(tmp_path / "fresh"))
    assert seen.pop("infer") == ("render", "postprocess")
    overlapped([Render(), Post(), Noting(damaged={"i000"})], make_plan(), Store(tmp_path / "fresh"))  # cached
    assert "infer" not in seen  # nothing to compute: no feed at all


def test_a_stage_s_feed_learns_when_each_stage_before_it_is_done(tmp_path: Path) -> None:
    """What lets inference take every core once the renders are done, while post-processing still
    hands it their last images (``Feed.finished``)."""
    seen: list[set[str]] = []

    class Noting(Infer):
        def compute(self, todo: Feed, plan: Plan, store: Store) -> Iterator[Computed]:
            seen.append(set(todo.finished))
            yield from super().compute(todo, plan, store)
            seen.append(set(todo.finished))  # its feed has closed: every stage before is done

    overlapped([Render(), Post(), Noting()], make_plan(), Store(tmp_path))
    assert seen[0] <= {"render", "postprocess"} and seen[-1] == {"render", "postprocess"}
