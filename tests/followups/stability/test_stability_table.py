"""The stability check's table is declared once, by its package: the rows it writes and the
columns the store holds an old segment to are one list."""

from __future__ import annotations

from sweep3d.cache import contract_of
from sweep3d.followups.stability.check import SCHEMA as WRITTEN
from sweep3d.followups.stability.stored import ADDED_SINCE, SCHEMA


def test_the_check_writes_the_rows_its_contract_declares() -> None:
    contract = contract_of("stability")
    assert WRITTEN is SCHEMA  # one schema, not a copy
    assert contract.key == "stability_key" and contract.merge == "first"  # a key names its inputs
    assert set(contract.columns) == set(SCHEMA.names) - set(ADDED_SINCE)
    assert set(ADDED_SINCE) <= set(SCHEMA.names)
