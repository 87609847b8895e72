"""Realism: do the verdicts on the renders hold for photographs of the same scenes (or for another
renderer's images of them)?

Shown only when the store holds verdicts of another source for the experiment (``sweep3d realism
score``). Per source, model and object (and over all objects): the share of jobs on which the
source's verdict is the render's, with its 95 % Wilson interval; PPV (of the jobs the model got
right in simulation, the share it got right in the source too), NPV (of those it got wrong, the
share it got wrong there too) and Cohen's κ (agreement beyond what the two verdicts' rates give by
chance). Then every render | photo pair with both verdicts, in pages of :data:`PAIRS` (the first
open, the others a click away, each saying which pairs it holds): the disagreements first, then
the objects in turn, so the first page shows every object it can. Another renderer as the source
says what it shares with Cycles (:data:`ENGINE_SHARES`): agreement with it is a test of the path
tracer, not of realism.
"""

from __future__ import annotations

import base64
import io
from typing import Any

from sweep3d.report.figures import interval, pct
from sweep3d.report.panel import PanelInputs
from sweep3d.results import has_view, photo_path

PAIRS = 24  # render | photo pairs per page (every pair is on a page)
JPEG_QUALITY = 80
#: What a renderer as the source shares with the run's Cycles renders: sweep3d replays the same
#: scene description through it, so only the path tracer changes.
ENGINE_SHARES = (
    "{engine} is not independent of the renders: it draws the same configurations through sweep3d's own scene "
    "path, so it shares with Cycles the reading of the OBJ and MTL files (sweep3d reads them as Blender's importer "
    "does), the framing and camera, the pose, the key light and lights, the denoiser (OpenImageDenoise) and the "
    "view transform; what changes is the path tracer (light transport, shading models, sampling, pixel filter). "
    "A verdict that survives it survives a change of path tracer; it does not show that the scene is realistic "
    "(photographs of it do)")


def build(inputs: PanelInputs) -> dict[str, Any] | None:
    """The agreement table and the pairs; None without another source's verdicts."""
    if not has_view(inputs.con, "agreement"):
        return None
    rows = inputs.rows("SELECT * FROM agreement")
    if not rows:
        return None
    sources = list(dict.fromkeys(r["source"] for r in rows))
    return {"rows": [_row(r) for r in rows], "sources": [_pairs(inputs, s) for s in sources],
            "several_models": len({r["model"] for r in rows}) > 1}


def _row(r: dict[str, Any]) -> dict[str, Any]:
    return {"source": r["source"], "model": r["model"], "object": "all objects" if r["overall"] else r["object"],
            "overall": r["overall"], "n": r["n"], "n_agree": r["n_agree"], "agreement": pct(r["agreement"], 0),
            "interval": interval(r["wilson_low"], r["wilson_high"]),
            "ppv": _ratio(r["ppv"], r["n_sim_right"]), "npv": _ratio(r["npv"], r["n_sim_wrong"]),
            "kappa": "–" if r["kappa"] is None else f"{r['kappa']:.2f}"}


def _ratio(value: float | None, n: int) -> str:
    return "–" if value is None else f"{value:.2f} (of {n})"


def _pairs(inputs: PanelInputs, source: str) -> dict[str, Any]:
    """Every job of ``source`` (first model's verdicts) in pages of :data:`PAIRS`: disagreements
    first, then each object's first job, each object's second, ... (job order within an object)."""
    rows = inputs.rows(
        "SELECT * FROM source_verdicts WHERE source = ? AND model = (SELECT min(model) FROM source_verdicts "
        "WHERE source = ?) ORDER BY sim_correct = source_correct, row_number() OVER (PARTITION BY "
        "sim_correct = source_correct, object ORDER BY job), object, job", [source, source])
    pairs = []
    # each image's hover text names its job and configuration (``job 3 · object = mug · …``)
    described = {row.job: inputs.results.describe(row) for row in inputs.results.rows([r["job"] for r in rows])}
    for r in rows:
        agree = r["sim_correct"] == r["source_correct"]
        job = described.get(r["job"], f"job {r['job']} · object = {r['object']} · environment = {r['environment']}")
        render = {"thumb": inputs.thumbs.want(r["image_key"]), "outcome": _outcome(r["sim_correct"]),
                  "caption": f"render: {r['sim_top1']}",
                  "title": f"{job} · render: {r['sim_top1']} ({_outcome(r['sim_correct'])})"}
        other = {"outcome": _outcome(r["source_correct"]), "caption": f"{_short(source)}: {r['source_top1']}",
                 "title": f"{job} · {_short(source)}{' ' + r['photo'] if r['photo'] else ''}: {r['source_top1']} "
                          f"({_outcome(r['source_correct'])})"}
        if r["source_image_key"]:
            other["thumb"] = inputs.thumbs.want(r["source_image_key"])
        else:
            other["uri"] = _photo_uri(inputs, r["photo_sha256"])
        pairs.append({"job": r["job"], "agree": agree, "render": render, "other": other})
    return {"source": source, "model": rows[0]["model"] if rows else "", "n": len(pairs), "pages": _paged(pairs),
            "disagree": sum(not p["agree"] for p in pairs), "preprocess": rows[0]["preprocess"] if rows else "",
            "shares": ENGINE_SHARES.format(engine=_short(source)) if source.startswith("engine:") else ""}


def _paged(pairs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``pairs`` in pages of :data:`PAIRS`, each with its first and last pair's place (from 1) and
    how many of its pairs disagree."""
    return [{"first": start + 1, "last": start + len(page), "pairs": page,
             "disagree": sum(not p["agree"] for p in page)}
            for start in range(0, len(pairs), PAIRS) for page in [pairs[start:start + PAIRS]]]


def _outcome(correct: bool) -> str:
    return "correct" if correct else "wrong"


def _short(source: str) -> str:
    return source.removeprefix("engine:")


def _photo_uri(inputs: PanelInputs, sha256: str | None) -> str | None:
    """The kept photograph as a data URI at the report's thumbnail size (None when it is gone)."""
    from PIL import Image

    if not sha256:
        return None
    try:
        with Image.open(photo_path(inputs.store, sha256)) as im:
            image = im.convert("RGB")
    except OSError:
        return None
    image.thumbnail((inputs.thumbs.size, inputs.thumbs.size))
    buffer = io.BytesIO()
    image.save(buffer, format="JPEG", quality=JPEG_QUALITY)
    return "data:image/jpeg;base64," + base64.b64encode(buffer.getvalue()).decode()
