"""How every command reports a user's mistake (one red line on stderr, exit code 2) and a failed
render worker (one line, exit code 1); how a command that reads results refuses a store that
does not exist."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Callable

import typer
from rich.console import Console
from rich.markup import escape

from sweep3d.api import check_wait
from sweep3d.core import RenderError, UserError, plugin_failure

if TYPE_CHECKING:
    from sweep3d.spec import LoadedSpec

__all__ = ["check_wait", "registrar", "require_store"]  # check_wait: the API's, for the commands' --wait

err_console = Console(stderr=True, highlight=False)
DEBUG = {"on": False}  # set by ``sweep3d --debug``: a failing plug-in's traceback is printed too


def registrar(app: typer.Typer) -> Callable[[Callable], Callable]:
    """A decorator registering commands on ``app`` whose user errors print one line and exit 2
    (render errors: exit 1)."""

    def command(func: Callable) -> Callable:
        @functools.wraps(func)
        def wrapper(*args, **kwargs):
            try:
                return _exits_as_errors(func, *args, **kwargs)
            except UserError as exc:
                if DEBUG["on"] and getattr(exc, "details", ""):  # a plug-in's traceback, on request
                    err_console.print(escape(exc.details), highlight=False, soft_wrap=True)
                err_console.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)
                raise typer.Exit(exc.exit_code) from None
            except RenderError as exc:  # not the user's mistake, but one line all the same
                err_console.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)
                raise typer.Exit(1) from None
            except KeyboardInterrupt:
                err_console.print("[yellow]interrupted[/]: everything finished so far is stored; run again to resume")
                raise typer.Exit(130) from None

        return app.command()(wrapper)

    return command


def require_store(spec: LoadedSpec) -> None:
    """Refuse, before anything is written, a command that reads results when ``spec``'s store does
    not exist: one line naming the store and ``sweep3d run SPEC``, exit 2, no folder made (a
    reader must leave the file system as it found it)."""
    if not spec.store.is_dir():
        from sweep3d.cache import Store
        from sweep3d.results import no_results

        raise no_results(Store(spec.store), spec.name, spec.path)


def _exits_as_errors(func: Callable, *args, **kwargs):
    """``func``'s result, a ``SystemExit`` escaping it raised as a PluginError instead. sweep3d's
    commands end with ``typer.Exit``, never ``SystemExit``, so one that escapes came from plug-in
    code that no boundary caught; passing it on would exit with its code, 0 as if all went well.
    The one exception is rich's own exit when the reader of a pipe went away (``query … | head``)."""
    try:
        return func(*args, **kwargs)
    except SystemExit as exc:
        if _raised_in(exc, "on_broken_pipe"):
            raise
        raise plugin_failure("a plug-in", exc) from None


def _raised_in(exc: BaseException, function: str) -> bool:
    """Whether ``exc`` was raised by a function named ``function`` (its innermost frame)."""
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    return tb is not None and tb.tb_frame.f_code.co_name == function
