"""What every export format is handed (the new images, each with its id, label and attributes),
the base class a format implements, and :data:`EXPORT_FORMATS`, the registry ``--format`` names
one in (a built-in's short name, or ``module:Name`` for a user's writer beside the spec)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import pyarrow as pa

from sweep3d.cache import Store
from sweep3d.core import Registry
from sweep3d.driver import StageProgress
from sweep3d.export.target import ExportFolder, Staging


@dataclass(frozen=True)
class Item:
    """One result to export.

    Attributes:
        id: its image id in the export (from 1, unique across appends).
        index: its row in the selection's table (:attr:`Batch.table`).
        row: every column of its ``results`` row (and the digests of its blobs).
        label: the object's true label (its first, as the spec writes it): the class.
        category: ``label``'s category id (from 1).
        attributes: what the export records about it: experiment, job, model, the scene, every
            control parameter, and its verdict (``correct``, ``valid``, ``evaluable``, …).
    """

    id: int
    index: int
    row: dict[str, Any]
    label: str
    category: int
    attributes: dict[str, Any]

    @property
    def stem(self) -> str:
        """The image's file name in the export (ids are unique, so names are)."""
        return f"{self.id:06d}.png"


@dataclass(frozen=True)
class Batch:
    """The items an export adds (in id order), and where their pixels are read from.

    Attributes:
        table: the selection's rows as DuckDB typed them (a Parquet export keeps their types).
        columns: ``results``' columns, in order (a Parquet export keeps all of them).
        link: hard-link image files to the store's blobs instead of copying them.
    """

    items: list[Item]
    store: Store
    table: pa.Table
    columns: list[str]
    link: bool = False


class DatasetWriter:
    """One export format: writes a batch's files into the staging folder, appending to what
    ``folder`` already holds (:attr:`ExportFolder.fresh` is False when appending).

    A built-in registers in :data:`EXPORT_FORMATS` under its ``--format`` name; a user's own is
    named ``--format module:Name`` (``module.py`` beside the spec) and needs no registration. It
    is made with no arguments, once per export.
    """

    #: It needs the mask pass (``[evaluator] passes = ["mask"]``).
    needs_mask: ClassVar[bool] = False
    #: It writes image files (``--link`` applies).
    files: ClassVar[bool] = True

    def write(self, batch: Batch, folder: ExportFolder, staging: Staging, progress: StageProgress) -> None:
        """Write ``batch`` (calling ``progress.advance()`` per item); raise ``UserError`` for what
        the user can fix (a missing blob)."""
        raise NotImplementedError

    def file_of(self, item: Item) -> str | None:
        """Where ``item``'s image file lies in the export (None: no file of its own)."""
        return None


#: ``--format`` → the writer of that format (``sweep3d.export`` registers the built-ins).
EXPORT_FORMATS: Registry[type[DatasetWriter]] = Registry("export format")
