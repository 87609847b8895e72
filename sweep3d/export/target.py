"""The export's folder: what may be written where, the manifest that makes appending safe, the
design table, and writing through a staging folder so a failed export leaves nothing behind.

Every export folder holds ``sweep3d-export.json`` (its format, categories and one entry per
exported image: its id, where it came from and its attributes) and ``design.csv``. An append
reads the manifest, skips results already exported, continues the ids after the largest one
and keeps category ids by name, so ids stay unique. Nothing in either file depends on the time
or the machine: the same export twice writes the same bytes.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

from sweep3d.cache import safe_filename
from sweep3d.core import UserError, csv_text

MANIFEST = "sweep3d-export.json"
DESIGN = "design.csv"
MANIFEST_VERSION = 1
#: The design table's first columns; the control parameters follow (``<control id>_<param>``).
SCENE = ("object", "environment")


@dataclass
class ExportFolder:
    """An export's folder as it is before this export: new (``fresh``) or one to append to.

    Attributes:
        categories: label → category id (from 1), in id order.
        items: the manifest's entries, in id order.
    """

    root: Path
    format: str
    fresh: bool
    categories: dict[str, int] = field(default_factory=dict)
    items: list[dict[str, Any]] = field(default_factory=list)

    def category(self, label: str) -> int:
        """``label``'s category id, giving a new label the next id."""
        if label not in self.categories:
            self.categories[label] = max(self.categories.values(), default=0) + 1
        return self.categories[label]

    def next_id(self) -> int:
        return max((item["id"] for item in self.items), default=0) + 1

    def known(self) -> set[tuple]:
        """The identities (:func:`identity`) of the results already exported."""
        return {identity(item) for item in self.items}

    def manifest(self) -> bytes:
        document = {"format": self.format, "version": MANIFEST_VERSION,
                    "categories": [{"id": i, "name": name} for name, i in self.categories.items()],
                    "items": self.items}
        return json_bytes(document, indent=1)


def identity(entry: dict[str, Any]) -> tuple:
    """What makes a result the same one again: its experiment, model, job and image."""
    return entry["experiment"], entry.get("model"), entry["job"], entry["image_key"]


def open_folder(output: Path, store: Path, fmt: str, append: bool) -> ExportFolder:
    """Check that an export of ``fmt`` may be written at ``output``.

    Raises:
        UserError: ``output`` is inside the store, is a file, or is a folder holding other files
            (without ``append``), or ``append`` names a folder that is not a ``fmt`` export.
    """
    if Path(os.path.realpath(output)).is_relative_to(os.path.realpath(store)):
        raise UserError(f"--output {output}: inside the store {store}, whose files only sweep3d's runs write; "
                        "export to another folder")
    if output.exists() and not output.is_dir():
        raise UserError(f"--output {output}: is a file, not a folder; name a new folder for the export")
    try:
        entries = list(output.iterdir()) if output.is_dir() else []
    except OSError as exc:
        raise UserError(f"--output {output}: cannot be read ({exc.strerror})") from None
    if not entries:
        return ExportFolder(output, fmt, fresh=True)
    existing = _read_manifest(output)
    if not append:
        raise UserError(f"--output {output}: the folder already holds files; {_other_folder(existing, fmt)}")
    if existing is None:
        raise UserError(f"--append {output}: not a sweep3d export (no readable {MANIFEST}); name a new or "
                        "empty folder instead")
    if existing.format != fmt:
        raise UserError(f"--append {output}: it is a {existing.format} export, not {fmt}; use --format "
                        f"{existing.format} or another folder")
    return existing


def _other_folder(existing: ExportFolder | None, fmt: str) -> str:
    """What to do about a folder that holds files: ``--append`` only where an append would work."""
    if existing is None:
        return "name a new or empty folder (it is not a sweep3d export, so --append cannot add to it)"
    if existing.format != fmt:
        return (f"it is a {existing.format} export: name a new or empty folder, or add --append with "
                f"--format {existing.format}")
    return f"name a new or empty folder, or add --append to add to the {fmt} export there"


def _read_manifest(output: Path) -> ExportFolder | None:
    """The sweep3d export ``output`` holds, as its manifest records it (None: it is not one)."""
    try:
        document = json.loads((output / MANIFEST).read_text())
        found = str(document["format"])
        categories = {c["name"]: int(c["id"]) for c in document["categories"]}
        items = list(document["items"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return ExportFolder(output, found, fresh=False, categories=categories, items=items)


class Staging:
    """Where an export writes before it is committed: beside a new folder (renamed into place),
    or inside the folder appended to (each file moved into place, the manifest last)."""

    def __init__(self, folder: ExportFolder) -> None:
        self.target = folder.root
        self.fresh = folder.fresh
        tag = uuid.uuid4().hex[:12]
        self.root = (folder.root.parent / f".{folder.root.name}.{tag}.tmp" if folder.fresh
                     else folder.root / f".staging-{tag}")
        try:
            self.root.mkdir(parents=True)
        except OSError as exc:
            raise UserError(f"--output {folder.root}: cannot create it ({exc.strerror})") from None

    def path(self, relative: str) -> Path:
        """Where the file ``relative`` (to the export's root) is written now (its folder made)."""
        path = self.root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        return path

    def write(self, relative: str, data: bytes) -> None:
        self.path(relative).write_bytes(data)

    def place(self, relative: str, data: bytes, source: Path, link: bool) -> None:
        """The image ``data`` at ``relative``: a hard link to ``source`` (the store's blob, whose
        bytes ``data`` are) with ``link`` where the file system allows it, else a copy."""
        target = self.path(relative)
        if link:
            try:
                os.link(source, target)
                return
            except OSError:
                pass  # another file system, or links not allowed: copy
        target.write_bytes(data)

    def commit(self) -> None:
        """Move what was written into the export's folder."""
        try:
            if self.fresh:
                os.rename(self.root, self.target)  # replaces an empty folder, as open_folder allowed
                return
            files = sorted((p for p in self.root.rglob("*") if not p.is_dir()), key=lambda p: p.name == MANIFEST)
            for path in files:
                final = self.target / path.relative_to(self.root)
                final.parent.mkdir(parents=True, exist_ok=True)
                os.replace(path, final)
            shutil.rmtree(self.root)
        except OSError as exc:
            raise UserError(f"--output {self.target}: cannot write it ({exc.strerror})") from None

    def discard(self) -> None:
        shutil.rmtree(self.root, ignore_errors=True)


def design_table(items: Iterable[dict[str, Any]]) -> bytes:
    """``design.csv``: one row per exported image, in id order; columns ``object``, ``environment``
    and every control parameter (``<control id>_<param>``) as ``results`` names them, empty where
    a control does not apply to the job's scene."""
    items = list(items)
    columns = list(dict.fromkeys([*SCENE, *(c for item in items for c in item["design"])]))
    return csv_bytes(columns, ([item["design"].get(c) for c in columns] for item in items))


def csv_bytes(columns: list[str], rows: Iterable[list[Any]]) -> bytes:
    """CSV as DuckDB writes it (see :mod:`sweep3d.core.csv_format`), as bytes."""
    return csv_text(columns, rows).encode()


def json_bytes(document: Any, indent: int | None = None) -> bytes:
    """``document`` as JSON; NaN or infinity is a bug here, never written as invalid JSON."""
    separators = (",", ": ") if indent is not None else (",", ":")
    return (json.dumps(document, indent=indent, separators=separators, allow_nan=False, ensure_ascii=False)
            + "\n").encode()


def class_folder(label: str) -> str:
    """A folder name for ``label``: the label itself where it can be one (spaces kept), else
    :func:`~sweep3d.cache.store.safe_filename`'s (``/`` or a control character replaced, a hash added)."""
    plain = (label not in ("", ".", "..") and not any(c in label for c in "/\\") and label.isprintable()
             and len(label.encode()) <= 120)
    return label if plain else safe_filename(label)
