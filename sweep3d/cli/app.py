"""Typer commands. User mistakes print one red line and exit 2; nothing here imports bpy."""

from __future__ import annotations

import errno
import os
import re
import signal
import sys
import uuid
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Column, Table
from rich.text import Text

from sweep3d.cli._commands import DEBUG, check_wait, err_console, registrar, require_store
from sweep3d.core import UserError

if TYPE_CHECKING:
    from sweep3d.api import Experiment

app = typer.Typer(
    add_completion=False,
    rich_markup_mode=None,  # help texts are plain text: "[render]" is a table name, not markup
    no_args_is_help=True,
    help="Find where computer-vision models fail by rendering 3D scenes under systematic variation.",
)
console = Console(highlight=False)  # values from data print as text: no colouring of what looks like numbers or paths

command = registrar(app)


@app.callback()
def options(debug: bool = typer.Option(False, "--debug", help="When a plug-in of yours fails, print its traceback "
                                                                "too (otherwise: one line naming it).")) -> None:
    """Find where computer-vision models fail by rendering 3D scenes under systematic variation."""
    DEBUG["on"] = debug


SpecArg = typer.Argument(..., help="Path to the experiment's TOML spec.", show_default=False,
                         readable=False)  # the loader says why it cannot read one, in one line
ModelOption = typer.Option(None, "--model", help="Which of the spec's models results and the views show (its id; "
                                                   "default: the first). results_all holds every model's.")


@command
def plan(
    spec: Path = SpecArg,
    materials: bool = typer.Option(False, "--materials", help="Also import each object in Blender and print "
                                   "the material values it renders with (the file's, as the importer read them, "
                                   "and the spec's overrides)."),
    jobs: int = typer.Option(0, "--jobs", min=0, help="Also list the first N jobs: scene, values, cached or not."),
    design: Optional[Path] = typer.Option(None, "--design", help="Also write every job's object, environment and "
                                          "control values to this .csv or .parquet file: a design the table policy "
                                          "replays (type = \"table\", file = \"...\")."),
) -> None:
    """Count the jobs a spec expands to, what is already cached, and an estimated time."""
    import sweep3d
    from sweep3d.cli.output import print_plan
    from sweep3d.runner import plan_status

    if design is not None:
        from sweep3d.stages.plan import check_output

        check_output(design)
    loaded = sweep3d.load(spec).spec
    if materials:  # first: a part or material only Blender can check fails before anything prints
        from sweep3d.cli.materials import effective_materials, print_materials

        described = effective_materials(loaded)
    status = plan_status(loaded)
    print_plan(console, status, jobs)
    made = status.plan
    if design is not None:
        from sweep3d.stages.plan import write_design

        rows = write_design(made.jobs.columns.table(loaded.name, loaded.parameter_columns), loaded.parameter_columns,
                            design)
        console.print(f"wrote the design of {rows} jobs to {escape(str(design))}", highlight=False)
    if materials:
        print_materials(console, loaded, described)


@command
def run(
    spec: Path = SpecArg,
    report: bool = typer.Option(True, help="Write the HTML report when the run ends."),
    wait: float = typer.Option(0.0, help="Seconds to wait for another run holding the store's lock."),
    executor: str = typer.Option("local", help="Where renders run: local worker processes, or ray."),
    address: Optional[str] = typer.Option(None, help="With --executor ray: the cluster's address (default: "
                                                      "start a local one on 127.0.0.1)."),
) -> None:
    """Render, postprocess and infer everything the spec needs that the store lacks."""
    check_wait(wait)
    from sweep3d.stages.render import drop_early_worker, start_early_worker

    if executor == "local":
        start_early_worker()  # Blender loads in a render worker while the spec is read and planned
    try:
        from sweep3d.api import Experiment

        experiment = Experiment(spec)
        signal.signal(signal.SIGTERM, _interrupt)  # clean up workers and scratch files as on Ctrl-C
        result = experiment.run(wait=wait, executor=executor, address=address, console=console)
    finally:
        drop_early_worker()  # a run that rendered nothing, or not with Cycles on the CPU
    from sweep3d.cli.output import print_run

    print_run(console, result)
    if len(experiment.spec.models) > 1:
        from sweep3d.cli.output import print_comparison

        print_comparison(console, experiment.spec)
    from sweep3d.cli.output import check_some_valid

    check_some_valid(result.plan, result.store)
    from sweep3d.cli.output import nothing_to_report

    if report and not nothing_to_report(result):  # every job failed: the failure line said why, no report
        _write_report(experiment, None)
    if result.failed:
        raise typer.Exit(1)


@command
def explain(
    spec: Path = SpecArg,
    budget: Optional[int] = typer.Option(None, help="Most configurations beyond the run's own that the search may "
                                                    "probe, each at most one render (default: no limit); the "
                                                    "failures are then a seeded sample."),
    seed: Optional[int] = typer.Option(None, help="Seed of the order the failures are taken in (default: the spec's)."),
    wait: float = typer.Option(0.0, help="Seconds to wait for another run holding the store's lock."),
    report: bool = typer.Option(True, help="Write the HTML report (with its Nearest fixes panel) when it ends."),
) -> None:
    """For each failure of a finished run, find the nearest configuration where the model is right."""
    from sweep3d.api import Experiment

    check_wait(wait)
    experiment = Experiment(spec)
    signal.signal(signal.SIGTERM, _interrupt)  # clean up workers and scratch files as on Ctrl-C
    experiment.explain(budget=budget, seed=seed, wait=wait, console=console)
    if report:
        _write_report(experiment, None)


@command
def report(
    spec: Path = SpecArg,
    output: Optional[Path] = typer.Option(None, "--output", "-o", help="HTML file to write."),
    model: Optional[str] = ModelOption,
) -> None:
    """Write a self-contained HTML dashboard of the spec's results."""
    from sweep3d.api import Experiment

    experiment = Experiment(spec)
    require_store(experiment.spec)
    _write_report(experiment, output, model)


@command
def compare(spec: Path = SpecArg) -> None:
    """Compare the spec's models on the same jobs: accuracy, McNemar's test, where each is better."""
    from sweep3d.api import Experiment, require_models
    from sweep3d.cli.output import print_comparison

    loaded = Experiment(spec).spec
    require_models(loaded)
    require_store(loaded)
    print_comparison(console, loaded)


@command
def stability(
    spec: Path = SpecArg,
    sample: int = typer.Option(64, "--sample", min=1, help="Images to re-infer first (per model), spread over margin "
                                                             "bins, near-ties first."),
    max_sample: int = typer.Option(1024, "--max-sample", min=1,
                                   help="Most images per model: rounds doubling the sample give the margin bins not "
                                        "yet decided against the fragile rule more images, up to this many."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, show_default=False,
                                       help="Seeds the sample's order and the random changes (default: the spec's)."),
    wait: float = typer.Option(0.0, help="Seconds to wait for another command holding the store's lock."),
    scene: Optional[bool] = typer.Option(None, "--scene/--no-scene", show_default=False,
                                         help="Re-render each sampled job's scene neighbours (yaw ±1°, camera "
                                              "distance ±1 %, light ±5 %, ...; default: the spec's [stability] "
                                              "scene, true)."),
    executor: str = typer.Option("local", help="Where the neighbours render: local worker processes, or ray."),
    address: Optional[str] = typer.Option(None, help="With --executor ray: the cluster's address (default: "
                                                      "start a local one on 127.0.0.1)."),
) -> None:
    """Re-infer a sample of the run's images under changes no eye sees (±1 level of noise, dither, 8-bit
    resizing) and re-render their scene neighbours (a degree, a percent away): the flip rate per margin bin,
    which results are fragile, and worst-of-neighbourhood accuracy."""
    from sweep3d.cli.stability import run_stability

    check_wait(wait)
    signal.signal(signal.SIGTERM, _interrupt)  # the neighbours' render workers end with the command
    run_stability(console, spec, sample, seed, wait, max_sample, scene=scene, executor=executor, address=address)


@command
def bench(
    spec: Path = SpecArg,
    jobs: Optional[int] = typer.Option(None, min=1, show_default=False,
                                       help="Jobs sampled (seeded) from the spec's plan: 100 unless --budget "
                                            "chooses; agreement is known to about ±1/sqrt(jobs), so a few dozen at "
                                            "least."),
    budget: Optional[float] = typer.Option(None, show_default=False,
                                           help="Minutes the bench may take: it samples the most jobs whose bench "
                                                "is estimated to fit, and says how many and why (instead of --jobs; "
                                                "not with it)."),
    reference_samples: int = typer.Option(512, min=1, help="Samples per pixel of the reference renders."),
    reference_denoise: str = typer.Option("off", help="The reference's denoiser: off, or OIDN with the "
                                                      "accurate/fast/none prefilter."),
    floor: bool = typer.Option(True, help="Render the reference again with another seed: how often two "
                                          "references disagree is the noise floor (doubles the reference's cost)."),
    agreement: float = typer.Option(0.99, min=0.0, max=1.0, help="Top-1 agreement with the reference a setting "
                                                                 "needs (lowered to the noise floor's, if lower)."),
    apply: bool = typer.Option(False, "--apply", help="Write the recommended setting into the spec's [render]."),
    engine: list[str] = typer.Option([], "--engine", help="Also render the spec's setting with this renderer "
                                                          "(mitsuba, cycles): its time against agreement with the "
                                                          "reference, rendered by the spec's renderer (never "
                                                          "recommended). Repeatable."),
    wait: float = typer.Option(0.0, help="Seconds to wait for another command holding the store's lock."),
) -> None:
    """Render time against error: find the cheapest render setting the model cannot tell apart.

    Renders a seeded sample of jobs at a high-sample reference, at the reference again with
    another seed (the noise floor) and at a grid of cheaper settings, all through the cached
    stages. A setting passes when the top of the 95 % Wilson interval of its top-1 agreement
    with the reference reaches --agreement (or the floor's agreement, if lower): it is not
    clearly worse. The fastest passing setting is recommended, with its speed-up over the
    spec's setting measured in the same run. Times are steady-state: what a worker spends
    switching scene (mesh, world, importance map) is reported apart, as load.
    """
    import time

    import sweep3d
    from sweep3d.bench import (
        Setting,
        apply_setting,
        budget_chooser,
        check_budget,
        default_settings,
        measure,
        recommend,
        reference_settings,
        write_pareto_plot,
    )
    from sweep3d.cache import Store
    from sweep3d.cli.output import print_bench
    from sweep3d.driver import RunProgress
    from sweep3d.stages.infer import ModelHandle
    from sweep3d.stages.render import duration

    check_wait(wait)
    if budget is not None:
        check_budget(budget)
        if jobs is not None:
            raise UserError(f"--budget {budget:g} and --jobs {jobs} together: give one (--jobs: that many jobs; "
                            "--budget: as many as are estimated to fit in the minutes)")
    if reference_denoise not in ("off", "accurate", "fast", "none"):
        raise UserError(f"--reference-denoise {reference_denoise!r}: use off, accurate, fast or none")
    loaded = sweep3d.load(spec).spec
    r = loaded.render
    view = ModelHandle.resolve(loaded).view  # None: a user's own preprocessing, compared at the spec's size
    model_view, full_frame = view is not None, view.crop if view is not None else None
    current = Setting(r.samples, r.denoise_prefilter if r.denoise else "off", r.max_bounces,
                      "model" if r.resolution == "model" else None, r.adaptive_threshold, engine=r.engine)
    reference, twin = reference_settings(reference_samples, reference_denoise, current, model_view)
    from sweep3d.stages.render import BACKENDS

    unknown = [e for e in engine if e not in BACKENDS]
    if unknown:
        raise UserError(f"--engine {unknown[0]!r}: use one of {', '.join(BACKENDS.names())}")
    settings = default_settings(current, model_view, full_frame, engine)
    references = [reference] + ([twin] if floor else [])
    sample = 100 if jobs is None else jobs
    if budget is not None:
        sample = budget_chooser(loaded, references + settings, budget,
                                lambda choice: console.print(escape(choice.line()), soft_wrap=True))
    started = time.perf_counter()
    with RunProgress(console) as progress:
        rows = measure(loaded, settings, reference, twin if floor else None, sample, progress, wait)
    best = recommend(rows, agreement, current.engine)
    print_bench(console, rows, best, current, agreement)
    if budget is not None:
        console.print(f"the bench took {duration(time.perf_counter() - started)} (--budget {budget:g} min)")
    plot = write_pareto_plot(rows, best, Store(loaded.store).report_path(loaded.name, ".html", "bench"),
                             f"{loaded.name}: render time against error ({rows[0].jobs} jobs)")
    console.print(f"Pareto plot: [bold]{plot}[/]")
    if apply and best is not None:
        apply_setting(spec, best.setting, r.resolution)
        console.print(f"wrote {best.setting.label()} into the \\[render] table of {escape(str(spec))}")


@command
def grade(
    spec: Path = SpecArg,
    budget: Optional[int] = typer.Option(None, "--budget", min=0, show_default=False,
                                         help="Most renders the checks may use, cached ones included (default: two "
                                              "thirds of the renders the run made, so grading takes less time than the "
                                              "run; the same budget and seed give the same grades and render nothing "
                                              "the second time)."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, show_default=False,
                                       help="Seed of the checks' draws (default: the spec's)."),
    wait: float = typer.Option(0.0, help="Seconds to wait for another command holding the store's lock."),
    executor: str = typer.Option("local", help="Where the checks' renders run: local worker processes, or ray."),
    address: Optional[str] = typer.Option(None, help="With --executor ray: the cluster's address (default: "
                                                     "start a local Ray)."),
) -> None:
    """Grade every finding of the last run: replicated on fresh renders, reproduced by the second renderer, not
    fragile (solid), or renderer-sensitive, fragile, not replicated, inconclusive or untested, with its evidence."""
    from sweep3d.api import EXECUTORS, Experiment
    from sweep3d.cli.grading import print_grades
    from sweep3d.followups.grade import grade_findings
    from sweep3d.stages.render import Executor

    check_wait(wait)
    if executor not in EXECUTORS:
        raise UserError(f"--executor {executor}: use local or ray")
    experiment = Experiment(spec)
    require_store(experiment.spec)
    signal.signal(signal.SIGTERM, _interrupt)
    graded = grade_findings(experiment.spec, budget, seed, console, wait=wait, executor=Executor(executor, address))
    print_grades(console, graded, spec)


@command
def confirm(
    spec: Path = SpecArg,
    renders: Optional[int] = typer.Option(None, "--renders", min=2, show_default=False,
                                          help="Fresh renders per finding, half inside its region and half outside "
                                               "(default 64)."),
    max_renders: int = typer.Option(1024, "--max-renders", min=2,
                                    help="Most fresh renders per finding: looks doubling the pairs give the findings "
                                         "neither confirmed nor bounded below 10 points more, up to this many."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, show_default=False,
                                       help="Seed of the fresh draws (default: the spec's)."),
    wait: float = typer.Option(0.0, help="Seconds to wait for another command holding the store's lock."),
) -> None:
    """Test each significant finding of the last run on fresh renders: twins inside and outside its
    region, matched on every other parameter, never an image of the run; confirmed, not replicated (the effect
    bounded below 10 points) or inconclusive."""
    from sweep3d.api import Experiment
    from sweep3d.cli.confirming import print_confirmation
    from sweep3d.followups.confirm import confirm as confirm_findings
    from sweep3d.results import DEFAULT_RENDERS

    check_wait(wait)
    experiment = Experiment(spec)
    require_store(experiment.spec)
    signal.signal(signal.SIGTERM, _interrupt)
    result = confirm_findings(experiment.spec, renders or DEFAULT_RENDERS, seed, console, wait=wait,
                              max_renders=max_renders)
    print_confirmation(console, result)
    if result.failed:
        raise typer.Exit(1)


@command
def sheet(
    spec: Path = SpecArg,
    output: Optional[Path] = typer.Option(None, "--output", "-o", help="PNG file to write."),
    object_name: Optional[str] = typer.Option(None, "--object", help="The object every row shows (default: the "
                                                                     "spec's first)."),
    environment: Optional[str] = typer.Option(None, "--environment", help="The environment every row shows "
                                                                          "(default: the spec's first)."),
    tiles: int = typer.Option(8, min=0, help="The most tiles a row shows, evenly spread over its values (0: all)."),
    wait: float = typer.Option(0.0, help="Seconds to wait for another command holding the store's lock."),
) -> None:
    """Render a contact sheet: one row per control, showing its effect alone on one scene.

    A range is shown at the spec's own grid when its policy is a grid, else at five points.
    """
    import sweep3d
    from sweep3d.cache import Store
    from sweep3d.driver import RunProgress
    from sweep3d.report import contact_sheet

    check_wait(wait)
    loaded = sweep3d.load(spec).spec
    target = output or Store(loaded.store).report_path(loaded.name, "-controls.png")
    with RunProgress(console) as progress:
        sheet = contact_sheet(loaded, target, progress, object_name, environment, tiles, wait)
    console.print(f"contact sheet of {escape(sheet.object)} in {escape(sheet.environment)}: [bold]{escape(str(sheet.path))}[/]")
    for control, shown, total in sheet.sampled:
        console.print(f"{escape(control)}: {shown} of its {total} values shown, evenly spread (--tiles {total} shows all)")


@command
def query(
    spec: Path = SpecArg,
    sql: str = typer.Argument(..., help="A SELECT over the views results, jobs, predictions, renders, images, runs."),
    output: Optional[Path] = typer.Option(None, "--output", "-o", help="Write all rows to .csv, .json or .parquet."),
    limit: int = typer.Option(50, help="Rows to print (all rows go to --output)."),
    model: Optional[str] = ModelOption,
    form: str = typer.Option("auto", "--format", help="How rows print: table, records (one 'column: value' "
                                                          "block per row), csv, json; auto: a table when it fits "
                                                          "the terminal, else records. Values are never cut."),
) -> None:
    """Answer SQL over the store with DuckDB, read-only: only --output writes a file."""
    from sweep3d.api import Experiment
    from sweep3d.results import results_connection, select_only

    experiment = Experiment(spec)
    statement = select_only(sql)
    require_store(experiment.spec)
    export = _export_target(output, experiment.store) if output is not None else None
    with results_connection(experiment.spec, model, writable=[export[0]] if export else [],
                            statement=statement) as con:
        if export is not None:
            _export(con, statement, output, *export)
        else:
            _print_rows(con.execute(statement), limit, form)
    if export is not None:
        console.print(f"wrote {output}")


@command
def export(
    spec: Path = SpecArg,
    form: str = typer.Option(..., "--format", show_default=False,
                             help="coco (images, boxes and masks from the mask pass), imagefolder (a folder per "
                                  "class), parquet (Hugging Face's layout: image bytes and every column of results), "
                                  "or module:Name, your own DatasetWriter in module.py beside the spec."),
    where: Optional[str] = typer.Option(None, "--where", show_default=False,
                                        help="Which results: a condition over the columns of results, e.g. "
                                             "\"NOT correct AND object = 'mug'\" (default: NOT correct, the failures)."),
    output: Optional[Path] = typer.Option(None, "--output", "-o", show_default=False,
                                          help="The export's folder: new or empty (default: "
                                               "exports/<experiment>-<format> beside the spec)."),
    model: Optional[str] = ModelOption,
    unevaluable: str = typer.Option("skip", "--unevaluable", help="Jobs that are not evaluable (too little of the "
                                    "object visible): skip them, or flag them (attribute evaluable: false)."),
    append: bool = typer.Option(False, "--append", help="Add to the export of the same format in --output: results "
                                "it holds already are skipped, ids continue after its largest."),
    link: bool = typer.Option(False, "--link", help="Hard-link image files to the store's blobs instead of copying "
                              "them (where the file system allows; coco and imagefolder)."),
) -> None:
    """Export a run's results (by default its failures) as a dataset, with design.csv: the
    configurations that made them, one row per image, to render them again later."""
    from sweep3d.api import Experiment
    from sweep3d.export import export_dataset

    loaded = Experiment(spec).spec
    result = export_dataset(loaded, form, output=output, where=where, model=model,
                            unevaluable=unevaluable, append=append, link=link, console=console)
    console.print(escape(result.line()), soft_wrap=True)


PRINT_FORMATS = ("auto", "table", "records", "csv", "json")


def _print_rows(cursor, limit: int, form: str = "auto") -> None:
    """``cursor``'s rows in ``form`` (see ``query --format``), every value whole and as text (never
    read as markup; control characters shown escaped). A table or records show the first ``limit``
    rows and say on stderr when there are more; CSV and JSON, for pipes, hold every row."""
    if form not in PRINT_FORMATS:
        raise UserError(f"--format {form!r}: use one of {', '.join(PRINT_FORMATS)}")
    columns = [d[0] for d in cursor.description or []]
    if form in ("csv", "json"):
        _print_plain(columns, cursor.fetchall(), form)
        return
    rows = cursor.fetchmany(limit + 1)
    shown = rows[:limit]
    table = Table(*(Column(header=Text(visible(c)), overflow="fold") for c in columns))  # wrap, never cut
    for row in shown:
        table.add_row(*[Text(visible(_cell(v))) for v in row])
    fits = console.measure(table).minimum <= console.width and all(
        len(c) <= max(console.width // max(len(columns), 1) - 3, 1) for c in columns)
    if form == "auto" and fits or form == "table" and console.measure(table).minimum <= console.width and fits:
        console.print(table)
    elif form == "table":  # too wide for one table: a table per group of columns that fits, never a grid of slivers
        _print_folded(columns, [[Text(visible(_cell(v))) for v in row] for row in shown])
    else:
        _print_records(columns, shown)
    if len(rows) > limit:
        err_console.print(f"[dim]first {limit} rows shown; --limit N or --output FILE for more[/]")


def _print_folded(columns: list[str], cells: list[list[Text]]) -> None:
    """``cells`` as several tables, each of as many columns as fit the terminal whole (headers
    unbroken where the terminal allows), each row numbered so the tables line up."""
    number = len(str(len(cells)))
    room = console.width - (number + 3) - 1  # the row number's column and the table's left edge
    need = [max([len(visible(c)), *(len(line) for row in cells for line in row[i].plain.splitlines())]) + 3
            for i, c in enumerate(columns)]
    groups: list[list[int]] = [[]]
    for i, width in enumerate(need):
        if groups[-1] and sum(need[j] for j in groups[-1]) + width > room:
            groups.append([])
        groups[-1].append(i)
    for group in groups:
        title = (f"column {group[0] + 1}" if len(group) == 1 else f"columns {group[0] + 1}–{group[-1] + 1}") + \
            f" of {len(columns)}"
        table = Table(Column(header="#", style="dim", justify="right"),
                      *(Column(header=Text(visible(columns[i])), overflow="fold") for i in group),
                      title=title, title_justify="left", title_style="dim")
        for n, row in enumerate(cells, start=1):
            table.add_row(str(n), *(row[i] for i in group))
        console.print(table)


def _print_records(columns: list[str], rows: list[tuple]) -> None:
    """One block per row, ``column: value`` per line (for rows wider than the terminal)."""
    width = max((len(c) for c in columns), default=0)
    for i, row in enumerate(rows):
        console.print(f"[dim]-- row {i + 1}[/]", highlight=False)
        for column, value in zip(columns, row):
            console.print(Text(f"{visible(column.rjust(width))}: {visible(_cell(value, whole=True))}"),
                          highlight=False, soft_wrap=True)


_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")  # control characters but tab and newline


def visible(text: str) -> str:
    """``text`` with its control characters (an ANSI escape's ESC, a bell) written as ``\\x1b``: a
    value from the data reaches the terminal as text, never as a command to it."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


def _print_plain(columns: list[str], rows: list[tuple], form: str) -> None:
    """Rows as CSV or JSON on stdout, full precision, for pipes."""
    import csv
    import io
    import json

    if form == "json":  # JSON escapes control characters itself
        typer.echo(json.dumps([dict(zip(columns, row)) for row in rows], default=str, indent=1))
        return
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows(["" if v is None else v for v in row] for row in rows)
    text = buffer.getvalue()
    # a pipe gets the values as they are (typer.echo would strip what looks like colour codes)
    sys.stdout.write(visible(text) if sys.stdout.isatty() else text)


EXPORT_FORMATS = {".csv": "FORMAT CSV, HEADER", ".json": "FORMAT JSON, ARRAY true", ".parquet": "FORMAT PARQUET"}


def _export_target(output: Path, store: Path) -> tuple[Path, str]:
    """(the temp file an export writes before it is renamed to ``output``, its COPY options).

    Raises:
        UserError: the suffix is not a format we write, ``output`` is inside the ``store`` (whose
            files only sweep3d writes: an export there would replace or add a table), or the
            folder cannot be created.
    """
    suffix = output.suffix.lower()
    if Path(os.path.realpath(output)).is_relative_to(os.path.realpath(store)):
        raise UserError(f"--output {output}: inside the store {store}, whose files only sweep3d writes; "
                        "write it to another folder")
    if suffix not in EXPORT_FORMATS:
        raise UserError(f"--output {output}: unsupported format {suffix or '(none)'!r}; use .csv, .json or .parquet")
    try:
        output.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--output {output}: cannot create its folder ({exc.strerror})") from None
    return output.with_name(f".{output.name}.{uuid.uuid4().hex}.tmp").absolute(), EXPORT_FORMATS[suffix]


def _export(con, statement: str, output: Path, tmp: Path, options: str) -> None:
    """Write every row of ``statement`` to ``output``, whole or not at all (temp file, rename).

    The connection may write only ``tmp``; the newlines keep a trailing ``--`` comment in the
    statement from swallowing the closing parenthesis.
    """
    import duckdb

    from sweep3d.cache import full_disk_error, is_full_disk

    target = str(tmp).replace("'", "''")
    try:
        try:
            con.execute(f"COPY (\n{statement}\n) TO '{target}' ({options}, USE_TMP_FILE false)")
        except duckdb.IOException as exc:  # writing the file (not the SQL: no hint about the query)
            if "No space left on device" in str(exc):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)) from None
            if str(tmp) in str(exc):
                raise OSError(errno.EIO, str(exc).splitlines()[0]) from None
            raise  # reading the store: the connection says it
        os.replace(tmp, output)
    except OSError as exc:
        if is_full_disk(exc):
            raise full_disk_error(exc, f"write --output {output}", output.parent,
                                  "write it to another disk") from None
        raise UserError(f"--output {output}: cannot write it ({exc.strerror})") from None
    finally:
        tmp.unlink(missing_ok=True)


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def _cell(value, whole: bool = False) -> str:
    """A value as the table shows it: floats to 4 significant digits (``whole``: all of them)."""
    if isinstance(value, float):
        return repr(value) if whole else f"{value:.4g}"
    return "" if value is None else str(value)


def _write_report(experiment: Experiment, output: Optional[Path], model: Optional[str] = None) -> None:
    path = experiment.report(output, model)
    console.print(f"report: [bold]{path}[/]")


def main() -> None:
    """The command line, ending with ``SystemExit`` as any click application does (tests call it)."""
    from sweep3d.cache import skip_pandas_probe

    skip_pandas_probe()
    app()


def console_main() -> None:
    """The ``sweep3d`` command and ``python -m sweep3d``: :func:`main`, then an exit that skips
    the interpreter's teardown (:mod:`.quick_exit`). An exception no command caught (a bug) goes
    on to Python's own handling, traceback and all."""
    from sweep3d.cli.quick_exit import exit_now

    try:
        main()
    except SystemExit as exc:
        exit_now(exc.code)
    exit_now(0)


def _register_subcommands() -> None:
    from sweep3d.cli.cache import cache_app

    app.add_typer(cache_app, name="cache")
    from sweep3d.cli.realism import realism_app

    app.add_typer(realism_app, name="realism")


_register_subcommands()
