"""How deeply a spec's values may nest (issue 45, item 4): :data:`MAX_NESTING` levels of arrays and
tables inside one another load; one more is one line naming the key, and nesting too deep for
tomllib's recursion is one line too, not a RecursionError."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sweep3d.core.errors import SpecError
from sweep3d.spec.loader import MAX_NESTING, parse_toml, too_deep


def nest(depth: int, table: bool) -> str:
    """A TOML value ``depth`` levels deep below the key ``a`` (the key's own table is level 1)."""
    inner = depth - 1
    return "{b = " * inner + "1" + "}" * inner if table else "[" * inner + "1" + "]" * inner


@given(depth=st.integers(1, 3 * MAX_NESTING), table=st.booleans())
def test_values_nested_up_to_the_limit_load_and_deeper_ones_are_named(depth: int, table: bool) -> None:
    text = f"a = {nest(depth, table)}\n"
    if depth <= MAX_NESTING:
        assert too_deep(parse_toml(text, "s.toml")) is None
        return
    with pytest.raises(SpecError) as raised:
        parse_toml(text, "s.toml")
    assert str(raised.value).startswith("s.toml: a" + (".b" if table else "[0]")), str(raised.value)
    assert f"nested more than {MAX_NESTING} levels deep" in str(raised.value)


@pytest.mark.parametrize("opening, closing", [("[", "]"), ("{a = ", "}")])
def test_nesting_too_deep_for_the_toml_reader_is_one_line(opening: str, closing: str) -> None:
    text = f"a = {opening * 5000}{closing * 5000}\n"
    with pytest.raises(SpecError) as raised:
        parse_toml(text, "s.toml")
    assert str(raised.value) == ("s.toml: values nested too deeply to read (arrays or inline tables inside one "
                                 f"another); a spec nests them at most {MAX_NESTING} levels: flatten them")
