"""What ``sweep3d plan --materials`` prints (:mod:`sweep3d.cli.materials`), from rows made here (no
Blender): each value exactly as Blender holds it, in the fewest digits that give it back, and
never cut, whatever the terminal's width."""

from __future__ import annotations

import io
from types import SimpleNamespace

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from rich.console import Console

from sweep3d.cli.materials import exact, print_materials
from sweep3d.stages.render import COLUMNS


@given(st.floats(allow_nan=False, allow_infinity=False, width=32))
def test_a_value_prints_as_the_float32_it_is(value: float) -> None:
    assert np.float32(exact(value)) == np.float32(value)  # copied into a spec, it renders the same
    assert "e" not in exact(value)


def test_the_table_prints_every_value_whole_and_exact() -> None:
    ior, coat = float(np.float32(1.4500000476837158)), float(np.float32(0.12345678901))
    row = {"part": "bottle", "material": "glass_with_a_long_name", "base_color": [0.8, 0.123456789, 0.05, 1.0],
           "opacity": 0.3, "roughness": 0.25, "metallic": 0.0, "transmission": 0.9, "ior": ior, "coat": coat,
           "overridden": {"roughness"}}
    assert set(COLUMNS) <= set(row)
    spec = SimpleNamespace(objects=[SimpleNamespace(name="bottle", mesh="bottle.obj")])
    wide, narrow = io.StringIO(), io.StringIO()
    print_materials(Console(file=wide, width=300), spec, [[row]])  # type: ignore[arg-type]
    print_materials(Console(file=narrow, width=60), spec, [[row]])  # type: ignore[arg-type]
    cells = [c.strip() for line in wide.getvalue().splitlines() if line.count("│") > 8 for c in line.split("│")[1:-1]]
    assert cells == ["bottle", "glass_with_a_long_name", "(0.8, 0.12345679, 0.05, 1)", "0.3", "0.25*", "0", "0.9",
                     "1.45", "0.12345679"]
    assert "…" not in narrow.getvalue()
    body = [line.split("│")[1:-1] for line in narrow.getvalue().splitlines() if line.count("│") == len(cells) + 1]
    assert len(body) > 1  # 60 columns: the values wrap onto several lines of the row ...
    assert ["".join(line[j].strip() for line in body) for j in range(len(cells))] == [c.replace(" ", "")
                                                                                      for c in cells]  # ... whole
