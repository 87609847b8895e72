"""What the stability check keeps in the store: its table, declared once, here.

Each (image, model, change) is one row under its ``stability_key``; a key names its inputs, so
its rows are alike and the first written counts. The store knows the table only by this
contract (the package root names this module, so every command sees the table).
"""

from __future__ import annotations

import pyarrow as pa

from sweep3d.cache import TableContract, register_table

#: One row of the check: an image's verdict before and after one change.
SCHEMA = pa.schema([("stability_key", pa.string()), ("pred_key", pa.string()), ("image_key", pa.string()),
                    ("change", pa.string()), ("seed", pa.int64()),
                    ("base_correct", pa.bool_()), ("base_margin", pa.float64()), ("correct", pa.bool_()),
                    ("margin", pa.float64()), ("flipped", pa.bool_()), ("created_at", pa.timestamp("us", tz="UTC")),
                    ("neighbour_key", pa.string())])
#: Columns added after the table was first written: older segments rightly lack them. ``neighbour_key``:
#: a scene neighbour's prediction key (its row compares that prediction with ``pred_key``'s); null
#: for an image change.
ADDED_SINCE = ("seed", "neighbour_key")

STABILITY = register_table(TableContract(
    "stability", key="stability_key", columns=tuple(n for n in SCHEMA.names if n not in ADDED_SINCE)))
