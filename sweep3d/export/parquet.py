"""Parquet, as a Hugging Face dataset stores images: ``data/train-<n>.parquet`` with an ``image``
column (a struct of the PNG's ``bytes`` and its ``path``, the layout of ``datasets.Image``, declared
as such in the file's ``huggingface`` metadata), ``id``, ``label`` (the object's true label) and
every column of ``results``. ``datasets.load_dataset(folder)`` reads it; so does any Parquet reader.

An append writes one more file. Every file of an export shares one schema (``datasets`` refuses
files that differ): when the new results have columns the export lacks (another experiment's
controls), the earlier files are written again with those columns, null.
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.core import UserError
from sweep3d.driver import StageProgress
from sweep3d.export.formats import EXPORT_FORMATS, Batch, DatasetWriter
from sweep3d.export.selection import image_bytes
from sweep3d.export.target import ExportFolder, Staging

DATA = "data"
IMAGE_TYPE = pa.struct([("bytes", pa.binary()), ("path", pa.string())])
#: The dataset's features as ``datasets`` reads them from the schema (the rest it infers).
HF_METADATA = {b"huggingface": json.dumps({"info": {"features": {"image": {"_type": "Image"}}}}).encode()}
OWN = ("image", "id", "label")
ROW_GROUP = 100  # rows per row group: images are large, a reader holds one group at a time


@EXPORT_FORMATS.register("parquet")
class ParquetWriter(DatasetWriter):
    """``data/train-00000.parquet``, then ``train-00001.parquet`` for the first append, …"""

    files = False

    def write(self, batch: Batch, folder: ExportFolder, staging: Staging, progress: StageProgress) -> None:
        images, ids, labels = [], [], []
        for item in batch.items:
            images.append({"bytes": image_bytes(batch.store, item.row), "path": item.stem})
            ids.append(item.id)
            labels.append(item.label)
            progress.advance()
        results = batch.table.take(pa.array([item.index for item in batch.items], pa.int64())).select(batch.columns)
        columns = {"image": pa.array(images, IMAGE_TYPE), "id": pa.array(ids, pa.int64()),
                   "label": pa.array(labels, pa.string())}
        for name in results.column_names:  # a column of a user's evaluator named like ours keeps its name prefixed
            columns[f"results_{name}" if name in OWN else name] = results.column(name)
        table = pa.table(columns)
        earlier = sorted((folder.root / DATA).glob("train-*.parquet")) if not folder.fresh else []
        schema = _unified(table.schema, earlier)
        for path in earlier:
            old = pq.read_table(path)
            if old.schema.remove_metadata() != schema:
                _write(_conform(old, schema, path), staging.path(f"{DATA}/{path.name}"))
        _write(_conform(table, schema, None), staging.path(f"{DATA}/train-{len(earlier):05d}.parquet"))


def _unified(schema: pa.Schema, earlier: list[Path]) -> pa.Schema:
    """One schema for the export's files: the earlier files' columns first, then the new ones."""
    try:
        schemas = [pq.read_schema(p).remove_metadata() for p in earlier]
        return pa.unify_schemas([*schemas, schema.remove_metadata()], promote_options="permissive")
    except (OSError, pa.ArrowException) as exc:
        raise UserError(f"--append: the export's Parquet files and these results do not fit one table "
                        f"({str(exc).splitlines()[0]}); export to a new folder instead") from None


def _conform(table: pa.Table, schema: pa.Schema, path: Path | None) -> pa.Table:
    """``table`` with ``schema``'s columns in its order, null where it had none."""
    columns = []
    for field in schema:
        if field.name in table.column_names:
            try:
                columns.append(table.column(field.name).cast(field.type))
            except pa.ArrowException:
                where = f"{path.name}'s" if path else "the new results'"
                raise UserError(f"--append: column {field.name} of {where} cannot be stored as {field.type}; "
                                "export to a new folder instead") from None
        else:
            columns.append(pa.nulls(table.num_rows, field.type))
    return pa.Table.from_arrays(columns, schema=schema)


def _write(table: pa.Table, path: Path) -> None:
    pq.write_table(table.replace_schema_metadata(HF_METADATA), path, row_group_size=ROW_GROUP, compression="zstd")
