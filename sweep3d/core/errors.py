"""Errors a user can fix. The CLI prints them as one line and exits with code 2."""

from __future__ import annotations


class UserError(Exception):
    """A mistake in a spec, a path or a command line; the message says how to fix it."""

    exit_code = 2


class SpecError(UserError):
    """A spec file is malformed: the message names the file, the key path and what is expected."""

    def __init__(self, file: str, key: str, problem: str) -> None:
        self.file, self.key, self.problem = file, key, problem
        where = f"{file}: {key}" if key else file
        super().__init__(f"{where}: {problem}")


class StoreBusyError(UserError):
    """Another sweep3d process holds the store's writer lock."""


class RenderError(RuntimeError):
    """Blender failed on a job in a way the spec did not cause (a crashed worker, a bpy error)."""


class PluginError(UserError):
    """A user's plug-in (a control, policy, evaluator or model factory) failed or misbehaved.

    The message is one line naming the plug-in, the file and line where it failed and the
    exception; ``details`` keeps the traceback, which the CLI prints with ``--debug``.
    """

    def __init__(self, message: str, details: str = "") -> None:
        super().__init__(message)
        self.details = details


#: What a plug-in's code may raise that is its failure: any exception, and an exit. ``sys.exit``
#: in a plug-in would otherwise end sweep3d with the plug-in's code, 0 as if all went well (CI
#: would see success with nothing run). Not KeyboardInterrupt: Ctrl-C stays the user's way out.
PLUGIN_FAILURES: tuple[type[BaseException], ...] = (Exception, SystemExit)


def exit_call(exc: SystemExit) -> str:
    """How a plug-in exited, as the user wrote it: ``sys.exit(0)``, ``sys.exit()`` (no code, or
    ``raise SystemExit``), ``sys.exit('done')``."""
    return "sys.exit()" if exc.code is None else f"sys.exit({exc.code!r})"


def plugin_failure(plugin: str, exc: BaseException, doing: str = "failed", during: str = "") -> PluginError:
    """A :class:`PluginError` for ``exc`` raised inside ``plugin`` (e.g. ``"control mymod:Liquid"``),
    located at the innermost frame of the traceback in the user's code (outside sweep3d, the
    standard library and installed packages).

    An exit (``SystemExit``, any code) says so instead of ``doing``: ``plugin (file:line) called
    sys.exit(0) {during}``, e.g. ``during="in apply()"``.
    """
    import sysconfig
    import traceback
    from pathlib import Path

    library = (str(Path(__file__).resolve().parent), *{sysconfig.get_paths()[k] for k in ("stdlib", "purelib", "platlib")})
    frames = traceback.extract_tb(exc.__traceback__)
    own = [f for f in frames if not str(Path(f.filename).resolve()).startswith(library)]
    where = f" ({Path(own[-1].filename).name}:{own[-1].lineno})" if own else ""
    details = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    if isinstance(exc, SystemExit):
        when = f" {during}" if during else ""
        return PluginError(f"{plugin}{where} called {exit_call(exc)}{when}; a plug-in must not end sweep3d: "
                           "raise an exception to fail", details)
    problem = " ".join(f"{type(exc).__name__}: {exc}".split())
    return PluginError(f"{plugin}{where} {doing}: {problem}", details)
