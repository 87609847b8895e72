"""Export a run's results (by default its failures) as a dataset: COCO, ImageFolder or Parquet
(Hugging Face's layout), each with ``design.csv``, the configurations that made them.

Usage::

    from sweep3d.export import export_dataset
    from sweep3d.stages import load_spec
    export_dataset(load_spec("spec.toml"), "coco", output="failures")  # failures/annotations.json, images/
"""

from sweep3d.export.dataset import FORMATS, ExportResult, default_output, export_dataset

__all__ = ["FORMATS", "ExportResult", "default_output", "export_dataset"]
