"""Column names of the jobs and results tables: built in one place, reserved in one place.

Every control parameter becomes a column ``<control id>_<param>`` of the experiment's jobs table
(and so of ``results``). The list of those columns is stored with the jobs (Parquet metadata under
:data:`PARAMETERS_METADATA`), so readers never guess parameters from what a column is not.
"""

from __future__ import annotations

#: The jobs table's own columns, besides the control parameters.
JOB_COLUMNS = ("experiment", "job", "object", "environment", "render_key", "image_key", "pred_key",
               "parts_key", "in_frame", "model")
#: Columns the ground-truth passes add to ``results`` (see ``sweep3d.core.truth``), reserved even when off.
TRUTH_RESULT_COLUMNS = ("truth_key", "gt_x0", "gt_y0", "gt_x1", "gt_y1", "visible_pixels", "silhouette_pixels",
                        "visible_fraction", "evaluable")
#: Bookkeeping columns every prediction row has, besides its evaluator's columns.
PREDICTION_COLUMNS = ("pred_key", "image_key", "model", "model_digest", "seconds", "created_at")
#: Parquet metadata key of a jobs file holding its parameter columns (a JSON list, in spec order).
PARAMETERS_METADATA = b"sweep3d.parameters"
#: Parquet metadata key of a jobs file holding the models its rows name (a JSON list, in spec order).
MODELS_METADATA = b"sweep3d.models"
#: Parquet metadata key of a jobs file planned with truth passes: ``[evaluator] min_visible``.
MIN_VISIBLE_METADATA = b"sweep3d.min_visible"
#: Parquet metadata key of a jobs file whose spec sets ``[aggregate] drop_fragile`` (b"true"; absent otherwise).
DROP_FRAGILE_METADATA = b"sweep3d.drop_fragile"
#: Its value when no gate applies (the truth passes were asked for by a control, not the evaluation).
MIN_VISIBLE_OFF = b"off"
#: Parquet metadata key of a jobs file holding, per model, the classes the spec names otherwise than
#: the model does (a JSON object: model → list of [class id, the model's name, the spec's name,
#: whether another class of the model has the same name]); see ``spec.class_names``.
CLASS_NAMES_METADATA = b"sweep3d.class_names"
#: Parquet metadata key of a jobs file holding, per model, what the model sees (a JSON object: model →
#: ``Framing.protocol``'s line), for the report.
PROTOCOL_METADATA = b"sweep3d.protocol"
#: ``results`` shows class names as the spec wrote them; beside each such column, the model's own
#: names, under these names.
MODEL_NAME_COLUMNS = {"top1_label": "top1_model_label", "topk_labels": "topk_model_labels"}


def parameter_column(control_id: str, param: str) -> str:
    """The column of one control parameter in the jobs and results tables."""
    return f"{control_id}_{param}"
