"""Key lookups by sorting (sweep3d.cache.key_join) answer as Arrow's hash lookup does."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.cache.key_join import ABSENT, positions, sorted_keys
from tests.helpers import examples

HEX = st.text(alphabet="0123456789abcdef", min_size=4, max_size=4)  # one width: the sorted path
ANY = st.text(alphabet="ab\x00é", max_size=3)  # mixed widths, NUL bytes, non-ASCII: the fallback


def _index_in(query: list[str], values: list[str]) -> list[int]:
    found = pc.index_in(pa.array(query, pa.string()), value_set=pa.array(values, pa.string()))
    return pc.fill_null(found, ABSENT).to_pylist()


@settings(max_examples=examples(100), deadline=None)
@given(st.lists(HEX | ANY, max_size=12), st.lists(HEX | ANY, max_size=12), st.booleans())
def test_positions_match_a_hash_lookup(query: list[str], values: list[str], sort_values: bool) -> None:
    if sort_values:
        values = sorted(values, key=lambda v: v.encode())
    got = positions(pa.array(query, pa.string()), pa.array(values, pa.string()))
    assert got.tolist() == _index_in(query, values)


@settings(max_examples=examples(60), deadline=None)
@given(st.lists(HEX, max_size=20), st.lists(HEX, max_size=20))
def test_same_width_keys_join_through_the_sorted_path(query: list[str], values: list[str]) -> None:
    values = values + query[: len(query) // 2]  # some found, some repeated, some absent
    chunked = pa.chunked_array([pa.array(values[:3], pa.string()), pa.array(values[3:], pa.string())])
    assert positions(pa.array(query, pa.large_string()), chunked).tolist() == _index_in(query, values)


@settings(max_examples=examples(60), deadline=None)
@given(st.lists(HEX | ANY, max_size=15))
def test_sorted_keys_orders_bytes_and_keeps_repeats(keys: list[str]) -> None:
    out = sorted_keys(keys)
    assert out.to_pylist() == sorted(keys, key=lambda k: k.encode())
    assert sorted_keys(out).equals(out)


def test_the_same_keys_in_the_same_order_are_found_in_place() -> None:
    keys = sorted_keys([f"{i:040x}" for i in np.random.default_rng(0).integers(0, 2**62, 1000)])
    assert (positions(keys, keys.take(pa.array(range(len(keys))))) == np.arange(len(keys))).all()
    assert positions(keys, pa.array([], pa.string())).tolist() == [ABSENT] * len(keys)
