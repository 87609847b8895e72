"""What a stage did: how many items it needed, found cached, computed, failed and repaired."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class StageOutcome:
    stage: str
    total: int = 0  # distinct keys the plan needs at this stage
    cached: int = 0
    computed: int = 0
    failed: int = 0
    skipped: int = 0  # waiting on an upstream stage that failed, or on a damaged upstream blob
    seconds: float = 0.0
    errors: list[str] = field(default_factory=list)
    #: Upstream blobs this stage found damaged and discarded: the run's next pass recomputes them.
    repaired: int = 0

    def as_row(self) -> dict[str, object]:
        return {k: getattr(self, k) for k in ("stage", "total", "cached", "computed", "failed", "skipped", "seconds")}
