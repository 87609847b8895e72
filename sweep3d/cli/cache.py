"""``sweep3d cache``: verify (and repair), gc, compact and stats for the store a spec points at.

Commands that change the store take its writer lock (``--wait`` as for ``run``); ``verify``
without ``--repair`` and ``stats`` only read it.
"""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from sweep3d.cli._commands import check_wait, registrar, require_store

cache_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help="Check and tidy a spec's store: verify, gc, compact, stats.")
console = Console(highlight=False)  # values from data print as text: no colouring of what looks like numbers or paths

SpecArg = typer.Argument(..., help="Path to a spec whose store to work on.", show_default=False,
                         readable=False)  # the loader says why it cannot read one, in one line
WaitOption = typer.Option(0.0, help="Seconds to wait for a run holding the store's lock.")
MAX_LISTED = 20  # problems printed one per line; the rest are counted


command = registrar(cache_app)


def _store_root(spec: Path) -> Path:
    import sweep3d

    loaded = sweep3d.load(spec).spec
    require_store(loaded)
    return loaded.store


@command
def verify(
    spec: Path = SpecArg,
    repair: bool = typer.Option(False, "--repair", help="Quarantine corrupt files and drop their rows, "
                                "so the next run recomputes them (files it cannot read stay as they are)."),
    wait: float = WaitOption,
) -> None:
    """Re-read every segment and re-hash every blob, kept model output and extracted mesh, check
    every file a table's rows keep (decode every kept photo); report corrupt, missing or unreadable
    ones (exit 2 if any)."""
    from sweep3d.cache import Store
    from sweep3d.cache import repair as repair_store
    from sweep3d.cache import verify as verify_store

    check_wait(wait)
    root = _store_root(spec)
    with Store(root).lock(wait) if repair else nullcontext():  # a repair writes: its lock before the hashing
        report = verify_store(root)
        kept = "".join(f", {n} kept {files.noun}s" for files, n in report.kept.items() if n)
        console.print(f"checked {report.segments} segments ({report.rows} rows), {report.blobs} blobs{kept}, "
                      f"{report.outputs} kept model outputs and {report.assets} extracted meshes in "
                      f"{escape(str(root))}")
        _list(report.problems, root)
        if report.ok:
            console.print("[green]store OK[/]")
            return
        damaged = len(report.repairable)
        if not repair:
            if damaged:
                console.print(f"{damaged} problems; run: sweep3d cache verify {escape(str(spec))} --repair "
                              "(or the next run recomputes what it needs)")
            _unreadable(report)
            raise typer.Exit(2)
        if damaged:
            fixed = repair_store(root, report)
            console.print(f"repaired {fixed} problems: damaged files moved to quarantine/; the next run recomputes "
                          "their rows")
    if _unreadable(report):
        raise typer.Exit(2)


def _list(problems: list, root: Path) -> None:
    """One line per problem, the first :data:`MAX_LISTED`; the rest counted."""
    for problem in problems[:MAX_LISTED]:
        console.print(f"[red]{escape(problem.line(root))}[/]", highlight=False)
    if len(problems) > MAX_LISTED:
        console.print(f"[red]... and {len(problems) - MAX_LISTED} more[/]")


def _unreadable(report) -> int:
    """Say how many files the OS would not let sweep3d read (left as they are: they may be intact);
    their number."""
    n = len(report.problems) - len(report.repairable)
    if n:
        console.print(f"{n} files cannot be read (as listed: their permissions, or the disk), so they were not "
                      "checked; --repair leaves them and their rows as they are: fix them and verify again")
    return n


@command
def gc(
    spec: Path = SpecArg,
    older_than: float = typer.Option(3600.0, help="Remove temp files older than this many seconds."),
    purge_quarantine: bool = typer.Option(False, "--purge-quarantine", help="Also delete quarantined files."),
    wait: float = WaitOption,
) -> None:
    """Remove blobs no row references, kept photos no verdict names, leftover temp files and
    segments compaction replaced."""
    from sweep3d.cache import Store, collect_garbage

    check_wait(wait)
    root = _store_root(spec)
    with Store(root).lock(wait):
        out = collect_garbage(root, older_than, purge_quarantine)
    console.print(f"removed {out.blobs} unreferenced blobs, "
                  + "".join(f"{n} kept {files.noun}s {files.unnamed}, " for files, n in out.kept.items() if n)
                  + f"{out.temp_files} temp or compacted-away files"
                  + (f", {out.quarantined} quarantined files" if purge_quarantine else "")
                  + f" ({_bytes(out.bytes)})")


@command
def compact(spec: Path = SpecArg, wait: float = WaitOption) -> None:
    """Merge each table's segments into one (dropping duplicate rows); readers see no gap."""
    from sweep3d.cache import Store, compact_table, table_names

    check_wait(wait)
    root = _store_root(spec)
    store = Store(root)
    with store.lock(wait):
        done = [c for c in (compact_table(store, t) for t in table_names()) if c is not None]
    if not done:
        console.print("nothing to compact")
    for c in done:
        console.print(f"{c.table}: {c.segments_before} segments → 1 ({c.rows_before} rows → {c.rows_after})")


@command
def stats(spec: Path = SpecArg) -> None:
    """Files, rows, distinct keys and bytes per table, blobs, temp files and quarantine."""
    from sweep3d.cache import store_stats

    root = _store_root(spec)
    table = Table("table", "files", "rows", "keys", "size", title=escape(str(root)))
    total = 0
    for t in store_stats(root):
        total += t.bytes
        table.add_row(t.name, str(t.files), str(t.rows), str(t.keys), _bytes(t.bytes))
    table.add_row("[bold]total[/]", "", "", "", f"[bold]{_bytes(total)}[/]")
    console.print(table)


def _bytes(n: int) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TB"
