"""A contact sheet: one row per control of a spec, showing its effect alone.

Each row renders one scene (the spec's first object in its first environment, or those the user
names) with only that control varied and every other control neutral, through the normal render
and postprocess stages, so every tile is cached like any job. A range is shown at the spec's own
grid when its policy is a grid (five points across it otherwise). A row with more values than
tiles shows an evenly spread subset, and says so (:attr:`Sheet.sampled`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from PIL import Image, ImageDraw

from sweep3d.cache import Store
from sweep3d.core import UserError
from sweep3d.driver import Job, Plan, RunProgress
from sweep3d.runner import plan_spec, running
from sweep3d.spec import LoadedSpec
from sweep3d.stages.infer import ModelHandle
from sweep3d.stages.plan import GridPolicy

TILE = 128
LABEL_WIDTH = 170
SAMPLES_PER_RANGE = 5
MAX_TILES = 8


@dataclass(frozen=True)
class Sheet:
    """A written contact sheet: its file, its scene, and the rows that show a subset of their
    values (control id, values shown, values in all)."""

    path: Path
    object: str
    environment: str
    sampled: list[tuple[str, int, int]]


def contact_sheet(loaded: LoadedSpec, output: Path, progress: RunProgress, object_name: str | None = None,
                  environment: str | None = None, tiles: int = MAX_TILES, wait: float = 0.0) -> Sheet:
    """Render the sheet for ``loaded`` into the PNG ``output``.

    Args:
        object_name, environment: the scene every row shows (default: the spec's first of each).
        tiles: the most tiles a row shows (0: every value).
        wait: seconds to wait for another command holding the store's lock.
    """
    if not loaded.controls:
        raise UserError(f"{loaded.path}: the spec has no [[controls]] to show")
    scene = _scene(loaded, object_name, environment)
    rows: list[tuple[str, list[Job]]] = []
    sampled: list[tuple[str, int, int]] = []
    jobs: list[Job] = []
    model = ModelHandle.resolve(loaded)
    for inst in loaded.controls:
        plan = plan_spec(_one_control(scene, inst), model)
        distinct = list({j.image_key: j for j in plan.jobs}.values())
        if 0 < tiles < len(distinct):  # an evenly spread subset, said
            sampled.append((inst.id, tiles, len(distinct)))
            distinct = ([distinct[round(i * (len(distinct) - 1) / (tiles - 1))] for i in range(tiles)]
                        if tiles > 1 else distinct[:1])
        rows.append((inst.id, distinct))
        jobs += distinct
    plan = Plan(loaded, jobs, model.digest, framing=model.framing, device=plan.device)
    store = Store(loaded.store)
    with running(loaded, wait=wait, progress=progress, store=store) as runner:  # every image stored: the tiles read them
        runner.run(plan, stages=("render", "postprocess"), every_image=True, strict=True, overlap=False)
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
    return Sheet(output, scene.objects[0].name, scene.environments[0].name, sampled)


def _scene(loaded: LoadedSpec, object_name: str | None, environment: str | None) -> LoadedSpec:
    """The spec reduced to one object and one environment (the named ones, else the first)."""
    def pick(items: list, name: str | None, what: str, option: str) -> list:
        if name is None:
            return items[:1]
        found = [item for item in items if item.name == name]
        if not found:
            known = ", ".join(repr(item.name) for item in items)
            raise UserError(f"{loaded.path}: no {what} named {name!r} for {option}; the spec has {known}")
        return found

    spec = loaded.spec.model_copy(update={
        "objects": pick(loaded.objects, object_name, "object", "--object"),
        "environments": pick(loaded.environments, environment, "environment", "--environment")})
    return dataclasses.replace(loaded, spec=spec)


def _one_control(scene: LoadedSpec, inst) -> LoadedSpec:
    """The one-scene spec with only this control, on the spec's own grid when its policy is one
    (else five points across each range)."""
    policy = scene.policy if isinstance(scene.policy, GridPolicy) else GridPolicy(
        GridPolicy.Params(samples_per_dim=SAMPLES_PER_RANGE))
    return dataclasses.replace(scene, controls=[inst], policy=policy)


def _varied(loaded: LoadedSpec, control_id: str) -> set[str]:
    inst = next(c for c in loaded.controls if c.id == control_id)
    return {name for name, space in inst.spaces.items() if len(space.values()) > 1} or set(inst.spaces)


def _short(value) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)
