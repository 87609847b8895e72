"""The corpus of bad inputs (tests/helpers/bad_inputs.py) against every command that reads them.

Each bad spec, asset and material against ``plan``, ``run`` and ``realism score``; each bad
photograph against ``realism score``: one ``error:`` line, exit code 2, no traceback, and the
store's files unchanged (their checksums). Nothing waits on a FIFO for more than a second.
Commands run in this process (typer's runner) on a copy of one synthetic run with a realism kit:
no Blender, no model.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from tests.helpers.bad_inputs import FIFO_SECONDS, PHOTOS, SPEC_CASES, BadPhoto, BadSpec, checksums, fifo_watch
from tests.helpers.realism import make_run, stub_kit_tools

COMMANDS = {"plan": ["plan", "SPEC"], "run": ["run", "SPEC", "--no-report"],
            "realism score": ["realism", "score", "SPEC", "PHOTOS"]}
#: What ``realism score`` says before it checks the photographs (issue 45, item 10 asks that it go;
#: until then it is the one line allowed beside the error).
FRAMING_NOTE = "photographs are read upright"


@pytest.fixture(scope="module")
def kit_run(tmp_path_factory) -> Path:
    """A folder holding a finished synthetic run (spec.toml, store/) and its realism kit (kit/)."""
    folder = tmp_path_factory.mktemp("corpus")
    spec = make_run(folder)
    with pytest.MonkeyPatch.context() as monkeypatch:
        stub_kit_tools(monkeypatch)
        result = CliRunner().invoke(app, ["realism", "pick", str(spec), "-o", str(folder / "kit")])
    assert result.exit_code == 0, result.output
    return folder


@pytest.fixture
def folder(kit_run: Path, tmp_path: Path) -> Path:
    """A private copy of :func:`kit_run` with the kit's renders as the photographs (photos/)."""
    copy = Path(shutil.copytree(kit_run, tmp_path / "run"))
    shutil.copytree(copy / "kit" / "renders", copy / "photos")
    return copy


def refused(folder: Path, args: list[str]) -> str:
    """``sweep3d ARGS`` in this process: asserts one ``error:`` line (beside the framing note), exit
    code 2, no traceback, the store's files unchanged and no FIFO waited on; returns the line."""
    before = checksums(folder / "store")
    started = time.monotonic()
    with fifo_watch(folder) as waited:
        result = CliRunner().invoke(app, args)
    seconds = time.monotonic() - started
    output = result.output
    assert not waited, f"waited on {waited} for over {FIFO_SECONDS:g} s ({seconds:.1f} s): {output}"
    assert result.exit_code == 2, output
    assert "Traceback" not in output and not isinstance(result.exception, (AssertionError, RecursionError)), output
    lines = [line for line in output.splitlines() if line.strip() and not line.startswith(FRAMING_NOTE)]
    assert len(lines) == 1 and lines[0].startswith("error: "), output
    assert checksums(folder / "store") == before, "the store changed"
    return lines[0]


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("case", SPEC_CASES, ids=[c.id for c in SPEC_CASES])
def test_a_bad_spec_or_asset_is_one_line_exit_2_and_leaves_the_store_as_it_was(folder: Path, case: BadSpec,
                                                                               command: str) -> None:
    spec = case.write(folder)
    args = [str(spec) if a == "SPEC" else str(folder / "photos") if a == "PHOTOS" else a for a in COMMANDS[command]]
    line = refused(folder, args)
    assert str(spec) in line, line
    for text in case.expect:
        assert text in line, f"{text!r} not in {line!r}"


@pytest.mark.parametrize("case", PHOTOS, ids=[c.id for c in PHOTOS])
def test_a_bad_photograph_is_one_line_exit_2_and_stores_nothing(folder: Path, case: BadPhoto) -> None:
    job = json.loads((folder / "kit" / "kit.json").read_text())["jobs"][0]
    (folder / "photos" / f"{job}.png").unlink()
    photo = folder / "photos" / f"{job}.png"
    case.make(photo)
    line = refused(folder, ["realism", "score", str(folder / "spec.toml"), str(folder / "photos"),
                            "--kit", str(folder / "kit")])
    assert line.startswith(f"error: {photo}: "), line
    for text in case.expect:
        assert text in line, f"{text!r} not in {line!r}"
    assert not (folder / "store" / "realism").exists() and not (folder / "store" / "tables" / "verdicts").exists()


def test_the_renders_as_photographs_pass_the_checks_the_corpus_fails(folder: Path, monkeypatch) -> None:
    """The corpus's photographs fail for what they are: the same folder with the kit's own renders
    (exactly their size, the smallest allowed) passes every check, to the framed photographs."""
    import sweep3d.followups.realism.score as score
    from sweep3d.core import UserError

    def reached(spec, frames):
        raise UserError(f"reached with {len(frames)} framed photographs")

    monkeypatch.setattr(score, "post_processed", reached)
    jobs = json.loads((folder / "kit" / "kit.json").read_text())["jobs"]
    line = refused(folder, ["realism", "score", str(folder / "spec.toml"), str(folder / "photos"),
                            "--kit", str(folder / "kit")])
    assert line == f"error: reached with {len(jobs)} framed photographs", line
