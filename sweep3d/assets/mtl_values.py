"""The values of an MTL file, checked as text before either renderer reads them.

Blender's OBJ importer drops a ``Kd`` line it cannot read (``Kd 1 nan 0``: the default grey
renders) and reads ``Ns abc`` as some roughness; Mitsuba's principled BSDF refuses a base colour
of ``1e300`` or ``-5`` and so fails every job at render time. Neither says a word at ``plan``. These
checks read each line of an MTL and name the line to fix: a number that is not one (``abc``,
``1_0``), one that is not finite in the 32 bits renderers keep (``nan``, ``inf``, ``1e39``), and a
base colour outside 0–1 (with :data:`COLOUR_SLACK` for rounding) or a negative one.

What neither renderer reads is only warned about: ``Ka`` (ambient) is ignored by Blender's
importer (4.5) and by the Mitsuba engine, so a bad ``Ka`` changes no pixel.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

#: The base colour, a reflectance: each channel must lie in [0, 1] (give or take the slack); Mitsuba's
#: principled BSDF refuses any other value and Cycles' would reflect more light than it receives.
UNIT_COLOURS = ("kd",)
#: Colours neither renderer reads (checked, but only warned about).
UNUSED_COLOURS = ("ka",)
#: Colours that must be finite and not negative but may exceed 1: specular (exporters write ``Ks`` up
#: to 2: Blender's Specular IOR Level, which Mitsuba's translation bounds), transmission (its mean,
#: clamped to 1 by both) and emission (a bright emitter).
OPEN_COLOURS = ("ks", "tf", "ke")
#: Scalar keys Blender's importer reads (``illum`` is an integer).
NUMBERS = ("ns", "ni", "d", "tr", "pr", "pm", "ps", "pc", "pcr", "aniso", "anisor", "sharpness", "illum")
#: How far past 0 and 1 a colour channel may be written (an exporter's rounding: ``1.0000001``).
COLOUR_SLACK = 0.01
#: The largest finite 32-bit float: renderers keep colours and numbers in 32 bits.
FLOAT32_MAX = 3.4028234663852886e38
#: A plain decimal number, as MTL files write them (Python's float() also takes ``1_0`` and ``nan``).
PLAIN_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
NOT_FINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)
FIX = "fix the line or export the material again"


@dataclass(frozen=True)
class MtlProblem:
    """One line of an MTL that a renderer would misread: an error, or a warning (``fatal`` False)."""

    line: int
    text: str  # the line as written (shortened)
    problem: str
    fatal: bool = True

    def message(self, mtl: str) -> str:
        """``cube.mtl line 3 ('Kd 1 nan 0'): ...``: the file, the line, what is wrong and the fix."""
        return f"{mtl} line {self.line} ({self.text!r}): {self.problem}"


def check_mtl_text(text: str) -> list[MtlProblem]:
    """Every value problem of an MTL's lines, in file order (errors and warnings together)."""
    problems = []
    for number, raw in enumerate(text.splitlines(), 1):
        words = raw.split("#", 1)[0].split()
        if len(words) < 2:
            continue
        key = words[0].lower()
        shown = raw.strip()[:60]
        problem = None
        if key in UNIT_COLOURS or key in UNUSED_COLOURS:
            problem = _colour(words[0], words[1:], upper=1.0)
        elif key in OPEN_COLOURS:
            problem = _colour(words[0], words[1:], upper=None)
        elif key in NUMBERS:
            problem = _number(words[0], words[1], integer=key == "illum")
        if problem is not None:
            unused = key in UNUSED_COLOURS
            if unused:
                problem += f" (neither Blender's importer nor the Mitsuba engine reads {words[0]}, so it is ignored)"
            problems.append(MtlProblem(number, shown, problem, fatal=not unused))
    return problems


def _colour(key: str, values: list[str], upper: float | None) -> str | None:
    """What is wrong with a colour's values (``Kd r g b`` or ``Kd grey``), or None."""
    if values[0].lower() in ("spectral", "xyz"):  # a spectral file or CIE XYZ: not judged here
        return None
    channels = values[:3]
    if len(channels) == 2:
        return f"{key} needs one grey value or three (r g b), not two; {FIX}"
    bounds = f"from 0 to {upper:g}" if upper is not None else "of 0 or more"
    for word in channels:
        bad = _not_a_number(word)
        if bad:
            return f"{bad}; give {key} as three numbers {bounds}: {FIX}"
        value = float(word)
        if value < -COLOUR_SLACK or (upper is not None and value > upper + COLOUR_SLACK):
            where = "negative" if value < 0 else f"over {upper:g}"
            return f"{key} {word} is {where}; give {key} as three numbers {bounds}: {FIX}"
    return None


def _number(key: str, word: str, integer: bool) -> str | None:
    """What is wrong with a scalar's value, or None."""
    bad = _not_a_number(word)
    if bad:
        return f"{bad}; give {key} as a number: {FIX}"
    if abs(float(word)) > FLOAT32_MAX:
        return f"{key} {word} is too large to be finite in 32 bits; {FIX}"
    if integer and not float(word).is_integer():
        return f"{key} must be a whole number (an illumination model 0–10), not {word}; {FIX}"
    return None


def _not_a_number(word: str) -> str | None:
    """Why ``word`` is not a finite plain number, or None when it is one."""
    if NOT_FINITE.fullmatch(word):
        return f"{word!r} is not a finite number"
    if not PLAIN_NUMBER.fullmatch(word):
        return f"{word!r} is not a number"
    if not math.isfinite(float(word)) or abs(float(word)) > FLOAT32_MAX:
        return f"{word!r} is too large to be finite in 32 bits"
    return None
