"""Measures of each result that the views level like parameters (binned axes of
``control_accuracy`` and the report's explorer): the object's visible fraction, the classifier's
margin (the best true class's probability less the best other's) and the IoU. They are outcomes, not causes: never a
failure mode, a pair of levels, a sensitivity, a boundary or a rule."""

MEASURES = ("visible_fraction", "margin", "iou")
#: A SQL condition on a ``parameter`` column leaving the measures out.
NOT_A_MEASURE = f"parameter NOT IN ({', '.join(repr(m) for m in MEASURES)})"
