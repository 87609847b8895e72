"""A dict spec's TOML text: read back as the dict it came from, laid out as tomlkit laid it out
(so a spec's recorded text and identity are unchanged), and written in linear time."""

from __future__ import annotations

import math
import time
import tomllib
from typing import Any

import pytest
import tomlkit
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.spec.toml_text import toml_text
from tests.helpers import REPO, TINY_SPEC

SCALARS = st.one_of(st.booleans(), st.integers(), st.floats(), st.text(max_size=6))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                       st.dictionaries(st.text(max_size=4), inner, max_size=3)),
                      max_leaves=12)


def same(value: Any) -> Any:
    """``value`` comparable by ==: NaN as a marker, every scalar with its type (1 is not 1.0 nor True)."""
    if isinstance(value, float) and math.isnan(value):
        return "NaN"
    if isinstance(value, dict):
        return {k: same(v) for k, v in value.items()}
    if isinstance(value, list):
        return [same(v) for v in value]
    return type(value).__name__, value


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(st.text(max_size=4), VALUES, max_size=4))
def test_the_text_reads_back_as_the_dict(doc: dict) -> None:
    assert same(tomllib.loads(toml_text(doc))) == same(doc)


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(st.text(alphabet="ab_-1", min_size=1, max_size=3), VALUES, max_size=4))
def test_the_text_is_tomlkits_for_bare_keys(doc: dict) -> None:
    assert toml_text(doc) == tomlkit.dumps(doc)


SPECS = {"tiny": TINY_SPEC, **{p.stem: p.read_text() for p in sorted((REPO / "specs").glob("*.toml"))}}


@pytest.mark.parametrize("text", SPECS.values(), ids=SPECS.keys())
def test_the_repositorys_specs_as_dicts_are_written_as_before(text: str) -> None:
    doc = tomllib.loads(text)
    assert toml_text(doc) == tomlkit.dumps(doc)


def test_a_value_toml_cannot_hold_is_a_type_error() -> None:
    with pytest.raises(TypeError, match="NoneType"):
        toml_text({"render": {"samples": None}})


def test_a_long_list_is_written_in_linear_time() -> None:
    started = time.monotonic()
    text = toml_text({"controls": [{"type": "orientation", "yaw": list(range(200_000))}]})
    assert len(tomllib.loads(text)["controls"][0]["yaw"]) == 200_000
    assert time.monotonic() - started < 20  # tomlkit: minutes (it re-indexes the array on every append)
