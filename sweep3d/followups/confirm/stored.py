"""What ``sweep3d confirm`` keeps in the store: the ``confirmations`` table, declared once, here.

One row per (experiment, claim): a finding's verdict on fresh renders, its counts and interval
(the fields of :class:`sweep3d.results.Verdict`), the renders and seed its twins were drawn with
and the fresh jobs' experiment. Its key is what the row is of (:func:`confirmation_key`), so a
later confirmation writes a newer row of each claim it tests, which counts ("newest"), and the
claims it does not test keep theirs. The store knows the table only by this contract (the
package root names this module, so every command sees the table: ``query``, ``cache verify``,
``compact`` and ``stats``).
"""

from __future__ import annotations

import hashlib
import json

import pyarrow as pa

from sweep3d.cache import TableContract, register_table

CONFIRMATIONS = "confirmations"

#: A verdict's fields (:class:`sweep3d.results.Verdict`), each a column of its own.
VERDICT_FIELDS = pa.schema([
    ("status", pa.string()), ("pairs", pa.int64()), ("both_right", pa.int64()), ("inside_wrong", pa.int64()),
    ("inside_right", pa.int64()), ("both_wrong", pa.int64()), ("accuracy_inside", pa.float64()),
    ("accuracy_outside", pa.float64()), ("difference", pa.float64()), ("difference_low", pa.float64()),
    ("difference_high", pa.float64()), ("p_value", pa.float64()), ("p_holm", pa.float64()),
    ("findings", pa.int64()), ("look", pa.int64()), ("looks", pa.int64()), ("futility", pa.float64()),
    ("in_family", pa.bool_()),  # null in rows from before Holm's family left findings out
])
#: One claim's confirmation: ``experiment`` is the discovery run's (whose finding it tests),
#: ``fresh_experiment`` the twins' (``<experiment>-confirm``).
SCHEMA = pa.schema([
    ("confirmation_key", pa.string()), ("experiment", pa.string()), ("claim", pa.string()), ("text", pa.string()),
    *VERDICT_FIELDS, ("renders", pa.int64()), ("seed", pa.int64()), ("drawn", pa.int64()),
    ("fresh_experiment", pa.string()), ("created_at", pa.timestamp("us", tz="UTC")),
])


def confirmation_key(experiment: str, claim: str) -> str:
    """The table's key: the claim (:mod:`sweep3d.followups.confirm.claims`) of one experiment."""
    return hashlib.sha256(json.dumps([experiment, claim]).encode()).hexdigest()


CONFIRMATIONS_TABLE = register_table(TableContract(CONFIRMATIONS, key="confirmation_key", columns=tuple(SCHEMA.names),
                                                  merge="newest"))
