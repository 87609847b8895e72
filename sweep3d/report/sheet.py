"""A contact sheet: one row per control of a spec, showing its effect alone.

Each row renders the spec's first object in its first environment with only that control
varied (its list values, or five points across its range) and every other control neutral,
through the normal render and postprocess stages, so every tile is cached like any job.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from PIL import Image, ImageDraw

from sweep3d.cache.store import Store
from sweep3d.errors import UserError
from sweep3d.pipeline import plan_spec
from sweep3d.progress import RunProgress
from sweep3d.spec.loader import LoadedSpec
from sweep3d.stages.driver import run_stages
from sweep3d.stages.infer import ModelHandle
from sweep3d.stages.plan import Job, Plan
from sweep3d.stages.plan.policies import GridPolicy
from sweep3d.stages.postprocess import PostprocessStage
from sweep3d.stages.render import RenderStage

TILE = 128
LABEL_WIDTH = 170
SAMPLES_PER_RANGE = 5
MAX_TILES = 8


def contact_sheet(loaded: LoadedSpec, output: Path, progress: RunProgress) -> Path:
    """Render the sheet for ``loaded`` into the PNG ``output`` and return its path."""
    if not loaded.controls:
        raise UserError(f"{loaded.path}: the spec has no [[controls]] to show")
    rows: list[tuple[str, list[Job]]] = []
    jobs: list[Job] = []
    model = ModelHandle.resolve(loaded)
    for inst in loaded.controls:
        plan = plan_spec(_one_control(loaded, inst), model)
        distinct = list({j.image_key: j for j in plan.jobs}.values())
        if len(distinct) > MAX_TILES:  # several ranges: a spread of the grid
            distinct = [distinct[round(i * (len(distinct) - 1) / (MAX_TILES - 1))] for i in range(MAX_TILES)]
        rows.append((inst.id, distinct))
        jobs += distinct
    plan = Plan(loaded, jobs, model.digest, framing=model.framing)
    store = Store(loaded.store)
    with store.lock():
        run_stages((RenderStage(), PostprocessStage()), plan, store, progress, strict=True)
    width = LABEL_WIDTH + TILE * max(len(r[1]) for r in rows)
    sheet = Image.new("RGB", (width, TILE * len(rows)), "white")
    draw = ImageDraw.Draw(sheet)
    for y, (control_id, row_jobs) in enumerate(rows):
        draw.text((8, y * TILE + TILE // 2 - 6), control_id, fill="black")
        for x, job in enumerate(row_jobs):
            with Image.open(store.blob_path(job.image_key)) as tile:
                sheet.paste(tile.convert("RGB").resize((TILE, TILE)), (LABEL_WIDTH + x * TILE, y * TILE))
            caption = ", ".join(f"{k}={_short(v)}" for k, v in job.values[control_id].items()
                                if k in _varied(loaded, control_id))
            draw.rectangle([LABEL_WIDTH + x * TILE, y * TILE + TILE - 13, LABEL_WIDTH + (x + 1) * TILE, y * TILE + TILE],
                           fill="white")
            draw.text((LABEL_WIDTH + x * TILE + 2, y * TILE + TILE - 12), caption[:24], fill="black")
    output.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(output)
    return output


def _one_control(loaded: LoadedSpec, inst) -> LoadedSpec:
    """The spec reduced to its first scene and this one control, on a small grid."""
    spec = loaded.spec.model_copy(update={"objects": loaded.objects[:1], "environments": loaded.environments[:1]})
    policy = GridPolicy(GridPolicy.Params(samples_per_dim=SAMPLES_PER_RANGE))
    return dataclasses.replace(loaded, spec=spec, controls=[inst], policy=policy)


def _varied(loaded: LoadedSpec, control_id: str) -> set[str]:
    inst = next(c for c in loaded.controls if c.id == control_id)
    return {name for name, space in inst.spaces.items() if len(space.values()) > 1} or set(inst.spaces)


def _short(value) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)
