"""Is a failure real? Agreement of the renders' verdicts with photographs of the same scenes, or
with another renderer's images (``sweep3d realism pick`` / ``score``; the ``agreement`` view)."""

from sweep3d.realism.photos import photo_like
from sweep3d.realism.pick import margin, near_tie
from sweep3d.realism.pick import pick as pick_kit  # not ``pick``: that name is the module's
from sweep3d.realism.score import score_engine, score_photos

__all__ = ["margin", "near_tie", "photo_like", "pick_kit", "score_engine", "score_photos"]
