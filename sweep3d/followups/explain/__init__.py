"""``sweep3d explain``: the nearest change that fixes each failure (see :mod:`.search`, the pure
search, :mod:`.further`, which goes past a fragile fix, :mod:`.run`, which answers their probes
through the stages, :mod:`.sentence`, the words a user reads of each fix, and :mod:`.stored`,
the ``counterfactuals`` table it keeps them in)."""

from __future__ import annotations

# Lazy exports (PEP 562): the block under TYPE_CHECKING is this package's one listing (its names, their
# modules, __all__); a name's module is imported when first used. From outside, import through here.
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
    from sweep3d.followups.explain.stored import counterfactual_key, write_counterfactuals

__getattr__, __dir__ = _exports(__name__)  # names, modules and __all__ from the block above
