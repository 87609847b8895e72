"""Is a failure real? Agreement of the renders' verdicts with photographs of the same scenes, or
with another renderer's images (``sweep3d realism pick`` / ``score``; the ``agreement`` view)."""

from __future__ import annotations

from sweep3d.followups.realism.photos import photo_like
from sweep3d.followups.realism.pick import margin, near_tie
from sweep3d.followups.realism.pick import pick as pick_kit  # not ``pick``: that name is the module's
from sweep3d.followups.realism.score import score_engine, score_photos

__all__ = ["margin", "near_tie", "photo_like", "pick_kit", "score_engine", "score_photos"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles; from outside the package, import through here.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.followups.realism.score import score_engine, score_photos

__getattr__, __dir__ = _exports(__name__, {
    "score_engine": ("sweep3d.followups.realism.score", "score_engine"),
    "score_photos": ("sweep3d.followups.realism.score", "score_photos"),
})
