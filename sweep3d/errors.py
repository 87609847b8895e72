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


def plugin_failure(plugin: str, exc: BaseException, doing: str = "failed") -> PluginError:
    """A :class:`PluginError` for ``exc`` raised inside ``plugin`` (e.g. ``"control mymod:Liquid"``),
    located at the innermost frame of the traceback in the user's code (outside sweep3d, the
    standard library and installed packages)."""
    import sysconfig
    import traceback
    from pathlib import Path

    library = (str(Path(__file__).resolve().parent), *{sysconfig.get_paths()[k] for k in ("stdlib", "purelib", "platlib")})
    frames = traceback.extract_tb(exc.__traceback__)
    own = [f for f in frames if not str(Path(f.filename).resolve()).startswith(library)]
    where = f" ({Path(own[-1].filename).name}:{own[-1].lineno})" if own else ""
    problem = " ".join(f"{type(exc).__name__}: {exc}".split())
    details = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    return PluginError(f"{plugin}{where} {doing}: {problem}", details)
