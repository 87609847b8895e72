"""Every code block of the tutorials runs as written (tests/helpers/doc_blocks.py says how a page marks them).

Each tutorial runs in a folder of its own: titled blocks are written there as files, Python blocks
run there in one namespace, and bash blocks' ``sweep3d`` commands run in-process and must exit 0.
Tutorials name Sweet Home 3D's furniture; where Debian's package is missing, a cube stands in.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from tests.helpers import write_cube
from tests.helpers.doc_blocks import FURNITURE, Block, blocks, markers, tutorials

#: Blocks that show something and run nothing: a command's output, a file's layout.
SHOWN = {"text", "console", "csv", ""}


def _with_meshes(code: str, folder: Path) -> str:
    """``code`` with each furniture mesh replaced by a cube where the furniture is not installed."""
    def replace(match: re.Match) -> str:
        path = match[0]
        return path if Path(path.partition("#")[0]).exists() else str(write_cube(folder))

    return re.sub(re.escape(FURNITURE) + r'[^"\s]+', replace, code)


def run_block(block: Block, folder: Path, scope: dict, page: str) -> None:
    from typer.testing import CliRunner

    from sweep3d.cli import app

    if block.title is not None:
        (folder / block.title).parent.mkdir(parents=True, exist_ok=True)
        (folder / block.title).write_text(_with_meshes(block.code, folder))
    elif block.lang == "python":
        exec(compile(_with_meshes(block.code, folder), f"{page}:{block.line}", "exec"), scope)
    elif block.lang == "bash":
        for args in block.commands():
            result = CliRunner().invoke(app, args)
            assert result.exit_code == 0, f"{page}:{block.line}: sweep3d {' '.join(args)}\n{result.output}"
    else:
        assert block.lang in SHOWN, f"{page}:{block.line}: a {block.lang} block with no title= runs nothing: " \
                                    "give it a title (a file to write) or mark it <!-- skip: why -->"


@pytest.mark.parametrize("page", [pytest.param(p, marks=[getattr(pytest.mark, m) for m in markers(p)])
                                  for p in tutorials()])
def test_every_block_of_the_tutorial_runs(page: str, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    before = set(sys.modules)
    scope: dict = {"__name__": "__tutorial__"}
    ran = 0
    try:
        for block in blocks(page):
            if not block.skip:
                run_block(block, tmp_path, scope, page)
                ran += 1
    finally:  # the page's own modules (mycontrols, ...) must not be found by the next page's
        for name in set(sys.modules) - before:
            if str(getattr(sys.modules[name], "__file__", "") or "").startswith(str(tmp_path)):
                del sys.modules[name]
    assert ran, f"{page} runs no block"


def test_the_tutorials_mark_what_they_need() -> None:
    """A page that runs sweep3d end to end declares Blender and torch (the fast lane would refuse it)."""
    for page in tutorials():
        runs = any(args[:1] == ["run"] or args[:1] == ["export"] for b in blocks(page) if not b.skip
                   and b.lang == "bash" for args in b.commands())
        runs |= any(".run(" in b.code for b in blocks(page) if not b.skip and b.lang == "python")
        assert not runs or {"blender", "torch", "slow"} <= set(markers(page)), page


def test_the_tutorials_fence_every_code_block() -> None:
    """An indented block would be shown and never run: every tutorial block is fenced."""
    from tests.helpers.doc_blocks import indented

    assert {page: indented(page) for page in tutorials() if indented(page)} == {}
