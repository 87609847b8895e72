"""Photographs: which job each one shows, reading them upright, and bringing them to the model.

A photograph is matched to its job by its file name (``<job>.jpg``, as ``align.html`` saves it;
any image suffix) or by a CSV with the columns ``photo`` and ``job``. Everything is checked
before anything runs: a photograph that matches no job of the kit, a job of the kit without a
photograph, a file that is not a readable image each make one line, and nothing is stored.

A photograph is read upright (its EXIF orientation applied: Pillow's ``ImageOps.exif_transpose``),
then framed as the render it was aligned with: resized so its short side fits the render's
(Lanczos, keeping its aspect) and centre-cropped to the render's size. From there it takes the
path a render takes: its job's 2D controls (``score``), 8-bit pixels to floats and the model's own
preprocessing. A photograph of exactly the kit's raw render is therefore, once its job's controls
are applied, the image the model saw, to the bit.

:func:`photo_like` is the documented transformation that makes a stand-in photograph from a
render (tests, and a dry run of the workflow).
"""

from __future__ import annotations

import csv
import io
import os
import re
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from sweep3d.assets import not_a_file
from sweep3d.core import UserError

#: File suffixes read as photographs (any case).
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".webp", ".tif", ".tiff", ".bmp")
#: Files of a kit that sit beside the photographs when the kit's folder is the photographs' folder.
KIT_FILES = frozenset({"kit.json", "design.csv", "align.html"})
#: The most pixels a photograph may have: Pillow's own guard against decompression bombs (89 megapixels),
#: past which it warns (and at twice which it refuses). A photograph is framed to its render's size.
MAX_PIXELS = 89_478_485
#: What the verdicts record about how a photograph reached the model.
PREPROCESS = ("EXIF orientation applied; resized (short side, Lanczos) and centre-cropped to the render's "
              "{width}x{height}; the job's 2D controls (blur, noise, ...) applied as to its render; then the "
              "model's own preprocessing, as for the render: {model}")


class PhotoProblems(UserError):
    """Photographs that cannot be scored: one line each (the CLI prints the first after ``error:``)."""

    def __init__(self, lines: list[str]) -> None:
        self.lines = lines
        super().__init__("\n".join([lines[0], *(f"error: {line}" for line in lines[1:])]))


@dataclass(frozen=True)
class Photo:
    """One photograph matched to its job."""

    job: int
    path: Path


def match_photos(folder: Path, jobs: Iterable[int], match: Path | None = None) -> list[Photo]:
    """The photographs of ``folder`` (or those the CSV ``match`` lists), one per job of ``jobs``.

    Raises:
        PhotoProblems: one line per photograph that matches no job, job without a photograph,
            photograph listed twice for a job, and file that is not a readable image.
        UserError: ``folder`` or ``match`` cannot be read.
    """
    wanted = sorted(set(jobs))
    if not folder.is_dir():
        raise UserError(f"{folder}: is not a folder of photographs; give the folder the photographs are in")
    if not os.access(folder, os.R_OK | os.X_OK):
        raise UserError(f"{folder}: cannot be read (permission denied); fix its permissions")
    pairs, problems = (_listed(match, folder) if match is not None else _named(folder, wanted))
    found: dict[int, Photo] = {}
    for job, path in pairs:
        if job not in wanted:
            problems.append(f"{path}: matches no job of the kit (its jobs are {_jobs_text(wanted)}); "
                            "rename it <job>.jpg or list it in --match")
            continue
        if job in found:
            problems.append(f"{path}: job {job} has another photograph already ({found[job].path.name}); keep one")
            continue
        problem = unreadable(path)
        if problem:
            fix = "save it smaller" if problem.startswith(TOO_LARGE) else "replace it with the photograph (JPEG, PNG, WebP, TIFF or BMP) or remove it"
            problems.append(f"{path}: {problem}; {fix}")
            continue
        found[job] = Photo(job, path)
    for job in wanted:
        if job not in found and not any(j == job for j, _ in pairs):
            problems.append(f"job {job}: has no photograph in {folder}; take it ({job}.jpg) or pick again without it")
    if problems:
        raise PhotoProblems(problems)
    return [found[job] for job in wanted]


def _named(folder: Path, jobs: list[int]) -> tuple[list[tuple[int | None, Path]], list[str]]:
    """(job, path) for each file of ``folder`` by its name; lines for files named after no job."""
    pairs: list[tuple[int | None, Path]] = []
    problems: list[str] = []
    for path in sorted(folder.iterdir()):
        if path.is_dir() or path.name.startswith(".") or path.name in KIT_FILES:
            continue
        stem = path.stem.strip()
        if stem.isdigit():
            pairs.append((int(stem), path))
        elif path.suffix.lower() in IMAGE_SUFFIXES:
            problems.append(f"{path}: matches no job of the kit (name it <job>{path.suffix}, one of "
                            f"{_jobs_text(jobs)}, or list it in --match)")
        else:
            problems.append(f"{path}: is not a photograph (an image file named <job>.jpg); move it out of the folder")
    return pairs, problems


def _listed(match: Path, folder: Path) -> tuple[list[tuple[int | None, Path]], list[str]]:
    """(job, path) for each row of the CSV ``match`` (photo paths relative to ``folder``)."""
    kind = not_a_file(match)
    if kind:
        raise UserError(f"--match {match}: is {kind}, not a file; give the CSV of photos and jobs")
    try:
        with match.open(newline="", encoding="utf-8-sig") as handle:
            rows = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise UserError(f"--match {match}: cannot be read ({getattr(exc, 'strerror', None) or exc})") from None
    header = [c.strip().lower() for c in rows[0]] if rows else []
    if "photo" not in header or "job" not in header:
        raise UserError(f"--match {match}: its first line must name the columns photo and job")
    at_photo, at_job = header.index("photo"), header.index("job")
    pairs: list[tuple[int | None, Path]] = []
    problems: list[str] = []
    for number, row in enumerate(rows[1:], start=1):
        if not any(cell.strip() for cell in row):
            continue
        cells = row + [""] * (len(header) - len(row))
        photo, job = cells[at_photo].strip(), cells[at_job].strip()
        path = Path(photo).expanduser()
        path = path if path.is_absolute() else folder / path
        if not job.isdigit():
            problems.append(f"--match {match}: row {number}: job {job!r} is not a job number")
            continue
        pairs.append((int(job), path))
    return pairs, problems


def _jobs_text(jobs: list[int]) -> str:
    shown = ", ".join(map(str, jobs[:8]))
    return shown + (f", … ({len(jobs)} in all)" if len(jobs) > 8 else "")


#: How :func:`unreadable` begins its answer for a photograph of more than :data:`MAX_PIXELS`.
TOO_LARGE = "is too large"


def unreadable(path: Path) -> str:
    """Why ``path`` is not a readable image of at most :data:`MAX_PIXELS` ("" when it is). Its size
    is judged from its header, before a pixel is decoded."""
    from PIL import Image, UnidentifiedImageError

    kind = not_a_file(path)  # a FIFO's open would wait for a writer for ever
    if kind:
        return f"is {kind}, not an image"
    try:
        with _opened(path) as im:
            if im.width * im.height > MAX_PIXELS:
                return _too_large(im.width * im.height, f"{im.width}×{im.height} pixels, ")
            im.load()
    except Image.DecompressionBombError as exc:  # past twice the limit: Pillow refuses to open it
        found = re.search(r"\((\d+) pixels\)", str(exc))
        return _too_large(int(found.group(1)) if found else None)
    except FileNotFoundError:
        return "does not exist"
    except IsADirectoryError:
        return "is a folder, not an image"
    except PermissionError:
        return "cannot be read (permission denied)"
    except UnidentifiedImageError:
        return "is not an image Pillow can read"
    except (OSError, ValueError, SyntaxError) as exc:  # truncated or damaged
        return f"cannot be decoded ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
    return ""


def _too_large(pixels: int | None, size: str = "") -> str:
    found = f" ({size}{pixels / 1e6:.0f} megapixels)" if pixels else ""
    return f"{TOO_LARGE}{found}: sweep3d reads photographs of at most {MAX_PIXELS / 1e6:.0f} megapixels"


@contextmanager
def _opened(path: Path) -> Iterator[object]:
    """``Image.open(path)`` without Pillow's warning of a possible decompression bomb: the size is
    judged here (:data:`MAX_PIXELS`), in the user's words."""
    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        with Image.open(path) as im:
            yield im


def upright(path: Path) -> np.ndarray:
    """The photograph at ``path`` as 8-bit RGB (H, W, 3), its EXIF orientation applied."""
    from PIL import ImageOps

    with _opened(path) as im:
        return np.asarray(ImageOps.exif_transpose(im).convert("RGB"), dtype=np.uint8)


def too_small(photo: tuple[int, int], render: tuple[int, int]) -> str:
    """Why a photograph of ``photo`` pixels (height, width; upright) cannot be framed as its render of
    ``render`` pixels ("" when it can): framing shrinks a photograph, never enlarges it, so a model
    never judges a photograph with less detail than its render had."""
    (h, w), (rh, rw) = photo, render
    if h >= rh and w >= rw:
        return ""
    return (f"is {w}×{h} pixels, smaller than its render ({rw}×{rh}): a photograph is shrunk to its render's size, "
            f"never enlarged; use one of at least {rw}×{rh} pixels")


def framed(rgb: np.ndarray, height: int, width: int) -> np.ndarray:
    """``rgb`` resized so that it covers (``height``, ``width``) keeping its aspect, then
    centre-cropped to it (unchanged when it is that size already)."""
    from PIL import Image

    h, w = rgb.shape[:2]
    if (h, w) == (height, width):
        return rgb
    scale = max(height / h, width / w)
    size = (max(width, round(w * scale)), max(height, round(h * scale)))
    resized = np.asarray(Image.fromarray(rgb).resize(size, Image.Resampling.LANCZOS), dtype=np.uint8)
    top, left = (size[1] - height) // 2, (size[0] - width) // 2
    return resized[top:top + height, left:left + width]


def photo_like(rgb: np.ndarray, seed: int = 0) -> bytes:
    """A stand-in photograph of a render: the documented transformation (see docs/how-to/photographs.md).

    In order: a white-balance shift (red × 1.06, blue × 0.92), a 3° rotation about the centre
    (bilinear; the corners it uncovers filled with the image's mean colour), sensor noise
    (Gaussian, σ = 3 levels of 255, seeded) and JPEG at quality 70. Returns the JPEG's bytes.
    """
    from PIL import Image

    x = rgb.astype(np.float64) * np.array([1.06, 1.0, 0.92])
    x = np.clip(np.rint(x), 0, 255).astype(np.uint8)
    fill = tuple(int(v) for v in x.reshape(-1, 3).mean(axis=0))
    rotated = Image.fromarray(x).rotate(3.0, resample=Image.Resampling.BILINEAR, fillcolor=fill)
    noisy = np.asarray(rotated, dtype=np.float64) + np.random.default_rng(seed).normal(0.0, 3.0, x.shape)
    out = io.BytesIO()
    Image.fromarray(np.clip(np.rint(noisy), 0, 255).astype(np.uint8)).save(out, format="JPEG", quality=70)
    return out.getvalue()
