"""The documentation site builds with ``mkdocs build --strict``, and its reference is generated:
every registered plug-in is on it, a control registered for the build included, its text escaped."""

from __future__ import annotations

import html
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers.doc_blocks import REPO

if not os.environ.get("CI"):  # CI installs the docs extra (scripts/setup.sh --test): there a missing one fails
    pytest.importorskip("mkdocs", reason="the docs extra: pip install -e '.[docs]'")

DUMMY = '''
from pydantic import Field

from sweep3d.plugins import ControlParams, PostControl


class Smudge(PostControl):
    """Smudges <b>the</b> image | a test's control: `amount` 0 .. 1, *never* markup."""

    class Params(ControlParams):
        amount: float = Field(0.25, ge=0.0, le=1.0, description="How much, <i>not</i> bold.")
        passes_through: bool = False

    def apply(self, image, params, rng):
        return image
'''


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> tuple[subprocess.CompletedProcess, Path]:
    """The site, built once with --strict into a temporary folder, with ``dummydocs:Smudge``
    registered through SWEEP3D_DOCS_PLUGINS."""
    folder = tmp_path_factory.mktemp("docs")
    (folder / "dummydocs.py").write_text(DUMMY)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(folder)]),
           "SWEEP3D_DOCS_PLUGINS": "dummydocs:Smudge", "NO_MKDOCS_2_WARNING": "1"}
    built = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(folder / "site")],
                           cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    return built, folder / "site"


def page(site: Path, path: str) -> str:
    return (site / path / "index.html").read_text()


def visible(markup: str) -> str:
    """A page's text as a reader sees it (tags dropped, entities read)."""
    return html.unescape(re.sub(r"<[^>]+>", "", markup))


@pytest.mark.slow
def test_the_site_builds_strict_with_every_page_of_the_nav(site) -> None:
    built, folder = site
    assert built.returncode == 0, built.stdout + built.stderr
    assert "WARNING" not in built.stderr, built.stderr
    nav = re.findall(r":\s*([\w/-]+)\.md\s*$", (REPO / "mkdocs.yml").read_text(), re.M)
    nav += re.findall(r"^\s*-\s*([\w/-]+)\.md\s*$", (REPO / "mkdocs.yml").read_text(), re.M)
    assert len(nav) > 40
    for path in nav:
        target = folder / ("" if path == "index" else path.removesuffix("/index")) / "index.html"
        assert target.is_file(), path


@pytest.mark.slow
def test_the_reference_lists_every_registered_plugin(site) -> None:
    sys.path.insert(0, str(REPO / "scripts"))
    try:
        from docs_reference import sources
    finally:
        sys.path.remove(str(REPO / "scripts"))
    found = sources()
    _, folder = site
    pages = {"reference/controls": [*found.rendered, *found.post], "reference/policies": found.policies,
             "reference/evaluators": found.evaluators, "reference/models": found.models}
    for path, names in pages.items():
        text = visible(page(folder, path))
        assert names and all(name in text for name in names), path
    controls = visible(page(folder, "reference/controls"))
    assert "blur" in controls and "orientation" in controls and "sigma" in controls
    spec = visible(page(folder, "reference/spec"))
    assert "max_jobs" in spec and "samples_per_dim" not in spec  # the spec's keys; a policy's are on its page
    cli = visible(page(folder, "reference/cli"))
    assert all(f"sweep3d {command}" in cli for command in ("plan", "run", "query", "export", "cache verify"))
    api = page(folder, "reference/python-api")
    assert all(f'id="sweep3d.{name}"' in api for name in ("load", "Experiment.dataframe", "plugins.RenderedControl"))


@pytest.mark.slow
def test_a_control_registered_for_the_build_is_on_the_reference_as_text(site) -> None:
    _, folder = site
    markup = page(folder, "reference/controls")
    text = visible(markup)
    assert "dummydocs:Smudge" in text
    section = text[text.index("dummydocs:Smudge"):]
    assert "Smudges <b>the</b> image | a test's control" in section  # its docstring, as written
    assert "<b>the</b>" not in markup and "<i>not</i>" not in markup  # escaped, never markup
    mine = markup[markup.index("dummydocs:Smudge"):]
    row = " ".join(visible(next(r for r in re.findall(r"<tr>.*?</tr>", mine, re.S) if "amount" in r)).split())
    assert "0.25" in row and "0 ≤ x ≤ 1" in row and "How much, <i>not</i> bold." in row
    assert "passes_through" in section
