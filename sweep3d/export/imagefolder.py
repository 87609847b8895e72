"""ImageFolder: one folder per class (the object's true label) of PNG files, as torchvision's
``ImageFolder`` and Hugging Face's ``imagefolder`` read them, and ``metadata.csv`` beside them
(``file_name`` and every attribute: Hugging Face adds its columns to each image)."""

from __future__ import annotations

from sweep3d.driver import StageProgress
from sweep3d.export.formats import EXPORT_FORMATS, Batch, DatasetWriter, Item
from sweep3d.export.selection import image_bytes
from sweep3d.export.target import ExportFolder, Staging, class_folder, csv_bytes

METADATA = "metadata.csv"


@EXPORT_FORMATS.register("imagefolder")
class ImageFolderWriter(DatasetWriter):
    """``<label>/<id>.png`` and ``metadata.csv``."""

    def file_of(self, item: Item) -> str:
        return f"{class_folder(item.label)}/{item.stem}"

    def write(self, batch: Batch, folder: ExportFolder, staging: Staging, progress: StageProgress) -> None:
        for item in batch.items:
            data = image_bytes(batch.store, item.row)
            staging.place(self.file_of(item), data, batch.store.blob_path(item.row["image_key"]), batch.link)
            progress.advance()
        entries = [*folder.items]  # the manifest's, with this batch's already added
        columns = list(dict.fromkeys(c for entry in entries for c in entry["attributes"]))
        rows = ([entry["file"], entry["id"], *(entry["attributes"].get(c) for c in columns)] for entry in entries)
        staging.write(METADATA, csv_bytes(["file_name", "id", *columns], rows))
