"""What an evaluator declares beside its rows, shared by every layer that reads it.

An evaluator (``sweep3d.stages.infer.evaluators``) has its own settings, a pydantic
:class:`EvaluatorParams` model read from the spec's ``[evaluator]`` table, and says which of its
columns plays which :class:`Roles` part: which one is the verdict (``correct``), the loss, the
outcome, …. The plan records the experiment's evaluator (:class:`EvaluatorRecord`, in its jobs
file's metadata), so the views, the summary and the report follow *that* evaluator, never the
columns another experiment left in a shared store. This module imports no stage, so the spec
loader checks a declaration and the aggregate stage reads a record without importing a user's
evaluator.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Callable

import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import ConfigDict

from sweep3d.core.typed import Typed

#: Parquet metadata key of a jobs file recording its experiment's evaluator (a JSON object).
EVALUATOR_METADATA = b"sweep3d.evaluator"
#: What a box or mask task says of each image (the ``outcome`` role), besides null for an invalid one;
#: in the order the report stacks them.
OUTCOMES = ("correct", "wrong_class", "wrong_box", "missed")


class EvaluatorParams(Typed):
    """Base of every evaluator's settings: unknown keys are errors, values are checked."""

    model_config = ConfigDict(extra="forbid", frozen=True)


def _is_bool(t: pa.DataType) -> bool:
    return pa.types.is_boolean(t)


def _is_number(t: pa.DataType) -> bool:
    return pa.types.is_floating(t) or pa.types.is_integer(t)


def _is_text(t: pa.DataType) -> bool:
    return pa.types.is_string(t) or pa.types.is_large_string(t)


def _is_numbers(t: pa.DataType) -> bool:
    return pa.types.is_list(t) and _is_number(t.value_type)


#: Each role: the name ``results`` shows it under, and the type its column must have.
ROLE_COLUMNS: dict[str, tuple[str, Callable[[pa.DataType], bool], str]] = {
    "valid": ("valid", _is_bool, "bool"),
    "correct": ("correct", _is_bool, "bool"),
    "loss": ("loss", _is_number, "a number"),
    "outcome": ("outcome", _is_text, "a string"),
    "iou": ("iou", _is_number, "a number"),
    "prediction": ("top1_label", _is_text, "a string"),
    "detection_scores": ("det_scores", _is_numbers, "a list of numbers"),
    "detection_ious": ("det_ious", _is_numbers, "a list of numbers"),
}


@dataclass(frozen=True)
class Roles:
    """Which of an evaluator's columns plays which part (None: it has none).

    Attributes:
        valid: false when the model's output was unusable (the row is then counted apart).
        correct: the verdict every accuracy counts (bool; required).
        loss: what ranks the worst failures and guides adaptive search (higher is worse).
        outcome: how an image failed, one of :data:`OUTCOMES` (the *Boxes and masks* panel).
        iou: the overlap with the truth (IoU per object; 1 - IoU guides search without a loss).
        prediction: the predicted class name (confusions, and the report's captions).
        detection_scores, detection_ious: per image, every matching detection's score and IoU
            (lists of equal length), for average precision.

    ``results`` shows a role's column under its usual name (``correct``, ``loss``, ``top1_label``,
    … see :data:`ROLE_COLUMNS`) too, so the views read one name whatever the evaluator calls it.
    """

    valid: str = "valid"
    correct: str = "correct"
    loss: str | None = None
    outcome: str | None = None
    iou: str | None = None
    prediction: str | None = None
    detection_scores: str | None = None
    detection_ious: str | None = None

    def columns(self) -> dict[str, str]:
        """Role → its column, for the roles the evaluator fills."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}

    def aliases(self) -> dict[str, str]:
        """The usual name ``results`` gives each filled role → the evaluator's column."""
        return {ROLE_COLUMNS[role][0]: column for role, column in self.columns().items()}

    def has(self, role: str) -> bool:
        return getattr(self, role) is not None

    def problem(self, schema: pa.Schema) -> str | None:
        """What is wrong with these roles for ``schema`` (None: nothing): a role's column must be
        in it with the role's type, and no other column may take a role's usual name."""
        types = dict(zip(schema.names, schema.types))
        for role, column in self.columns().items():
            usual, fits, kind = ROLE_COLUMNS[role]
            if column not in types:
                return (f"its {role} column {column!r} is not in its schema ({', '.join(schema.names)}); "
                        f"add it, or set roles = Roles({role}=...) to the column that is")
            if not fits(types[column]):
                return f"its {role} column {column!r} is {types[column]}, not {kind}"
        aliases = self.aliases()
        for usual, column in aliases.items():
            if usual in types and usual != column:
                return (f"its column {usual!r} would be hidden by its {_role_of(usual)} column {column!r}, "
                        f"which results show as {usual!r}; rename one")
        if self.has("detection_scores") != self.has("detection_ious"):
            return "detection_scores and detection_ious go together: set both or neither"
        return None

    @classmethod
    def guess(cls, columns: set[str]) -> "Roles":
        """The roles of a plan that recorded no evaluator (made before plans did): each role's
        usual column, where there is one."""
        found = {role: usual for role, (usual, _, _) in ROLE_COLUMNS.items() if usual in columns}
        return cls(**{"valid": "valid", "correct": "correct", **found})


def _role_of(usual: str) -> str:
    return next(role for role, (name, _, _) in ROLE_COLUMNS.items() if name == usual)


@dataclass(frozen=True)
class EvaluatorRecord:
    """The experiment's evaluator as its plan records it: its kind, its columns and their roles."""

    kind: str
    columns: tuple[str, ...]
    roles: Roles

    def to_json(self) -> bytes:
        return json.dumps({"kind": self.kind, "columns": list(self.columns), "roles": asdict(self.roles)}).encode()

    @classmethod
    def from_json(cls, raw: bytes) -> "EvaluatorRecord":
        data: dict[str, Any] = json.loads(raw)
        return cls(str(data["kind"]), tuple(data["columns"]), Roles(**data["roles"]))


def read_record(jobs: Path) -> EvaluatorRecord | None:
    """The evaluator the plan at ``jobs`` recorded; None for a plan from before plans recorded
    it (or a jobs file written by hand), or one that does not read."""
    try:
        raw = (pq.read_schema(jobs).metadata or {}).get(EVALUATOR_METADATA)
        return EvaluatorRecord.from_json(raw) if raw is not None else None
    except (OSError, ValueError, TypeError, KeyError, pa.ArrowException):
        return None


def declaration_problem(cls: Any) -> str | None:
    """What keeps ``cls`` from being an evaluator (None: nothing): it must be a class with a
    pyarrow ``schema``, an :class:`EvaluatorParams` ``Params``, :class:`Roles` that fit the
    schema, and an ``evaluate`` method."""
    if not isinstance(cls, type) or not callable(getattr(cls, "evaluate", None)):
        return "is not an evaluator class (subclass sweep3d.stages.infer.Evaluator)"
    if not isinstance(getattr(cls, "schema", None), pa.Schema):
        return "declares no pyarrow schema (schema = pa.schema([...]) of the columns it returns)"
    params = getattr(cls, "Params", None)
    if not (isinstance(params, type) and issubclass(params, EvaluatorParams)):
        return "its Params is not an EvaluatorParams model (class Params(EvaluatorParams): ...)"
    roles = getattr(cls, "roles", None)
    if not isinstance(roles, Roles):
        return "its roles is not a Roles (roles = Roles(correct=..., loss=...))"
    return roles.problem(cls.schema)
