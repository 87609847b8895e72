"""The code blocks of the documentation's pages, for the tests that run them.

A page's blocks are read in order. What each is for comes from its fence and the line above it:

- ```` ```toml title="first.toml" ```` (any language, with ``title=``): a file the reader writes;
- ```` ```python ```` without a title: code the reader runs, in one namespace per page;
- ```` ```bash ````: ``sweep3d`` commands, one a line (a trailing ``\\`` continues it);
- ``<!-- skip: why -->`` on the line above a fence: shown, not run (a long run, an illustration);
- ``<!-- test: blender torch slow -->`` anywhere on a page: the pytest markers its run needs.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
#: The furniture meshes tutorials name, where Debian's sweethome3d-furniture installs them.
FURNITURE = "/usr/share/sweethome3d/furniture/"

_FENCE = re.compile(r"^(?P<indent> *)```(?P<lang>[\w-]*)(?P<attrs>[^\n]*)\n(?P<body>.*?)^(?P=indent)```[ \t]*$",
                    re.M | re.S)
_SKIP = re.compile(r"<!--\s*skip\b[^>]*-->\s*$")
_MARKERS = re.compile(r"<!--\s*test:\s*([\w\s]+?)\s*-->")


@dataclass(frozen=True)
class Block:
    """One fenced block of a page: its language, the file it is written to (``title``), its text,
    and whether the page marks it not to run."""

    lang: str
    title: str | None
    code: str
    skip: bool
    line: int

    def commands(self) -> list[list[str]]:
        """A bash block's ``sweep3d`` commands as argument lists (without ``sweep3d``)."""
        joined = re.sub(r"\\\n\s*", " ", self.code)
        out = []
        for line in joined.splitlines():
            words = shlex.split(line, comments=True)
            if words:
                assert words[0] == "sweep3d", f"line {self.line}: a tutorial's bash block runs sweep3d only: {line!r}"
                out.append(words[1:])
        return out


def page_text(page: str | Path) -> str:
    return (DOCS / page).read_text()


def blocks(page: str | Path) -> list[Block]:
    """Every fenced block of a page under docs/, in order."""
    text = page_text(page)
    found = []
    for match in _FENCE.finditer(text):
        before = text[:match.start()].rstrip("\n").rsplit("\n", 1)[-1]
        title = re.search(r'title="([^"]+)"', match["attrs"])
        body = "\n".join(line[len(match["indent"]):] for line in match["body"].splitlines()) + "\n"
        found.append(Block(match["lang"], title[1] if title else None, body, bool(_SKIP.search(before)),
                           text[:match.start()].count("\n") + 1))
    return found


def block(page: str | Path, after: str, lang: str = "python") -> str:
    """The first ``lang`` block of ``page`` after the text ``after`` (a heading, a sentence)."""
    text = page_text(page)
    start = text.index(after)
    offset = text[:start].count("\n") + 1
    return next(b.code for b in blocks(page) if b.line >= offset and b.lang == lang)


def markers(page: str | Path) -> list[str]:
    """The pytest markers a page asks for (``<!-- test: blender torch slow -->``)."""
    found = _MARKERS.search(page_text(page))
    return found[1].split() if found else []


def tutorials() -> list[str]:
    """The tutorial pages, relative to docs/."""
    return sorted(str(p.relative_to(DOCS)) for p in (DOCS / "tutorials").glob("*.md"))


def indented(page: str | Path) -> list[int]:
    """Lines that open an indented code block outside a fence (a tutorial fences every block, so
    that the tests see it)."""
    found, fenced, previous = [], False, ""
    for number, line in enumerate(page_text(page).splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
        elif not fenced and line.startswith("    ") and line.strip() and not previous.strip():
            found.append(number)
        previous = line
    return found
