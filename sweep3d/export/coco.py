"""COCO instances: ``images/`` and ``annotations.json``, one annotation per image where its object
shows, with the box and the mask from the mask pass (compressed RLE, pycocotools' encoding).

What COCO readers trip on, ruled out here: ``area`` is one number (the mask's pixel count),
``width`` and ``height`` are read from the image itself, an image whose object shows no pixel
gets no annotation (never a zero-area one), category ids start at 1 (0 is background to many
trainers), and an append continues image and annotation ids after the largest there.
"""

from __future__ import annotations

import io
import json
from typing import Any

import numpy as np

from sweep3d.core import UserError, box
from sweep3d.driver import StageProgress
from sweep3d.export.formats import EXPORT_FORMATS, Batch, DatasetWriter, Item
from sweep3d.export.selection import image_bytes, mask_of
from sweep3d.export.target import ExportFolder, Staging, json_bytes

ANNOTATIONS = "annotations.json"
IMAGES = "images"


@EXPORT_FORMATS.register("coco")
class CocoWriter(DatasetWriter):
    """``images/<id>.png`` and ``annotations.json`` (``file_name`` relative to ``images/``)."""

    needs_mask = True

    def file_of(self, item: Item) -> str:
        return f"{IMAGES}/{item.stem}"

    def write(self, batch: Batch, folder: ExportFolder, staging: Staging, progress: StageProgress) -> None:
        document = _existing(folder)
        if batch.items:  # images the manifest does not list: left by an append killed while it committed
            orphans = {i["id"] for i in document["images"] if i["id"] >= batch.items[0].id}
            document["images"] = [i for i in document["images"] if i["id"] not in orphans]
            document["annotations"] = [a for a in document["annotations"] if a["image_id"] not in orphans]
        next_annotation = max((a["id"] for a in document["annotations"]), default=0) + 1
        for item in batch.items:
            data = image_bytes(batch.store, item.row)
            staging.place(self.file_of(item), data, batch.store.blob_path(item.row["image_key"]), batch.link)
            width, height = _size(data)
            document["images"].append({"id": item.id, "file_name": item.stem, "width": width, "height": height,
                                       "attributes": item.attributes})
            mask = mask_of(batch.store, item.row)
            if mask.shape != (height, width):
                raise UserError(f"job {item.row['job']}: its mask is {mask.shape[1]}×{mask.shape[0]} but its image "
                                f"{width}×{height}; run `sweep3d run` on the spec again to render its passes anew")
            annotation = annotation_of(mask, item)
            if annotation is not None:
                document["annotations"].append({"id": next_annotation, **annotation})
                next_annotation += 1
            progress.advance()
        document["categories"] = [{"id": i, "name": name, "supercategory": "object"}
                                   for name, i in folder.categories.items()]
        staging.write(ANNOTATIONS, json_bytes(document))


def annotation_of(mask: np.ndarray, item: Item) -> dict[str, Any] | None:
    """The annotation of ``item``'s object from its visible ``mask`` (None when nothing shows)."""
    from pycocotools import mask as rle_codec

    found = box(mask)
    if found is None:
        return None
    x0, y0, x1, y1 = found
    rle = rle_codec.encode(np.asfortranarray(mask.astype(np.uint8)))
    annotation = {"image_id": item.id, "category_id": item.category, "bbox": [x0, y0, x1 - x0, y1 - y0],
                  "area": int(rle_codec.area(rle)), "iscrowd": 0,
                  "segmentation": {"size": [int(s) for s in rle["size"]], "counts": rle["counts"].decode("ascii")},
                  "attributes": item.attributes}
    if item.attributes.get("evaluable") is False:  # kept with --unevaluable flag: trainers may skip it
        annotation["ignore"] = 1
    return annotation


def _existing(folder: ExportFolder) -> dict[str, Any]:
    """The annotations an append adds to (fresh: none)."""
    empty: dict[str, Any] = {"info": {"description": "sweep3d export", "version": "1"}, "licenses": [],
                             "images": [], "annotations": [], "categories": []}
    if folder.fresh:
        return empty
    path = folder.root / ANNOTATIONS
    try:
        document = json.loads(path.read_text())
        if not isinstance(document.get("images"), list) or not isinstance(document.get("annotations"), list):
            raise ValueError
    except (OSError, ValueError, AttributeError):
        raise UserError(f"--append {folder.root}: {path.name} is missing or not COCO annotations; "
                        "export to a new folder instead") from None
    return {**empty, **document}


def _size(data: bytes) -> tuple[int, int]:
    """(width, height) of PNG ``data``, as PIL reads them."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as image:
        return image.size
