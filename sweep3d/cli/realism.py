"""``sweep3d realism``: is a failure real? Pick jobs to photograph, then score the photographs
(or another renderer's images) against the renders' verdicts."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.markup import escape

from sweep3d.cli._commands import check_wait, registrar, require_store

realism_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None,
                          help="Agreement with photographs or another renderer: pick jobs, then score them.")
console = Console(highlight=False)
command = registrar(realism_app)

SpecArg = typer.Argument(..., help="Path to the experiment's TOML spec.", show_default=False, readable=False)
KitOption = typer.Option(None, "--kit", help="The kit's folder (default: PHOTOS when it holds kit.json, else "
                                              "kits/<experiment> in the store).",
                          readable=False)  # the command says why it cannot read one, in one line
WaitOption = typer.Option(0.0, help="Seconds to wait for a run holding the store's lock.")


@command
def pick(
    spec: Path = SpecArg,
    per_object: int = typer.Option(10, "--per-object", help="Results per object and model: half right, half wrong."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Seed of the draw (default: the spec's seed)."),
    output: Optional[Path] = typer.Option(None, "--output", "-o", help="The kit's folder: new, empty or an earlier "
                                          "kit (default: kits/<experiment> in the store).", readable=False),
    near_ties: str = typer.Option("leave", "--near-ties", help="Results whose true and best other class are within "
                                  "0.05 probability: leave them out, or mark them (kept, flagged in kit.json)."),
) -> None:
    """Choose results worth photographing and write the kit: design.csv, renders, edges, align.html."""
    import sweep3d
    from sweep3d.followups.realism import pick_kit

    loaded = sweep3d.load(spec).spec
    require_store(loaded)
    kit = pick_kit(loaded, output, per_object, seed, near_ties)
    for line in kit.short:
        console.print(f"[yellow]note:[/] {escape(line)}", soft_wrap=True)
    console.print(escape(kit.line()), soft_wrap=True)


@command
def score(
    spec: Path = SpecArg,
    photos: Optional[Path] = typer.Argument(None, help="The folder of photographs, each named <job>.jpg (or "
                                            "listed in --match). Not with --engine.", show_default=False,
                                            readable=False),
    match: Optional[Path] = typer.Option(None, "--match", help="A CSV with columns photo,job (photo paths relative "
                                         "to PHOTOS) instead of matching by file name.", readable=False),
    engine: Optional[str] = typer.Option(None, "--engine", help="Score another renderer instead of photographs: "
                                         "render the kit's design with [render] engine = NAME."),
    kit: Optional[Path] = KitOption,
    wait: float = WaitOption,
) -> None:
    """Run the spec's models on the photographs (or another renderer's images) of the picked jobs and
    store their verdicts; the agreement view and the report's Realism panel read them."""
    import sweep3d
    from sweep3d.core import UserError
    from sweep3d.followups.realism import score_engine, score_photos

    check_wait(wait)
    loaded = sweep3d.load(spec).spec
    require_store(loaded)
    if engine is not None:
        if photos is not None or match is not None:
            raise UserError("--engine scores renders, not photographs: leave PHOTOS and --match out")
        scored = score_engine(loaded, engine, kit, console, wait)
    else:
        if photos is None:
            raise UserError("give the folder of photographs (PHOTOS), or --engine NAME to score another renderer")
        scored = score_photos(loaded, photos, match, kit, wait)
        # said once the photographs are scored, so that an error is the only line of a refused score
        console.print("photographs are read upright (EXIF orientation), resized and centre-cropped to their "
                      "render's size, given their job's 2D controls (blur, noise, ...) as its render was, then "
                      "the model's own preprocessing, as the renders were", soft_wrap=True)
    for line in scored.lines():
        console.print(escape(line), soft_wrap=True)
