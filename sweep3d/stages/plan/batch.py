"""One control over all the jobs of a scene at once: values, neutrality and key parts as columns,
equal bit for bit to what the control's own methods give job by job.

Jobs that share their listed values form a group, validated through the control's ``Params``
once. Range values then go one of two ways:

* a *plain* control (``params``, ``canonical`` and ``key_part`` as ``Control`` defines them, and
  a ``Params`` model that cannot change a number in range: no validators, serializers or computed
  fields, range fields bounded by intervals only) keeps them as arrays. Its key part is the
  canonical text of its group with a hole per range parameter, filled with each job's number as
  ``canonical`` writes it (angles wrapped first); its neutrality is compared over arrays.
* any other control (a user's, or one that rewrites its values) gets a group per distinct
  combination, ranges included, each through the control's own methods: few on a grid, one per
  job for random draws.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import annotated_types
import numpy as np
from pydantic import BaseModel

from sweep3d.cache import Hole, Template, canonical, canonical_pieces, float_texts
from sweep3d.core import Control, Typed, wrap_periodic_many
from sweep3d.driver import ControlValues
from sweep3d.spec import Column, ControlInstance

#: Metadata a range field may carry and stay plain: bounds, which every value in range meets.
INTERVALS = (annotated_types.Ge, annotated_types.Gt, annotated_types.Le, annotated_types.Lt)
_DECORATORS = ("validators", "field_validators", "root_validators", "model_validators", "field_serializers",
               "model_serializers", "computed_fields")


@dataclass
class ControlBatch:
    """One control's values over a scene's jobs, with what its key part needs.

    Attributes:
        identity: per job, whether the control leaves the image alone (dropped from keys).
        plain: whether range values stay arrays (see the module's docstring); else ``texts``
            holds each group's key part as canonical text.
    """

    inst: ControlInstance
    columns: dict[str, Column]
    values: ControlValues
    identity: np.ndarray
    plain: bool = False
    texts: np.ndarray | None = None

    @property
    def id(self) -> str:
        return self.inst.id

    def part(self, group: int) -> Any:
        """The key part of the jobs of ``group``, with a :class:`Hole` for what differs between them."""
        if not self.plain:
            return Hole(self.hole())
        dump = dict(self.values.dumps[group])
        for param in self.values.numbers:
            dump[param] = Hole(self.hole(param))
        return self.inst.control.key_part(dump)

    def patterns(self, rows: np.ndarray) -> list[np.ndarray]:
        """Codes that are equal for jobs (of ``rows``) whose key parts share a :meth:`part`."""
        effective = ~self.identity[rows]
        return [self.values.group[rows], effective] if self.plain else [effective]

    def codes(self, rows: np.ndarray) -> list[np.ndarray]:
        """Codes that are equal for jobs (of ``rows``) whose values are equal."""
        return [self.values.group[rows]] + [_codes(numbers[rows]) for numbers in self.values.numbers.values()]

    def hole_texts(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """The canonical text filling each hole of :meth:`part`, per job of ``rows``."""
        if not self.plain:
            return {self.hole(): self.texts[self.values.group[rows]]}  # type: ignore[index]
        return {self.hole(param): self._number_texts(param, rows) for param in self.values.numbers}

    def hole(self, param: str = "") -> str:
        """The name of a hole of :meth:`part`: under ``control:``, so that no control id (``render``)
        can take the name of a key's other holes (``render``, ``image``)."""
        return f"control:{self.id}.{param}" if param else f"control:{self.id}"

    def _number_texts(self, param: str, rows: np.ndarray) -> np.ndarray:
        """Canonical texts of a range parameter's numbers, as ``key_part`` would write them."""
        numbers = self.values.numbers[param][rows]
        period = self.inst.control.periodic.get(param)
        if period is not None:
            return float_texts(wrap_periodic_many(numbers, period))
        if numbers.dtype == object:  # an integer range
            return np.array([str(int(v)) for v in numbers.tolist()], dtype=object)
        return float_texts(numbers)

    def raw(self, row: int) -> dict[str, Any]:
        """The job's values as the search space gives them (before validation)."""
        return _raw(self.columns, row)


def keyed_texts(batches: list[ControlBatch], rows: np.ndarray,
                make: Callable[[list[ControlBatch], list[Any]], Template | None],
                strings: dict[str, Sequence[str]] | None = None) -> list[str | None]:
    """For the jobs of ``rows``, the canonical text of a key's value built by ``make`` from the
    controls in ``batches`` that change the job's image and their key parts (in that order).

    Jobs whose effective controls share their parts (a *pattern*) share one :class:`Template`,
    filled per job; ``make`` returns None where the key is not hashed (no effective control).

    Args:
        strings: other holes of ``make``'s value, filled with plain strings (keys), per job.
    """
    n = len(rows)
    strings = strings or {}
    first, pattern = groups([code for b in batches for code in b.patterns(rows)], n)
    holes: dict[str, np.ndarray] = {}
    for b in batches:
        holes.update(b.hole_texts(rows))
    holes.update({name: np.array(column, dtype=object) for name, column in strings.items()})
    order = np.argsort(pattern, kind="stable")
    bounds = np.searchsorted(pattern[order], np.arange(len(first) + 1))
    out = np.empty(n, dtype=object)
    for p, at in enumerate(rows[first].tolist()):
        effective = [b for b in batches if not b.identity[at]]
        template = make(effective, [b.part(b.values.group[at]) for b in effective])
        if template is None:
            continue
        chosen = order[bounds[p]:bounds[p + 1]] if len(first) > 1 else slice(None)
        if not template.names:
            out[chosen] = template.pieces[0]
            continue
        texts = template.fill(list(strings), **{name: holes[name][chosen].tolist() for name in template.names})
        if len(first) == 1:
            return texts
        out[chosen] = texts
    return out.tolist()


def control_batch(inst: ControlInstance, columns: dict[str, Column], n: int) -> ControlBatch:
    """``inst`` over the ``n`` jobs whose unvalidated values are ``columns`` (parameter → column)."""
    control = inst.control
    ranges = [p for p, c in columns.items() if c.numbers is not None]
    if ranges and _plain(control, ranges, set(columns)):
        first, group = groups([c.index for c in columns.values() if c.index is not None], n)
        dumps = [control.params(_raw(columns, r)).model_dump() for r in first.tolist()]
        try:
            return _plain_batch(inst, columns, ControlValues(dumps, group, {p: columns[p].numbers for p in ranges}))
        except ValueError:  # a value imitates a hole: write each group in full
            pass
    codes = [c.index for c in columns.values() if c.index is not None] + [_codes(columns[p].numbers) for p in ranges]
    first, group = groups(codes, n)
    dumps = [control.params(_raw(columns, r)).model_dump() for r in first.tolist()]
    neutral = np.array([control.is_identity(d) for d in dumps], dtype=bool)
    texts = np.empty(len(dumps), dtype=object)
    for g, dump in enumerate(dumps):
        texts[g] = None if neutral[g] else canonical(control.key_part(dump))
    return ControlBatch(inst, columns, ControlValues(dumps, group), neutral[group], texts=texts)


def _plain_batch(inst: ControlInstance, columns: dict[str, Column], values: ControlValues) -> ControlBatch:
    batch = ControlBatch(inst, columns, values, np.zeros(len(values.group), bool), plain=True)
    for group in range(len(values.dumps)):
        canonical_pieces(batch.part(group))  # raises ValueError where a value imitates a hole
    batch.identity = _identity(batch)
    return batch


def _identity(batch: ControlBatch) -> np.ndarray:
    """Per job, ``control.is_identity`` of its values: over arrays for the base method, else once
    per distinct combination."""
    control, values = batch.inst.control, batch.values
    if type(control).is_identity is not Control.is_identity:
        codes = [values.group] + [_codes(numbers) for numbers in values.numbers.values()]
        first, inverse = groups(codes, len(values.group))
        return np.array([control.is_identity(values.at(r)) for r in first.tolist()], dtype=bool)[inverse]
    neutral = control.canonical(control.Params().model_dump())
    fixed = np.array([all(canon.get(k) == v for k, v in neutral.items() if k not in values.numbers)
                      for canon in (control.canonical(d) for d in values.dumps)], dtype=bool)
    identity = fixed[values.group]
    for param, numbers in values.numbers.items():
        period = control.periodic.get(param)
        canon = wrap_periodic_many(numbers, period) if period is not None else numbers
        identity &= np.asarray(canon == neutral.get(param), dtype=bool)
    return identity


def _plain(control: Control, ranges: list[str], given: set[str]) -> bool:
    """Whether ``control`` maps range values to key parts as :class:`Control` does, unchanged (its
    ``canonical`` may fold parameters, see ``Control.folds``, none of which ``given`` reads from a range)."""
    cls, model = type(control), control.Params
    if any(getattr(cls, m) is not getattr(Control, m) for m in ("params", "key_part")):
        return False
    if cls.canonical is not Control.canonical and not _folds_fixed(control, ranges, given):
        return False
    if any(_own_decorators(model, kind) for kind in _DECORATORS):
        return False
    if any(getattr(model, m) is not getattr(BaseModel, m) for m in ("__init__", "model_dump", "model_post_init")):
        return False
    for param in ranges:
        info = model.model_fields[param]
        if info.annotation not in (int, float) or info.exclude or info.alias not in (None, param):
            return False
        if info.validation_alias is not None or info.serialization_alias not in (None, param):
            return False
        if not all(isinstance(m, INTERVALS) for m in info.metadata):
            return False
    return True


def _folds_fixed(control: Control, ranges: list[str], given: set[str]) -> bool:
    """Whether ``control`` folds parameters and each one ``given`` is folded from fixed values: its
    ``canonical`` then writes a group's key part, holes and all, as the base method would per job."""
    folds = type(control).folds
    return bool(folds) and all(not ({param, *others} & set(ranges)) for param, others in folds.items()
                               if param in given)


def _own_decorators(model: type[BaseModel], kind: str) -> dict[str, Any]:
    """The model's decorators of ``kind``, but for :class:`~sweep3d.core.typed.Typed`'s type check,
    which refuses a value of the wrong type and never changes one that fits (a number in range)."""
    found = dict(getattr(model.__pydantic_decorators__, kind, None) or {})
    typed = Typed.__pydantic_decorators__.field_validators["_no_coercion"]
    mine = found.get("_no_coercion") if kind == "field_validators" else None
    if mine is not None and _function(mine.func) is _function(typed.func):
        del found["_no_coercion"]
    return found


def _function(method: Any) -> Any:
    """The plain function behind a (class-bound) method."""
    return getattr(method, "__func__", method)


def groups(codes: list[np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray]:
    """(first row of each group, each row's group) for rows grouped by equal ``codes``."""
    if not codes:
        return np.zeros(min(n, 1), dtype=np.intp), np.zeros(n, dtype=np.intp)
    combined = np.zeros(n, dtype=np.int64)
    size = 1
    for code in codes:
        code = np.asarray(code)
        if code.dtype == bool or (code.dtype.kind in "iu" and (not n or (code.min() >= 0 and code.max() < n))):
            levels = int(code.max()) + 1 if n else 1
        else:
            code = np.unique(code, return_inverse=True)[1].reshape(-1)
            levels = int(code.max()) + 1 if n else 1
        if size * levels >= 1 << 62:  # too many combinations for one integer: compact what there is
            combined = np.unique(combined, return_inverse=True)[1].reshape(-1).astype(np.int64)
            size = int(combined.max()) + 1 if n else 1
        combined = combined * levels + code.astype(np.int64)
        size *= levels
    _, first, group = np.unique(combined, return_index=True, return_inverse=True)
    return first, group.reshape(-1)


def _codes(numbers: np.ndarray) -> np.ndarray:
    """Integers equal exactly where ``numbers`` are the same value (bits for floats: -0.0 ≠ 0.0)."""
    if numbers.dtype == np.float64:
        return numbers.view(np.int64)
    return np.unique(numbers, return_inverse=True)[1].reshape(-1)


def _raw(columns: dict[str, Column], row: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for param, column in columns.items():
        if column.numbers is not None:
            value = column.numbers[row]
            out[param] = value.item() if column.numbers.dtype != object else value
        else:
            out[param] = column.options[0 if column.index is None else int(column.index[row])]
    return out
