"""Blender's progress lines, read back for one number: how long Cycles prepared a render before
its first sample (the BVH, the world's importance map, images, kernels).

Blender prints them to file descriptor 1 itself, and a Python ``render_stats`` handler deadlocks
the render, so a worker points fd 1 at a scratch file instead of ``/dev/null``: :meth:`RenderLog.clear`
empties it before a render and :meth:`RenderLog.setup_seconds` reads Cycles' own clock (the
``Time:`` field, 10 ms resolution) off the line where sampling starts. Plain Python (no bpy), so
the parsing is testable without Blender.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

#: ``Fra:1 Mem:8.56M (Peak 16.35M) | Time:00:03.37 | Mem:... | Scene, ViewLayer | Sample 0/4``
#: (``Time:`` is MM:SS.ss, or HH:MM:SS.ss past an hour, counted from the render's start).
_SAMPLING_STARTS = re.compile(r"Time:(?:(\d+):)?(\d+):(\d+(?:\.\d+)?)\b[^\n]*\|\s*Sample 0/\d+")


class RenderLog:
    """fd 1 of this process, redirected to ``path`` (opened for appending, so emptying it while
    Blender holds its own position in the file leaves no hole)."""

    def __init__(self, path: Path) -> None:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_TRUNC, 0o600)
        os.dup2(fd, 1)
        os.close(fd)
        self.path = path

    def clear(self) -> None:
        """Forget what Blender printed so far (call before a render)."""
        os.ftruncate(1, 0)

    def setup_seconds(self) -> float | None:
        """Seconds the latest render spent before its first sample; None when no line says."""
        try:
            text = self.path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return None
        return parse_setup_seconds(text)


def parse_setup_seconds(text: str) -> float | None:
    """The ``Time:`` of the last ``Sample 0/N`` line in ``text`` (Blender's render progress), in
    seconds; None when there is none (another engine, a render that failed first)."""
    found = _SAMPLING_STARTS.findall(text)
    if not found:
        return None
    hours, minutes, seconds = found[-1]
    return int(hours or 0) * 3600 + int(minutes) * 60 + float(seconds)
