"""The alignment page of a realism kit: ``align.html``, the render laid over the live camera view.

The render is the kit's ``renders/<job>.png``: the job's raw render, before its 2D controls (blur,
noise, ...), as the scene a camera sees; ``sweep3d realism score`` applies those to the photograph.

To photograph the scene of a render, a user stands in the real room with a phone, opens the page,
and moves the object (or the phone) until the camera view matches the render or its edges laid
translucently over it; the capture button saves the camera frame as ``<job_id>.jpg`` for
``sweep3d realism score``. The 3DB paper (Section 5) did this with a custom iOS app; a web page
needs nothing installed. Where the browser refuses the live camera (not a secure context, no
camera, permission denied) the page falls back to the phone's own camera app through a file input
and shows the photo under the overlay, so the user can judge it and retake.

The page is one file: its script and stylesheet inlined, and the images too, as data URIs. The
kit's images are already in its folder, but a page that needs nothing else can be sent to a phone
(a message, a mail, AirDrop) and opened there, where a phone's file viewer could not read the
page's siblings; a data URI also never taints a canvas. The data (job ids, captions, images)
travels as one JSON block that the script reads and prints as text, and a Content-Security-Policy
allows the page's one script and no request (no network, no CDN), so a job id cannot become markup
or code.

What the overlay means, for whoever crops the photos: it is the render fitted inside the camera
frame at the render's aspect ratio and centred (the largest such rectangle), so the region of
the photo to compare with the render is that same centred rectangle.
"""

from __future__ import annotations

import base64
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path

import jinja2
from markupsafe import Markup
from PIL import Image

from sweep3d.cache import atomic_write

#: The page's file name in the kit folder.
PAGE = "align.html"
TEMPLATE = "align.html.j2"
SCRIPT = "align.js"
STYLESHEET = "align.css"
_MEDIA_TYPES = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp"}


@dataclass(frozen=True)
class AlignShot:
    """One shot to take: a job, its render and edge image (paths relative to the kit folder), and
    the caption shown with it (e.g. the object and the values of its controls)."""

    job_id: str
    render: str
    edges: str
    caption: str


def write_align_page(kit_dir: Path, shots: Sequence[AlignShot]) -> Path:
    """Write ``kit_dir/align.html`` for ``shots`` (in their order) and return its path.

    Raises:
        ValueError: no shots, two shots with one job id, a shot whose image is not a PNG, JPEG or
            WebP, or whose edge image differs in size from its render (the caller's mistakes).
        FileNotFoundError: a render or edge image is not in ``kit_dir``.
        StoreWriteError: the page cannot be written (a full disk, a read-only folder).
    """
    kit_dir = Path(kit_dir)
    if not shots:
        raise ValueError("write_align_page needs at least one shot")
    seen: set[str] = set()
    for shot in shots:
        if shot.job_id in seen:
            raise ValueError(f"two shots have the job id {shot.job_id!r}: their photos would share one file name")
        seen.add(shot.job_id)
    path = kit_dir / PAGE
    atomic_write(path, render_align_page([_shot_data(kit_dir, shot) for shot in shots]).encode("utf-8"), durable=False)
    return path


def render_align_page(shots: list[dict[str, object]]) -> str:
    """The page's HTML for shots already read (see :func:`_shot_data`)."""
    script, stylesheet = _static(SCRIPT), _static(STYLESHEET)
    csp = "; ".join([
        "default-src 'none'",
        f"script-src {_csp_hash(script)}",
        "style-src 'unsafe-inline'",  # the script sizes the overlay through element styles
        "img-src data: blob:",  # the shots (data URIs) and the chosen photo (a blob URL)
        "media-src blob: mediastream:",
    ])
    return _environment().get_template(TEMPLATE).render(
        shots=shots, script=Markup(script), stylesheet=Markup(stylesheet), csp=csp)


def _shot_data(kit_dir: Path, shot: AlignShot) -> dict[str, object]:
    render_path, edges_path = kit_dir / shot.render, kit_dir / shot.edges
    width, height = _size(render_path)
    if _size(edges_path) != (width, height):
        raise ValueError(f"{shot.edges} is {_size(edges_path)} pixels but its render {shot.render} is {(width, height)}")
    return {"job_id": shot.job_id, "caption": shot.caption, "width": width, "height": height,
            "render": _data_uri(render_path), "edges": _data_uri(edges_path)}


def _size(path: Path) -> tuple[int, int]:
    with Image.open(path) as img:
        return img.size


def _data_uri(path: Path) -> str:
    media = _MEDIA_TYPES.get(path.suffix.lower())
    if media is None:
        raise ValueError(f"{path.name}: the page shows PNG, JPEG or WebP images ({', '.join(_MEDIA_TYPES)})")
    return f"data:{media};base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _csp_hash(script: str) -> str:
    """The CSP source that allows exactly the inline script ``script``."""
    return "'sha256-" + base64.b64encode(hashlib.sha256(script.encode("utf-8")).digest()).decode("ascii") + "'"


@lru_cache(maxsize=None)
def _static(name: str) -> str:
    # as the HTML parser will see it (CR LF → LF), so that the CSP hash matches
    text = resources.files("sweep3d.followups.realism").joinpath("templates", name).read_text(encoding="utf-8")
    return text.replace("\r\n", "\n").replace("\r", "\n")


@lru_cache(maxsize=1)
def _environment() -> jinja2.Environment:
    return jinja2.Environment(loader=jinja2.PackageLoader("sweep3d.followups.realism", "templates"), autoescape=True,
                              undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)

