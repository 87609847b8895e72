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


class PluginError(UserError):
    """A user's plug-in (a policy, a control, ...) broke its contract: the message names it and says
    what it must do."""


class StoreBusyError(UserError):
    """Another sweep3d process holds the store's writer lock."""


class RenderError(RuntimeError):
    """Blender failed on a job in a way the spec did not cause (a crashed worker, a bpy error)."""
