"""A follow-up's session: one runner for its several computations on one store, so the render
workers stay warm between plans and each model loads once (``sweep3d grade``'s dozen plans)."""

from __future__ import annotations

from pathlib import Path

from sweep3d.runner import running, session
from sweep3d.stages.infer import ModelHandle
from tests.helpers import SPEC_02, load_spec, write_spec


def test_every_computation_within_a_session_on_its_store_is_its_runner(tmp_path: Path) -> None:
    spec = load_spec(write_spec(tmp_path, SPEC_02))
    (tmp_path / "other").mkdir()
    other = load_spec(write_spec(tmp_path / "other", SPEC_02))  # another store
    with session(spec) as outer:
        with running(spec, leftovers=False) as inner:
            assert inner is outer
        with running(other) as elsewhere:
            assert elsewhere is not outer
        # two plans' handles of one model: one infer stage, one load
        first, second = ModelHandle.resolve(spec), ModelHandle.resolve(spec)
        assert first is not second and outer.infer(first) is outer.infer(second)
    with running(spec) as after:
        assert after is not outer  # the session ended with its block
