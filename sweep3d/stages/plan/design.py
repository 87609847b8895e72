"""Designs as tables: a file whose rows are jobs, read by the ``table`` policy and written by ``plan --design``.

A design table has an ``object`` and an ``environment`` column and one column per control
parameter, named as ``jobs`` and ``results`` name it (``orientation_yaw``). A cell is empty
where the control does not apply to the row's scene. CSV (numbers as Python writes them, so
every float reads back bit for bit) and Parquet are read and written.

Reading checks every cell against the spec: an unknown object or column, a value outside the
range (or list) the spec gives, a missing value, a value for a control that does not apply in
the row's scene are each one line naming the file, the row (1 is the first row under the header)
and the column.
"""

from __future__ import annotations

import csv
import difflib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import pyarrow as pa

from sweep3d.core import SpecError, csv_text
from sweep3d.spec import Choice, ControlInstance, Fixed, Range, parameter_column

SCENE_COLUMNS = ("object", "environment")
SUFFIXES = (".csv", ".parquet")


@dataclass(frozen=True)
class Cell:
    """Where a value sits: what errors name."""

    file: str
    row: int  # 1-based, under the header
    column: str

    def fail(self, problem: str) -> SpecError:
        return SpecError(self.file, f"row {self.row}, column {self.column}", problem)


@dataclass
class SceneRows:
    """One scene's rows of a design: per open parameter, its values in row order."""

    count: int
    values: dict[tuple[str, str], list[Any]]


def rows_by_scene(rows: Sequence[Mapping[str, Any]],
                  columns: Mapping[str, tuple[str, str]]) -> dict[tuple[str, str], SceneRows]:
    """Configurations given in memory (each a dict of ``object``, ``environment`` and parameter
    columns) as a design's rows per scene; ``columns``: column → (control id, parameter) of those
    the rows set (others are left out)."""
    scenes: dict[tuple[str, str], SceneRows] = {}
    for row in rows:
        scene = scenes.setdefault((row["object"], row["environment"]), SceneRows(0, {}))
        for column, value in row.items():
            if column in columns:
                scene.values.setdefault(columns[column], []).append(value)
        scene.count += 1
    return scenes


def design_order(objects: Sequence[str], environments: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> list[int]:
    """Each of ``rows``' job index in a plan of them (:func:`rows_by_scene`): scenes in spec order
    (objects, then environments), a scene's rows in the order given."""
    counts: dict[tuple[str, str], int] = {}
    position = []
    for row in rows:
        scene = (row["object"], row["environment"])
        position.append((scene, counts.get(scene, 0)))
        counts[scene] = counts.get(scene, 0) + 1
    offsets, total = {}, 0
    for o in objects:
        for e in environments:
            if (o, e) in counts:
                offsets[(o, e)] = total
                total += counts[(o, e)]
    return [offsets[scene] + k for scene, k in position]


def read_design(path: Path, controls: Sequence[ControlInstance], objects: Sequence[str],
                environments: Sequence[str], base: Path) -> dict[tuple[str, str], SceneRows]:
    """The rows of the design file ``path`` per (object, environment), checked against the spec
    (``base``: the spec's folder, against which a file a cell names may be relative).

    Raises:
        SpecError: naming the file, and the row and column of the first bad cell.
    """
    names, rows = _read_rows(path)
    file = str(path)
    columns = {parameter_column(inst.id, param): (inst, param) for inst in controls for param in inst.spaces}
    _check_header(file, names, columns)
    if not rows:
        raise SpecError(file, "", "the design table has no rows; give one row per job under the header")
    scenes: dict[tuple[str, str], SceneRows] = {}
    for number, row in rows:
        cells = dict(zip(names, row))
        obj = _scene_name(Cell(file, number, "object"), cells.get("object"), objects)
        env = _scene_name(Cell(file, number, "environment"), cells.get("environment"), environments)
        scene = scenes.setdefault((obj, env), SceneRows(0, {}))
        for column, (inst, param) in columns.items():
            cell = Cell(file, number, column)
            value = _value(cell, cells.get(column), inst, param, inst.applies_to(obj, env), base)
            if value is not _NONE:
                scene.values.setdefault((inst.id, param), []).append(value)
        scene.count += 1
    return scenes


_NONE = object()  # a cell with no value to take (the control does not apply, or its parameter is fixed)


def _read_rows(path: Path) -> tuple[list[str], list[tuple[int, list[Any]]]]:
    """The header and the numbered rows: CSV cells as text (None for empty), Parquet cells as typed values."""
    if path.suffix.lower() == ".parquet":
        import pyarrow.parquet as pq

        try:
            table = pq.read_table(path)
        except (OSError, pa.ArrowException) as exc:
            raise SpecError(str(path), "", f"cannot read the design table: {exc}") from None
        columns = [table.column(i).to_pylist() for i in range(table.num_columns)]
        return list(table.column_names), [(number, list(r)) for number, r in enumerate(zip(*columns), start=1)]
    try:  # utf-8-sig: a byte order mark (Excel's "CSV UTF-8") is not part of the first column's name
        with path.open(newline="", encoding="utf-8-sig") as handle:
            lines = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise SpecError(str(path), "", f"cannot read the design table: {exc}") from None
    if not lines:
        raise SpecError(str(path), "", "the design table is empty; its first line names the columns "
                                       "(object, environment, then <control id>_<param> for each parameter)")
    header, rows = [name.strip() for name in lines[0]], []
    for number, row in enumerate(lines[1:], start=1):
        if not any(cell.strip() for cell in row):
            continue  # a blank line (often the last): no job, but row numbers still count it
        if len(row) != len(header):
            raise SpecError(str(path), f"row {number}", f"has {len(row)} cells where the header has {len(header)}"
                            + (" (is the file separated by semicolons? write it with commas)"
                               if len(header) == 1 and ";" in header[0] else ""))
        rows.append((number, [cell.strip() or None for cell in row]))
    return header, rows


def _check_header(file: str, names: list[str], columns: dict[str, tuple[ControlInstance, str]]) -> None:
    valid = [*SCENE_COLUMNS, *columns]
    for name in names:
        if name not in valid:
            close = difflib.get_close_matches(name, valid, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise SpecError(file, f"column {name}", f"names no control parameter of the spec{hint}; columns are "
                                                    f"{', '.join(valid)}")
    if len(set(names)) < len(names):
        twice = next(n for i, n in enumerate(names) if n in names[:i])
        raise SpecError(file, f"column {twice}", "appears twice; keep one")
    for name in SCENE_COLUMNS:
        if name not in names:
            raise SpecError(file, f"column {name}", "is missing; every row names its object and environment")
    for name, (inst, param) in columns.items():
        if name not in names and not isinstance(inst.spaces[param], Fixed):
            raise SpecError(file, f"column {name}", f"is missing; the spec varies {inst.id}.{param}, so each row "
                                                    "gives its value (empty where the control does not apply)")


def _scene_name(cell: Cell, value: Any, valid: Sequence[str]) -> str:
    name = "" if value is None else str(value)
    if name not in valid:
        close = difflib.get_close_matches(name, valid, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise cell.fail(f"{name!r} is not one of the spec's {cell.column}s{hint}")
    return name


def _value(cell: Cell, raw: Any, inst: ControlInstance, param: str, applies: bool, base: Path) -> Any:
    """The value of one cell, checked against the parameter's space in the spec."""
    space = inst.spaces[param]
    if raw is None and applies and isinstance(space, (Choice, Fixed)) and "" in space.values():
        raw = ""  # CSV writes "" (a listed value, e.g. background colour "": the environment's) as nothing
    if not applies:
        if raw is not None:
            raise cell.fail(f"control {inst.id} does not apply in this row's scene (see its objects/environments); "
                            "leave the cell empty")
        return _NONE
    if isinstance(space, Fixed):
        if raw is not None and not _same(raw, space.value):
            raise cell.fail(f"{raw!r} differs from {space.value!r}, the value the spec fixes; make it a range or "
                            "a list in the spec to vary it, or leave the cell empty")
        return _NONE
    if raw is None:
        raise cell.fail(f"is empty where control {inst.id} applies; give its {param}")
    if isinstance(space, Choice):
        for option in space.options:
            if _same(raw, option) or _same_file(raw, option, base):
                return option
        close = difflib.get_close_matches(str(raw), [str(o) for o in space.options], n=1)
        if not close:
            close = [str(o) for o in space.options if str(o).lower() == str(raw).lower()]
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise cell.fail(f"{raw!r} is not one of the values the spec lists{hint}: "
                        f"{', '.join(map(repr, space.options))}")
    return _number(cell, raw, space)


def _number(cell: Cell, raw: Any, space: Range) -> Any:
    if isinstance(raw, bool):
        raise cell.fail(f"{raw!r} is not a number")
    try:
        value = float(raw)
    except (TypeError, ValueError):
        raise cell.fail(f"{raw!r} is not a number") from None
    if not math.isfinite(value):
        raise cell.fail(f"{raw!r} is not a finite number")
    if not space.low <= value <= space.high:
        raise cell.fail(f"{raw!r} is outside the range [{_text(space.low)}, {_text(space.high)}] the spec gives")
    if space.integer:
        if value != round(value):
            raise cell.fail(f"{raw!r} is not a whole number, which this parameter takes")
        return int(round(value))
    return value


def _same(raw: Any, option: Any) -> bool:
    """Whether a cell holds ``option``: typed (Parquet) or as text (CSV)."""
    if not isinstance(raw, str):
        return type(raw) is type(option) and raw == option or (
            isinstance(raw, (int, float)) and isinstance(option, (int, float))
            and not isinstance(raw, bool) and not isinstance(option, bool) and raw == option)
    if isinstance(option, bool):
        return raw.lower() == str(option).lower()
    if isinstance(option, (int, float)):
        try:
            return float(raw) == option
        except ValueError:
            return False
    return raw == option


def _same_file(raw: Any, option: Any, base: Path) -> bool:
    """Whether a cell names the file ``option`` (an absolute path the loader made), relative to the spec."""
    if not (isinstance(raw, str) and isinstance(option, str) and raw and Path(option).is_absolute()):
        return False
    path = Path(raw).expanduser()
    return str((path if path.is_absolute() else base / path).resolve()) == option


def _text(number: float) -> str:
    return str(int(number)) if number == int(number) else repr(number)


def check_output(path: Path) -> None:
    """Refuse a design file ``write_design`` cannot write, before any work (one line: the fix)."""
    from sweep3d.core import UserError

    if path.suffix.lower() not in SUFFIXES:
        raise UserError(f"--design {path}: write a {' or '.join(SUFFIXES)} file")
    if not path.parent.is_dir():
        raise UserError(f"--design {path}: folder {path.parent} does not exist")
    if path.is_dir():
        raise UserError(f"--design {path}: is a folder; name a file")


def write_design(table: pa.Table, parameter_columns: Sequence[str], path: Path) -> int:
    """Write the design of a jobs table (object, environment, each parameter) to ``path``
    (.csv or .parquet); returns the number of rows."""
    names = [*SCENE_COLUMNS, *(c for c in parameter_columns if c in table.column_names)]
    design = table.select(names)
    if path.suffix.lower() == ".parquet":
        import pyarrow.parquet as pq

        pq.write_table(design, path)
        return design.num_rows
    path.write_text(csv_text(names, zip(*(design.column(n).to_pylist() for n in names))), encoding="utf-8")
    return design.num_rows
