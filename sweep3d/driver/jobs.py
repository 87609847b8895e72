"""Jobs and plans: what the plan stage produces and every later stage reads.

The planner keeps a plan as columns (:class:`PlanColumns`: keys as lists, control values as
arrays per scene), so a plan of a million jobs holds no million dicts; :attr:`Plan.jobs` is a
sequence of :class:`Job` s made from them on first use, whose ``values`` and ``point`` are built
only when read. A plan made by hand from a list of jobs works the same way.

This module imports no stage, so every stage can import it without a cycle.
"""

from __future__ import annotations

import bisect
import gc
import hashlib
import json
from contextlib import contextmanager
from dataclasses import dataclass, field
from itertools import repeat
from operator import itemgetter
from typing import Any, Callable, Iterator, Mapping, Sequence, overload

import numpy as np
import pyarrow as pa

from sweep3d.core import EVALUATOR_METADATA, EvaluatorRecord
from sweep3d.spec import (
    CLASS_NAMES_METADATA,
    DROP_FRAGILE_METADATA,
    MIN_VISIBLE_METADATA,
    MIN_VISIBLE_OFF,
    PARAMETERS_METADATA,
    PROTOCOL_METADATA,
    Framing,
    LoadedSpec,
    Point,
    parameter_column,
)

_FIELDS = ("index", "object", "environment", "values", "render_key", "image_key", "pred_key", "point", "parts_key",
           "truth_key")


class Job(tuple):
    """One configuration of one scene, with the cache key of each stage it passes through.

    ``image_key`` equals ``render_key`` when no post control changes the image; ``parts_key`` is
    set only when the report asks for part visibility (a UV pass). ``values`` is control id →
    parameter → value for the controls that apply; ``point`` is where the policy put the job (for
    policies that learn from results).

    Immutable. A tuple underneath, so that a plan makes a million of them in a fraction of a
    second; a planned job reads ``values`` and ``point`` from its scene's columns when asked.
    """

    __slots__ = ()

    def __new__(cls, index: int, object: str, environment: str, values: dict[str, dict[str, Any]],
                render_key: str, image_key: str, pred_key: str, point: Point | None = None,
                parts_key: str | None = None, truth_key: str | None = None) -> Job:
        return tuple.__new__(cls, (index, object, environment, values, render_key, image_key, pred_key, point,
                                   parts_key, truth_key, None))

    index: int = property(itemgetter(0))  # type: ignore[assignment]
    object: str = property(itemgetter(1))  # type: ignore[assignment]
    environment: str = property(itemgetter(2))  # type: ignore[assignment]
    render_key: str = property(itemgetter(4))  # type: ignore[assignment]
    image_key: str = property(itemgetter(5))  # type: ignore[assignment]
    pred_key: str = property(itemgetter(6))  # type: ignore[assignment]
    parts_key: str | None = property(itemgetter(8))  # type: ignore[assignment]
    truth_key: str | None = property(itemgetter(9))  # type: ignore[assignment]

    @property
    def values(self) -> dict[str, dict[str, Any]]:
        block = self[10]
        return self[3] if block is None else block.values(self[0] - block.start)

    @property
    def point(self) -> Point | None:
        block = self[10]
        return self[7] if block is None else block.point(self[0] - block.start)

    @property
    def scene(self) -> tuple[str, str]:
        return (self[1], self[2])

    def _fields(self) -> tuple:
        return tuple(getattr(self, name) for name in _FIELDS)

    def __eq__(self, other: object) -> bool:
        return self._fields() == other._fields() if isinstance(other, Job) else NotImplemented

    def __ne__(self, other: object) -> bool:
        return not self == other if isinstance(other, Job) else NotImplemented

    __hash__ = None  # type: ignore[assignment]  (values is a dict, as it always was)

    def __getnewargs__(self) -> tuple:  # type: ignore[override]
        return self._fields()

    def __repr__(self) -> str:
        return "Job(" + ", ".join(f"{name}={getattr(self, name)!r}" for name in _FIELDS) + ")"


@dataclass
class ControlValues:
    """One control's validated values over a scene's jobs.

    Jobs that share their listed values form a group: ``dumps[g]`` is the control's parameters
    as its ``Params`` model dumps them for group ``g`` (defaults included), ``group`` each job's
    group. Range parameters of a control whose validation cannot change a number are kept apart
    as ``numbers`` (one per job), so groups stay few.
    """

    dumps: list[dict[str, Any]]
    group: np.ndarray
    numbers: dict[str, np.ndarray] = field(default_factory=dict)

    def at(self, row: int) -> dict[str, Any]:
        """The parameters of the job in ``row`` (as ``Params(...).model_dump()`` gives them)."""
        out = dict(self.dumps[self.group[row]])
        for param, numbers in self.numbers.items():
            out[param] = numbers[row].item() if numbers.dtype != object else numbers[row]
        return out

    def column(self, param: str) -> np.ndarray | list[Any]:
        """Every job's value of ``param`` (an array only where a list of Python values would
        become the same Arrow column)."""
        if param in self.numbers:
            numbers = self.numbers[param]
            return numbers if numbers.dtype == np.float64 else numbers.tolist()
        options = [dump[param] for dump in self.dumps]
        if all(type(v) is float for v in options):
            return np.array(options, dtype=np.float64)[self.group]
        return _objects(options)[self.group].tolist()

    def floats(self, param: str) -> np.ndarray:
        """Every job's value of a numeric ``param`` as float64."""
        if param in self.numbers:
            return self.numbers[param].astype(np.float64)
        return np.array([float(dump[param]) for dump in self.dumps], dtype=np.float64)[self.group]


@dataclass
class SceneBlock:
    """The jobs of one (object, environment) scene, indices ``start`` .. ``start + size - 1``.

    ``controls`` holds the values of the controls that apply, in spec order; ``unit`` and
    ``choice`` the policy's points (one row per job).
    """

    object: str
    environment: str
    start: int
    size: int
    controls: dict[str, ControlValues]
    unit: np.ndarray
    choice: np.ndarray

    def values(self, row: int) -> dict[str, dict[str, Any]]:
        return {control_id: values.at(row) for control_id, values in self.controls.items()}

    def point(self, row: int) -> Point:
        return Point(tuple(self.unit[row].tolist()), tuple(self.choice[row].tolist()))

    def parameters(self) -> dict[str, tuple[str, str]]:
        """Column name → (control id, parameter) of every parameter its jobs carry, in the order
        a row of the jobs table sets them (a later one wins a shared name, as in :meth:`Plan.rows`)."""
        out: dict[str, tuple[str, str]] = {}
        for control_id, values in self.controls.items():
            for param in values.dumps[0]:
                out[parameter_column(control_id, param)] = (control_id, param)
        return out


@dataclass
class PlanColumns:
    """A whole plan as columns: every job's keys by index, whether it is in frame, its scene's block."""

    blocks: list[SceneBlock]
    render_keys: list[str]
    image_keys: list[str]
    pred_keys: list[str]
    parts_keys: list[str] | None
    in_frame: np.ndarray
    truth_keys: list[str] | None = None

    @property
    def size(self) -> int:
        return len(self.render_keys)

    def jobs(self, indices: np.ndarray) -> list[Job]:
        """The jobs at ``indices`` (ascending), made block by block."""
        out: list[Job] = []
        make = tuple.__new__
        with paused_gc():
            for block in self.blocks:
                out += self._block_jobs(block, indices, make)
        return out

    def _block_jobs(self, block: SceneBlock, indices: np.ndarray, make: Callable) -> list[Job]:
        """The jobs of ``block`` among ``indices``: their values and point come from the block."""
        lo, hi = np.searchsorted(indices, [block.start, block.start + block.size])
        rows = indices[lo:hi].tolist()
        keys = [[column[i] for i in rows] for column in (self.render_keys, self.image_keys, self.pred_keys)]
        parts = [self.parts_keys[i] for i in rows] if self.parts_keys is not None else repeat(None)
        truths = [self.truth_keys[i] for i in rows] if self.truth_keys is not None else repeat(None)
        fields = zip(rows, repeat(block.object), repeat(block.environment), repeat(None), *keys, repeat(None),
                     parts, truths, repeat(block))
        return [make(Job, f) for f in fields]

    def block_of(self, index: int) -> SceneBlock:
        return self.blocks[bisect.bisect_right([b.start for b in self.blocks], index) - 1]

    def table(self, experiment: str, parameter_columns: list[str]) -> pa.Table:
        """The jobs table, column for column what ``pa.Table.from_pylist(plan.rows())`` makes."""
        names, sources, _ = self._sources(experiment, parameter_columns)
        return pa.Table.from_arrays([pa.array(source()) for source in sources], names)

    def fingerprint(self, experiment: str, parameter_columns: list[str]) -> str:
        """A digest of :meth:`table`'s names and values, made from the columns it is built from
        (at 10⁶ jobs, half the time building it takes): equal digests, equal tables."""
        names, sources, summaries = self._sources(experiment, parameter_columns)
        h = hashlib.sha256(repr(names).encode())
        for source, summary in zip(sources, summaries):
            if summary is not None:  # a column made from a few values (the experiment, each block's scene)
                h.update(b"\nsummary\n" + repr(summary).encode())
                continue
            values = source()
            if isinstance(values, np.ndarray) and values.dtype != object:
                h.update(f"\n{values.dtype.str}{values.shape}\n".encode())
                h.update(np.ascontiguousarray(values).tobytes())
            else:
                h.update(_list_bytes(values.tolist() if isinstance(values, np.ndarray) else values))
        return h.hexdigest()

    def _sources(self, experiment: str, parameter_columns: list[str]
                 ) -> tuple[list[str], list[Callable[[], Any]], list[Any]]:
        """The jobs table's column names; for each, a function making its values (a list or a
        numpy array), so that :meth:`table` and :meth:`fingerprint` read the same values; and for
        each, the few values it is made from (None: only its values say what it holds)."""
        names = list(_first_row_names(self.blocks[0], parameter_columns)) if self.blocks else []
        if self.truth_keys is not None and names:  # only with truth passes: other plans stay as they were
            names.append("truth_key")
        keys = {"render_key": self.render_keys, "image_key": self.image_keys, "pred_key": self.pred_keys,
                "parts_key": self.parts_keys if self.parts_keys is not None else [None] * self.size,
                "in_frame": self.in_frame, "truth_key": self.truth_keys}
        scenes = [(b.object, b.environment, b.size) for b in self.blocks]
        fixed = {"experiment": (lambda: [experiment] * self.size, (experiment, self.size)),
                 "job": (lambda: np.arange(self.size, dtype=np.int64), self.size),
                 "object": (lambda: self._repeat("object"), scenes),
                 "environment": (lambda: self._repeat("environment"), scenes)}
        sources: list[Callable[[], Any]] = []
        summaries: list[Any] = []
        for name in names:
            if name in keys:
                sources.append(lambda values=keys[name]: values)
            elif name in fixed:
                sources.append(fixed[name][0])
            else:
                sources.append(lambda name=name: self._parameter(name))
            summaries.append(fixed[name][1] if name in fixed else None)
        return names, sources, summaries

    def _repeat(self, attribute: str) -> list[str]:
        return [value for b in self.blocks for value in [getattr(b, attribute)] * b.size]

    def _parameter(self, name: str) -> np.ndarray | list[Any]:
        parts: list[np.ndarray | list[Any]] = []
        for block in self.blocks:
            where = block.parameters().get(name)
            parts.append(block.controls[where[0]].column(where[1]) if where else [None] * block.size)
        if all(isinstance(p, np.ndarray) for p in parts):
            return np.concatenate(parts) if parts else np.zeros(0)
        return [v for p in parts for v in (p.tolist() if isinstance(p, np.ndarray) else p)]


def _list_bytes(values: list[Any]) -> bytes:
    """``values`` written out unambiguously, fast for 10⁶ keys: strings as lines (as their
    lengths and text where one holds a newline), anything else (None, numbers) as its ``repr``."""
    try:
        joined = "\n".join(values)
    except TypeError:  # not all strings
        return b"\nrepr\n" + repr(values).encode()
    if joined.count("\n") == len(values) - 1:  # no value holds the separator: the text is unambiguous
        return b"\nlines\n" + joined.encode("utf-8", "surrogatepass")
    lengths = np.fromiter(map(len, values), dtype=np.int64, count=len(values))
    return b"\nstr\n" + lengths.tobytes() + "".join(values).encode("utf-8", "surrogatepass")


def _objects(values: list[Any]) -> np.ndarray:
    """``values`` as a 1-d object array (numpy would make rows of equal-length lists a 2-d one)."""
    out = np.empty(len(values), dtype=object)
    for i, value in enumerate(values):
        out[i] = value
    return out


def _first_row_names(block: SceneBlock, parameter_columns: list[str]) -> dict[str, None]:
    """The keys of the first row of :meth:`Plan.rows`, in order (what ``from_pylist`` takes as columns)."""
    names = dict.fromkeys(["experiment", "job", "object", "environment", *parameter_columns])
    names.update(dict.fromkeys(block.parameters()))
    names.update(dict.fromkeys(["render_key", "image_key", "pred_key", "parts_key", "in_frame"]))
    return names


@contextmanager
def paused_gc() -> Iterator[None]:
    """Pause the cyclic garbage collector while a million acyclic objects are made: it would
    otherwise walk the growing heap again and again (three quarters of the time, measured)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


class JobList(Sequence[Job]):
    """Some jobs of a :class:`PlanColumns` (those in frame, or those out of it), made on first use."""

    def __init__(self, columns: PlanColumns, indices: np.ndarray) -> None:
        self.columns = columns
        self.indices = indices
        self._jobs: list[Job] | None = None
        self._unique: dict[Callable, Mapping[str, Job]] = {}

    def unique_by(self, key: Callable[[Job], str | None],
                  keys_of: Callable[[JobList], list[str | None]] | None = None) -> Mapping[str, Job]:
        """The first job of each distinct ``key`` (None left out), in order; remembered per key
        function, as a run asks each stage's several times. Do not change the mapping returned.

        Args:
            keys_of: ``key`` of every job, from the columns (:meth:`key_column`): the distinct keys
                are then found without making a job, and the jobs are made only when one is read
                (a rerun that finds every key cached reads none).
        """
        function = getattr(key, "__func__", key)  # a stage's bound method: the same for every instance
        if function not in self._unique:
            if keys_of is not None:
                self._unique[function] = FirstJobs(self, _first_positions(keys_of(self)))
            else:
                unique: dict[str, Job] = {}
                for job in self._all():
                    k = key(job)
                    if k is not None:
                        unique.setdefault(k, job)
                self._unique[function] = unique
        return self._unique[function]

    def key_column(self, field: str) -> list[str | None]:
        """The ``field`` (``render_key``, ``image_key``, ``pred_key``) of each job, in order,
        read from the columns without making the jobs."""
        column = {"render_key": self.columns.render_keys, "image_key": self.columns.image_keys,
                  "pred_key": self.columns.pred_keys}[field]
        if len(self.indices) == len(column):  # every job of the plan (the indices ascend, distinct)
            return column
        return [column[i] for i in self.indices.tolist()]

    def scenes(self) -> set[tuple[str, str]]:
        """The (object, environment) scenes these jobs are of, read from the scene blocks (no job made)."""
        indices = np.asarray(self.indices)
        found = set()
        for block in self.columns.blocks:
            at = int(np.searchsorted(indices, block.start))  # the indices ascend
            if at < len(indices) and indices[at] < block.start + block.size:
                found.add((block.object, block.environment))
        return found

    def _all(self) -> list[Job]:
        if self._jobs is None:
            self._jobs = self.columns.jobs(self.indices)
        return self._jobs

    def __len__(self) -> int:
        return len(self.indices)

    @overload
    def __getitem__(self, i: int) -> Job: ...

    @overload
    def __getitem__(self, i: slice) -> list[Job]: ...

    def __getitem__(self, i: int | slice) -> Job | list[Job]:
        return self._all()[i]

    def __iter__(self) -> Iterator[Job]:
        return iter(self._all())

    def __add__(self, other: Sequence[Job]) -> list[Job]:
        return self._all() + list(other)

    def __radd__(self, other: Sequence[Job]) -> list[Job]:
        return list(other) + self._all()

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Sequence) and self._all() == list(other)

    def __repr__(self) -> str:
        return f"JobList({len(self)} jobs)"


@dataclass
class Plan:
    """A spec expanded into jobs, sorted by scene.

    Attributes:
        model_digest: the model's part of every prediction key.
        out_of_frame: jobs whose object is wholly outside the frame: flagged, never rendered.
        framing: the resolved frame (``resolution = "model"`` becomes the model's sizes).
        model: what results call the model the plan infers (its ``id`` or name).
        device: what renders: ``[render] device`` resolved ("cpu", "cuda", "optix"), as its
            render keys say.
        class_names: the classes the spec names otherwise than the model, as (class id, the
            model's name, the spec's name, whether the model's name is another class's too):
            ``results`` prints the spec's names (see ``spec.class_names``).
        view: the model's own resize and crop, when known (what a full frame goes through).
    """

    spec: LoadedSpec
    jobs: Sequence[Job]
    model_digest: str
    out_of_frame: Sequence[Job] = field(default_factory=list)
    framing: Framing | None = None
    model: str = ""
    device: str = "cpu"
    class_names: Sequence[tuple[int, str, str, bool]] = ()
    view: tuple[int, int] | None = None

    @property
    def protocol(self) -> str:
        """What the model sees, in one line (see ``Framing.protocol``); "" without a framing."""
        return self.framing.protocol(self.view) if self.framing is not None else ""

    @property
    def columns(self) -> list[str]:
        """One column per control parameter, in spec order."""
        return self.spec.parameter_columns

    def rows(self) -> list[dict[str, Any]]:
        """The jobs table: one row per job with its scene, control values, keys and ``in_frame``."""
        out = []
        flagged = {id(j) for j in self.out_of_frame}
        for job in sorted(self.jobs + self.out_of_frame, key=lambda j: j.index):
            row: dict[str, Any] = {"experiment": self.spec.name, "job": job.index,
                                   "object": job.object, "environment": job.environment}
            for column in self.columns:
                row[column] = None
            for control_id, values in job.values.items():
                for param, value in values.items():
                    row[parameter_column(control_id, param)] = value
            row.update(render_key=job.render_key, image_key=job.image_key, pred_key=job.pred_key,
                       parts_key=job.parts_key, in_frame=id(job) not in flagged)
            if job.truth_key is not None:  # only with truth passes: other plans' tables stay as they were
                row["truth_key"] = job.truth_key
            row["model"] = self.model or self.spec.model.label
            out.append(row)
        return out

    def evaluator_record(self) -> EvaluatorRecord:
        """The experiment's evaluator as the jobs file records it, for the views to follow."""
        kind = self.spec.evaluator.kind
        assert self.spec.catalogue is not None, "a spec from the loader carries its catalogue"
        return self.spec.catalogue.evaluators.get(kind).record(kind)

    def table(self) -> pa.Table:
        """:meth:`rows` as a table whose metadata lists the parameter columns (see spec.columns).

        A plan as the planner made it is written from its columns, without a row per job.
        """
        whole = _whole(self)
        if whole:
            table = whole.table(self.spec.name, self.columns)
            table = table.append_column("model", pa.array([self.model or self.spec.model.label] * table.num_rows,
                                                          pa.string()))
        else:
            table = pa.Table.from_pylist(self.rows())
        return table.replace_schema_metadata(self.metadata("truth_key" in table.column_names))

    def fingerprint(self) -> str | None:
        """A digest of :meth:`table` (its values and metadata) without building it; None for a
        plan whose jobs are not a whole planned plan's (its table is then built to compare)."""
        whole = _whole(self)
        if not whole:
            return None
        h = hashlib.sha256(whole.fingerprint(self.spec.name, self.columns).encode())
        h.update(json.dumps(self.model or self.spec.model.label).encode())
        for key, value in sorted(self.metadata(whole.truth_keys is not None).items()):
            h.update(b"\n" + key + b"=" + value)
        return h.hexdigest()

    def metadata(self, truths: bool) -> dict[bytes, bytes]:
        """The jobs table's schema metadata (``truths``: whether it has a ``truth_key`` column)."""
        metadata = {PARAMETERS_METADATA: json.dumps(self.columns).encode()}
        if truths:  # the validity gate's threshold, for the results view
            from sweep3d.driver.passes import visibility_gated

            gated = visibility_gated(self.spec)
            metadata[MIN_VISIBLE_METADATA] = repr(float(self.spec.evaluator.min_visible)).encode() if gated \
                else MIN_VISIBLE_OFF
        if self.spec.spec.aggregate.drop_fragile:  # only then: other plans' files stay as they were
            metadata[DROP_FRAGILE_METADATA] = b"true"
        metadata[EVALUATOR_METADATA] = self.evaluator_record().to_json()
        model = self.model or self.spec.model.label
        metadata[CLASS_NAMES_METADATA] = json.dumps({model: [list(c) for c in self.class_names]}).encode()
        metadata[PROTOCOL_METADATA] = json.dumps({model: self.protocol}).encode()
        return metadata


class FirstJobs(Mapping[str, Job]):
    """Distinct keys → the first job with each (see :meth:`JobList.unique_by`): the keys are
    known from the columns, the jobs made (all at once) the first time one is read."""

    def __init__(self, jobs: JobList, first: dict[str, int]) -> None:
        self._jobs = jobs
        self._first = first

    def __getitem__(self, key: str) -> Job:
        return self._jobs[self._first[key]]

    def __contains__(self, key: object) -> bool:
        return key in self._first

    def __iter__(self) -> Iterator[str]:
        return iter(self._first)

    def __len__(self) -> int:
        return len(self._first)

    def keys(self):  # type: ignore[override]  (the dict's own view: set operations in C)
        return self._first.keys()


def _first_positions(keys: list[str | None]) -> dict[str, int]:
    """Each distinct key (None left out) → where it first is, in order of first appearance."""
    first = dict(zip(keys, range(len(keys))))  # the last position, in order of first appearance
    if len(first) < len(keys):  # some key repeats (or is None throughout): each key's first position
        earliest = dict(zip(reversed(keys), range(len(keys) - 1, -1, -1)))
        first = {key: earliest[key] for key in first}
    first.pop(None, None)  # type: ignore[call-overload]
    return first  # type: ignore[return-value]


def _whole(plan: Plan) -> PlanColumns | None:
    """The columns behind ``plan`` when its jobs are exactly theirs (not a subset picked by hand)."""
    jobs, out = plan.jobs, plan.out_of_frame
    if isinstance(jobs, JobList) and (isinstance(out, JobList) and out.columns is jobs.columns or not out):
        if len(jobs) + len(out) == jobs.columns.size and jobs.columns.size:
            return jobs.columns
    return None
