"""Rich progress bars for long stages: counts, cache hits, failures and rate."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    SpinnerColumn,
    Task,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text


class RateColumn(ProgressColumn):
    """Items per second over the stage so far."""

    def render(self, task: Task) -> Text:
        elapsed = task.finished_time if task.finished else task.elapsed
        if not elapsed or not task.completed:
            return Text("     -/s", style="cyan")
        return Text(f"{task.completed / elapsed:6.2f}/s", style="cyan")


class StageProgress:
    """One stage's bar: ``advance`` for computed items; cache hits are shown beside the count."""

    def __init__(self, progress: Progress | None, task: TaskID | None) -> None:
        self._progress, self._task = progress, task
        self.failed = 0

    def advance(self, n: int = 1, failed: bool = False) -> None:
        self.failed += int(failed)
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, advance=n, failed=self.failed)


class RunProgress:
    """A rich Progress shared by the stages of one run (silent when ``console`` is None)."""

    def __init__(self, console: Console | None) -> None:
        self.console = console
        self.progress = (
            Progress(
                SpinnerColumn(),
                TextColumn("[bold]{task.description:<12}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("[green]{task.fields[cached]} cached[/] [red]{task.fields[failed]} failed[/]"),
                RateColumn(),
                TimeElapsedColumn(),
                TimeRemainingColumn(),
                console=console,
                transient=False,
            )
            if console is not None
            else None
        )

    def __enter__(self) -> "RunProgress":
        if self.progress is not None:
            self.progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.progress is not None:
            self.progress.stop()

    @contextmanager
    def stage(self, name: str, total: int, cached: int) -> Iterator[StageProgress]:
        if self.progress is None:
            yield StageProgress(None, None)
            return
        task = self.progress.add_task(name, total=total, cached=cached, failed=0)
        try:
            yield StageProgress(self.progress, task)
        finally:
            self.progress.stop_task(task)
