"""Progress of long stages: counts, cache hits, failures and rate.

A stage's count is of every key it needs in the pass, the cached ones counted done from the start
(``render: 14/28 (14 cached, 0 failed)``, then ``28/28``): a count never says fewer done than cached.
The rate and the time left are of what is computed.

On a terminal, Rich progress bars; when the output is not a terminal (a pipe, a log file, CI),
where bars would show only at the end, one plain line per running stage every
:data:`PLAIN_EVERY` seconds, and each stage's last line when it ends.
"""

from __future__ import annotations

import datetime
import threading
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


def computed(task: Task) -> float:
    """What ``task`` has computed so far (its count less the cached keys it started from)."""
    return task.completed - task.fields.get("cached", 0)


class RateColumn(ProgressColumn):
    """Items computed per second over the stage so far."""

    def render(self, task: Task) -> Text:
        elapsed = task.finished_time if task.finished else task.elapsed
        if not elapsed or not computed(task):
            return Text("     -/s", style="cyan")
        return Text(f"{computed(task) / elapsed:6.2f}/s", style="cyan")


class StageProgress:
    """One stage's bar: ``advance`` for computed items; cache hits are shown beside the count."""

    def __init__(self, progress: Progress | None, task: TaskID | None) -> None:
        self._progress, self._task = progress, task
        self.failed = 0

    def advance(self, n: int = 1, failed: bool = False) -> None:
        self.failed += int(failed)
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, advance=n, failed=self.failed)


#: Seconds between progress lines when the output is not a terminal.
PLAIN_EVERY = 10.0


def plain_line(task: Task) -> str:
    """One stage's progress as plain text: ``render: 120/264 (0 cached, 0 failed), 4.12/s, 0:00:29 elapsed,
    about 0:00:35 left`` (the count includes the cached keys; the rate is of those computed)."""
    elapsed = task.finished_time if task.finished else task.elapsed
    line = (f"{task.description}: {int(task.completed)}/{int(task.total or 0)} ({task.fields.get('cached', 0)} cached, "
            f"{task.fields.get('failed', 0)} failed)")
    done = computed(task)
    if elapsed and done:
        line += f", {done / elapsed:.2f}/s, {datetime.timedelta(seconds=int(elapsed))} elapsed"
        if not task.finished and task.total:
            left = (task.total - task.completed) * elapsed / done
            line += f", about {datetime.timedelta(seconds=int(left))} left"
    return line


class RunProgress:
    """A rich Progress shared by the stages of one run (silent when ``console`` is None; plain
    lines at a steady interval when the console is not a terminal)."""

    def __init__(self, console: Console | None, every: float = PLAIN_EVERY) -> None:
        self.console = console
        self.plain = console is not None and not console.is_terminal
        self.every = every
        self._stop = threading.Event()
        self._printer: threading.Thread | None = None
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
                disable=self.plain,  # the tasks are still counted: the plain lines read them
            )
            if console is not None
            else None
        )

    def __enter__(self) -> "RunProgress":
        if self.progress is not None:
            self.progress.start()
        if self.plain:
            self._printer = threading.Thread(target=self._print_lines, name="sweep3d-progress", daemon=True)
            self._printer.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.progress is not None:
            self.progress.stop()
        if self._printer is not None:
            self._stop.set()
            self._printer.join()

    def _print_lines(self) -> None:
        """Every ``every`` seconds, a line per stage still running (stages end with their own line)."""
        while not self._stop.wait(self.every):
            for task in list(self.progress.tasks):
                if task.started and task.stop_time is None:
                    self.console.print(plain_line(task), markup=False, highlight=False, soft_wrap=True)

    @contextmanager
    def stage(self, name: str, total: int, cached: int) -> Iterator[StageProgress]:
        """A bar for a stage that computes ``total`` keys and finds ``cached`` more stored: it
        counts to ``total + cached``, starting from ``cached``."""
        if self.progress is None:
            yield StageProgress(None, None)
            return
        task = self.progress.add_task(name, total=total + cached, completed=cached, cached=cached, failed=0)
        try:
            yield StageProgress(self.progress, task)
        finally:
            self.progress.stop_task(task)
            if self.plain:
                done = next(t for t in self.progress.tasks if t.id == task)
                self.console.print(plain_line(done), markup=False, highlight=False, soft_wrap=True)
