"""``sweep3d export``: the chosen results of a run (by default its failures) as a dataset to train
or test on, in one of :data:`EXPORT_FORMATS` (a built-in, or ``module:Name``: a user's
:class:`DatasetWriter` beside the spec), with ``design.csv`` beside it: the configurations that
made them, so the same scenes can be rendered again later (for a retrained model, say).

Every check a user's input can fail (the format, ``--where``, the folder) runs before anything is
written, and the files are written into a staging folder that is moved into place at the end:
an export that stops (a damaged blob, Ctrl-C) leaves the folder as it was.
"""

from __future__ import annotations

import datetime
import decimal
import errno
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sweep3d.cache import Store, safe_filename
from sweep3d.core import PLUGIN_FAILURES, UserError, is_user_plugin, plugin_failure
from sweep3d.driver import RunProgress, StageProgress
from sweep3d.export import coco, imagefolder, parquet  # noqa: F401  (the built-ins register in EXPORT_FORMATS)
from sweep3d.export.formats import EXPORT_FORMATS, Batch, DatasetWriter, Item
from sweep3d.export.selection import DEFAULT_WHERE, UNEVALUABLE, Selection, check_where, select
from sweep3d.export.target import DESIGN, MANIFEST, SCENE, ExportFolder, Staging, design_table, identity, open_folder
from sweep3d.results import no_results
from sweep3d.runner import write_unstored_images
from sweep3d.spec import LoadedSpec, plugin_folder

if TYPE_CHECKING:
    from rich.console import Console

#: The registry's name before there was one (``name in FORMATS``, ``FORMATS.get(name)``, iteration still work).
FORMATS = EXPORT_FORMATS
#: The errors of a disk that has no room left (for the export, or for the user's quota).
DISK_FULL = (errno.ENOSPC, errno.EDQUOT)
#: Columns of ``results`` an image's attributes carry besides its scene and control values, where they exist.
VERDICT = ("valid", "correct", "outcome", "top1_label", "evaluable", "visible_fraction")


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote.

    Attributes:
        added: images this export added.
        total: images the export folder holds now.
        left_out: results chosen but left out as not evaluable (``--unevaluable skip``).
        already: results chosen that an earlier export into the folder holds already.
    """

    folder: Path
    format: str
    added: int
    total: int
    categories: int
    left_out: int
    already: int
    where: str = DEFAULT_WHERE

    @property
    def written(self) -> bool:
        """Whether the export wrote anything (an export that selects nothing writes no folder)."""
        return self.added > 0

    def line(self) -> str:
        """One line for the command line."""
        if self.total == 0:
            return self._nothing()
        notes = []
        if self.left_out:
            notes.append(f"{self.left_out} not evaluable left out (--unevaluable flag keeps them)")
        if self.already:
            notes.append(f"{self.already} already in the export")
        extra = f"; {', '.join(notes)}" if notes else ""
        return (f"exported {self.added} images ({self.total} in all, {self.categories} categories) as {self.format} "
                f"to {self.folder}, with its design table {DESIGN}{extra}")

    def _nothing(self) -> str:
        """What an export that selected nothing says (it writes nothing: an empty dataset is not
        one ``datasets`` or COCO tools load)."""
        left = f" ({self.left_out} not evaluable left out: --unevaluable flag keeps them)" if self.left_out else ""
        return f"nothing to export: no result meets --where {self.where!r}{left}; nothing written to {self.folder}"


def writer_for(fmt: str, spec: LoadedSpec | None = None) -> DatasetWriter:
    """The writer of ``--format fmt``: a built-in's name, or ``module:Name`` (a
    :class:`DatasetWriter` subclass; ``module.py`` beside ``spec`` is found wherever the command runs).

    Raises:
        UserError: ``fmt`` names no format, a module that does not import, something that is not a
            ``DatasetWriter`` subclass, or one whose construction fails (a ``PluginError`` naming it).
    """
    if is_user_plugin(fmt) and spec is not None:
        plugin_folder(spec.path.parent)
    try:
        cls = EXPORT_FORMATS.get(fmt)
    except UserError as exc:  # unknown, or a user's module that does not import (its details kept for --debug)
        exc.args = (f"--format {fmt!r}: {exc}",)
        raise
    if not (isinstance(cls, type) and issubclass(cls, DatasetWriter)):
        what = f"a {type(cls).__name__}" if not isinstance(cls, type) else f"class {cls.__qualname__}"
        raise UserError(f"--format {fmt!r}: is {what}, not a sweep3d DatasetWriter subclass; an export format "
                        "subclasses sweep3d.plugins.DatasetWriter and writes its files in write()")
    try:
        return cls()
    except UserError:
        raise
    except PLUGIN_FAILURES as exc:
        raise plugin_failure(f"export format {fmt!r}", exc, "failed to start") from None


def default_output(spec: LoadedSpec, fmt: str) -> Path:
    """``exports/<experiment>-<format>`` beside the spec (a user's ``module:Name`` as a safe file name)."""
    return spec.path.parent / "exports" / f"{safe_filename(spec.name)}-{safe_filename(fmt)}"


def export_dataset(spec: LoadedSpec, fmt: str, *, output: Path | None = None, where: str | None = None,
                   model: str | None = None, unevaluable: str = "skip", append: bool = False, link: bool = False,
                   console: Console | None = None) -> ExportResult:
    """Export the results of ``spec``'s experiment that meet ``where`` (default: the failures).

    Args:
        output: the export's folder (default :func:`default_output`): new, empty, or with
            ``append`` an export of the same format to add to.
        model: whose results (its id; default the spec's first model).
        unevaluable: ``skip`` leaves out jobs whose ``evaluable`` is false; ``flag`` keeps them,
            marked (attribute ``evaluable: false``; COCO annotations ``ignore: 1``).
        link: hard-link image files to the store's blobs where the file system allows it.
        console: where the progress bar shows (None: none).

    Raises:
        UserError: an unknown format or ``unevaluable``, a ``where`` that is not one condition,
            an output folder that holds other files, no results, a damaged blob. Nothing is
            written then.
    """
    writer = writer_for(fmt, spec)
    if unevaluable not in UNEVALUABLE:
        raise UserError(f"--unevaluable {unevaluable!r}: use {' or '.join(UNEVALUABLE)}")
    if link and not writer.files:
        raise UserError(f"--link: a {fmt} export holds the images' bytes, not files; leave --link out")
    condition = check_where(DEFAULT_WHERE if where is None else where)
    folder = open_folder(Path(output) if output is not None else default_output(spec, fmt), spec.store, fmt, append)
    if not Path(spec.store).is_dir():  # after the options' own mistakes, before anything is made
        raise no_results(Store(spec.store), spec.name, spec.path)
    selection = select(spec, condition, model, unevaluable)
    if writer.needs_mask and not selection.truth:
        raise UserError(f"--format {fmt} takes boxes and masks from the mask pass, which {spec.path} does not render: "
                        "add passes = [\"mask\"] to its [evaluator], run it again, then export")
    items, already = _new_items(spec, selection, folder, writer)
    result = ExportResult(folder.root, fmt, len(items), len(folder.items), len(folder.categories),
                          selection.skipped, already, condition)
    if not items:
        return result  # nothing selected, or nothing new: the folder stays as it is (or is not made)
    store = Store(spec.store)
    write_unstored_images(spec, store, [item.row["image_key"] for item in items])  # made in memory by the run
    _write(writer, fmt, Batch(items, store, selection.table, selection.columns, link), folder, already, console)
    return result


def _write(writer: DatasetWriter, fmt: str, batch: Batch, folder: ExportFolder, already: int,
           console: Console | None) -> None:
    """Write ``batch`` through a staging folder, moved into place at the end; a write the disk
    refuses (full, read-only) is one line naming the folder, and leaves it as it was."""
    staging = Staging(folder)
    try:
        with RunProgress(console) as progress, progress.stage("export", len(batch.items), already) as bar:
            _run_writer(writer, fmt, batch, folder, staging, bar)
        staging.write(DESIGN, design_table(folder.items))
        staging.write(MANIFEST, folder.manifest())
        staging.commit()
    except OSError as exc:  # the writes' (the store's blobs are read behind UserErrors)
        staging.discard()
        fix = "free some space or choose another folder" if exc.errno in DISK_FULL else "choose another folder"
        raise UserError(f"--output {folder.root}: cannot write the export ({_reason(exc)}); nothing was written, "
                        f"{fix}") from None
    except BaseException:
        staging.discard()
        raise


def _run_writer(writer: DatasetWriter, fmt: str, batch: Batch, folder: ExportFolder, staging: Staging,
                bar: StageProgress) -> None:
    """``writer.write``; a user's writer that fails (an exception, ``sys.exit``) is one line naming
    it and where in its code, as other plug-ins' failures are; a full disk stays the folder's problem."""
    try:
        writer.write(batch, folder, staging, bar)
    except UserError:
        raise
    except PLUGIN_FAILURES as exc:
        if not is_user_plugin(fmt) or isinstance(exc, OSError) and exc.errno in DISK_FULL:
            raise
        raise plugin_failure(f"export format {fmt!r}", exc, "failed in write()") from None


def _reason(exc: OSError) -> str:
    """An OS error as a few words: its ``strerror`` (``No space left on device``), else its first line."""
    return exc.strerror or (str(exc).splitlines() or [type(exc).__name__])[0]


def _new_items(spec: LoadedSpec, selection: Selection, folder: ExportFolder,
               writer: DatasetWriter) -> tuple[list[Item], int]:
    """The selection's results the folder does not hold yet, with their ids and categories (their
    manifest entries added to ``folder``), and how many it holds already."""
    labels = {o.name: str(o.labels[0]) for o in spec.objects}
    for label in labels.values():  # the experiment's labels are the categories, in spec order
        folder.category(label)
    known, next_id, items = folder.known(), folder.next_id(), []
    for index, row in enumerate(selection.rows):
        entry = {"experiment": row["experiment"], "model": row.get("model"), "job": row["job"],
                 "image_key": row["image_key"]}
        if identity(entry) in known:
            continue
        known.add(identity(entry))
        if row["object"] not in labels:
            raise UserError(f"results name the object {row['object']!r}, which {spec.path} no longer has: run the "
                            "spec again (sweep3d run) to plan its jobs anew, then export")
        label = labels[row["object"]]
        design = {c: _plain(row.get(c)) for c in (*SCENE, *selection.parameters)}
        attributes = {**entry, **design, "label": label, "labels": [str(x) for x in _labels_of(spec, row["object"])],
                      **{c: _plain(row[c]) for c in VERDICT if c in row}}
        item = Item(next_id, index, row, label, folder.category(label), attributes)
        folder.items.append({"id": item.id, **entry, "label": label, "file": writer.file_of(item),
                             "attributes": attributes, "design": design})
        items.append(item)
        next_id += 1
    return items, len(selection.rows) - len(items)


def _labels_of(spec: LoadedSpec, name: str) -> list[Any]:
    return next(o.labels for o in spec.objects if o.name == name)


def _plain(value: Any) -> Any:
    """``value`` as JSON holds it (a parameter or verdict is a number, text or bool already)."""
    if isinstance(value, decimal.Decimal):
        return float(value)
    if isinstance(value, (datetime.date, datetime.time)):
        return value.isoformat()
    return value
