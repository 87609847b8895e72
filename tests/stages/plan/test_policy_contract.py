"""A user's policy that breaks its contract is one line naming the policy, exit code 2, and leaves
the store as it was: raising, returning a string or tuples instead of Points, a NaN coordinate, a
point outside the unit cube, a choice index past its list, a count that is not a number."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from tests.helpers import TINY_SPEC, write_spec

POLICIES = textwrap.dedent('''
    import math
    from sweep3d.plugins import Point, Policy

    class Raises(Policy):
        def points(self, shape, seed, history):
            return 1 / 0

    class Text(Policy):
        def points(self, shape, seed, history):
            return "0.5"

    class Tuples(Policy):  # what the README once said: unit-cube points as tuples
        def points(self, shape, seed, history):
            return [(0.5,) * shape.n_continuous]

    class NotANumber(Policy):
        def points(self, shape, seed, history):
            return [Point((math.nan,), (0,))]

    class Outside(Policy):
        def points(self, shape, seed, history):
            return [Point((1.5,), (0,))]

    class Choice99(Policy):
        def points(self, shape, seed, history):
            return [Point((0.5,), (99,))]

    class ShortUnit(Policy):
        def points(self, shape, seed, history):
            return [Point((), (0,))]

    class BadCount(Policy):
        def points(self, shape, seed, history):
            return [Point((0.5,), (0,))]

        def count(self, shape):
            return "many"

    class Good(Policy):
        def points(self, shape, seed, history):
            return [Point((u,), (c,)) for u in (0.0, 0.25, 1.0) for c in range(shape.choice_sizes[0])]

        def count(self, shape):
            return 3 * shape.choice_sizes[0]
''')

#: A space of one range (orientation.yaw) and one list of two options (blur.sigma).
SPEC = TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [0, 90] }")

CASES = {
    "Raises": "raised: ZeroDivisionError: division by zero",
    "Text": "its points are a str ('0.5'), not a list of points",
    "Tuples": "its point 0 is a tuple ((0.5,)), not a Point",
    "NotANumber": "its point 0 has unit coordinate nan for orientation_yaw",
    "Outside": "its point 0 has unit coordinate 1.5 for orientation_yaw",
    "Choice99": "its point 0 has choice index 99 for blur_sigma, which has 2 options",
    "ShortUnit": "its point 0 has 0 values as unit where this scene's space needs 1",
    "BadCount": "count(shape) returned 'many'",
}
CONTRACT = ("return a list of Point(unit, choice) (from sweep3d.plugins) with unit a tuple of 1 float in [0, 1] "
            "and choice a tuple of 1 option index (0..1)")


@pytest.fixture
def folder(tmp_path: Path, monkeypatch) -> Path:
    (tmp_path / "contract_policies.py").write_text(POLICIES)
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def spec_for(folder: Path, policy: str) -> Path:
    return write_spec(folder, SPEC.replace('type = "grid"', f'type = "contract_policies:{policy}"'))


def files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if "__pycache__" not in p.parts)


@pytest.mark.parametrize("policy", list(CASES))
def test_a_broken_policy_is_one_line_naming_it_and_exit_2(folder: Path, policy: str) -> None:
    spec = spec_for(folder, policy)
    before = files(folder)
    result = CliRunner().invoke(app, ["plan", str(spec)])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    line = " ".join(result.output.split())  # the console folds long lines
    where = " (contract_policies.py:7) " if policy == "Raises" else ": "  # a raise is located in the user's file
    assert line.startswith(f"error: policy contract_policies:{policy}{where}{CASES[policy]}"), line
    if policy not in ("Raises", "BadCount"):
        assert CONTRACT in line, line
    assert files(folder) == before  # nothing written, nothing lost


def test_a_policy_keeping_the_contract_plans(folder: Path) -> None:
    result = CliRunner().invoke(app, ["plan", str(spec_for(folder, "Good"))])
    assert result.exit_code == 0, result.output
    assert "12 jobs over 2 scenes" in result.output  # 3 points × 2 sigmas × 2 environments


def test_a_policy_overriding_arrays_is_checked_too() -> None:
    import numpy as np

    from sweep3d.core.errors import PluginError
    from sweep3d.spec import ControlInstance, Range
    from sweep3d.spec.space import SearchSpace
    from sweep3d.stages.plan.checked import policy_arrays
    from sweep3d.stages.plan.policies import Policy, PolicyParams
    from sweep3d.stages.render.controls import Orientation

    class Wide(Policy):
        def arrays(self, shape, seed, history):
            return np.full((2, shape.n_continuous + 1), 0.5), np.zeros((2, 0), np.int64)

    space = SearchSpace([ControlInstance(Orientation("o", "orientation"), {"yaw": Range(0.0, 90.0)})])
    with pytest.raises(PluginError, match=r"policy wide: arrays\(shape, seed, history\) returned unit of shape "
                                          r"\(2, 2\) and choice of shape \(2, 0\); this scene needs \(2, 1\)"):
        policy_arrays(Wide(PolicyParams()), "wide", space, 0, {})
