"""``sweep3d explain``: the nearest change that fixes each failure (see :mod:`.search`, the pure
search, :mod:`.further`, which goes past a fragile fix, :mod:`.run`, which answers their probes
through the stages, and :mod:`.sentence`, the words a user reads of each fix)."""

from __future__ import annotations

__all__ = ["ExplainResult", "change_words", "explain_spec", "fix_sentence", "print_explained", "resolution_words",
           "share_words", "trust_words"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles; from outside the package, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.followups.explain.run import ExplainResult, explain_spec, print_explained
    from sweep3d.followups.explain.sentence import (
        change_words,
        fix_sentence,
        resolution_words,
        share_words,
        trust_words,
    )

__getattr__, __dir__ = _exports(__name__, {
    "ExplainResult": ("sweep3d.followups.explain.run", "ExplainResult"),
    "explain_spec": ("sweep3d.followups.explain.run", "explain_spec"),
    "print_explained": ("sweep3d.followups.explain.run", "print_explained"),
    "change_words": ("sweep3d.followups.explain.sentence", "change_words"),
    "fix_sentence": ("sweep3d.followups.explain.sentence", "fix_sentence"),
    "resolution_words": ("sweep3d.followups.explain.sentence", "resolution_words"),
    "share_words": ("sweep3d.followups.explain.sentence", "share_words"),
    "trust_words": ("sweep3d.followups.explain.sentence", "trust_words"),
})
