"""Is a failure real? Agreement of the renders' verdicts with photographs of the same scenes, or
with another renderer's images (``sweep3d realism pick`` / ``score``; the ``agreement`` view)."""

from __future__ import annotations

from sweep3d.followups.realism.photos import photo_like
from sweep3d.followups.realism.pick import margin, near_tie
from sweep3d.followups.realism.pick import pick as pick_kit  # not ``pick``: that name is the module's
from sweep3d.followups.realism.score import score_engine, score_photos  # eager: score needs pick and photos

__all__ = ["margin", "near_tie", "photo_like", "pick_kit", "score_engine", "score_photos"]
