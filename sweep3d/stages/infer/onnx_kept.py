"""Exported ONNX graphs and their checks against torch, kept so that a runner needs neither again.

An export depends on the model (its digest names the file) and the torch that made it; whether
ONNX Runtime's answers are close enough to torch's depends on the graph's bytes, both releases and
the CPU they run on. So a check's outcome (the error it measured) is kept under exactly those
(:func:`check_name`), beside the graph in the store's ``models/``; both are also kept in the
user's cache folder (:func:`user_folder`), from which a fresh store takes them. Everything here is
a cache: a file that is missing, unreadable or for another graph means an export or a check, never
a wrong answer.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
from functools import lru_cache
from importlib import metadata
from pathlib import Path

from sweep3d.cache import StoreWriteError, atomic_write

#: Where the user's cache folder is (default ``$XDG_CACHE_HOME/sweep3d``, else ``~/.cache/sweep3d``);
#: ``off`` keeps nothing outside the stores.
CACHE_VARIABLE = "SWEEP3D_CACHE"


def user_folder() -> Path | None:
    """The user's folder of kept ONNX graphs and checks, or None when the user turned it off."""
    chosen = os.environ.get(CACHE_VARIABLE)
    if chosen is not None:
        return None if chosen.strip().lower() in ("", "off") else Path(chosen).expanduser() / "onnx"
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "sweep3d" / "onnx"


def fetch(path: Path) -> bool:
    """Copy the graph named like ``path`` from the user's folder into ``path``; False when none is kept."""
    folder = user_folder()
    kept = folder / path.name if folder is not None else None
    if kept is None or not kept.is_file():
        return False
    try:
        _copy(kept, path)
        return True
    except OSError:
        return False


def keep(path: Path) -> None:
    """Keep the graph at ``path`` in the user's folder too (quietly not, where it cannot be written)."""
    folder = user_folder()
    if folder is not None:
        try:
            _copy(path, folder / path.name)
        except OSError:
            pass


def checked_error(path: Path, providers: list[str]) -> float | None:
    """The error the check measured for the graph at ``path`` on these providers, releases and
    CPU, kept in the store or in the user's folder; None when it was never checked so."""
    name = check_name(path, providers)
    for folder in (path.parent, user_folder()):
        if folder is None:
            continue
        try:
            error = json.loads((folder / name).read_text())["error"]
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if isinstance(error, float) and 0 < error < 1:
            if folder != path.parent:
                keep_check(path, providers, error, user=False)
            return error
    return None


def keep_check(path: Path, providers: list[str], error: float, user: bool = True) -> None:
    """Keep a check's outcome beside the graph (and in the user's folder)."""
    data = json.dumps({"error": error, "graph": path.name, "versions": _versions(), "providers": providers}).encode()
    name = check_name(path, providers)
    for folder in (path.parent, user_folder() if user else None):
        if folder is not None:
            try:
                _write(folder / name, data)
            except OSError:
                pass


def check_name(path: Path, providers: list[str]) -> str:
    """The file name of a check of the graph at ``path``: its bytes, the releases, providers and CPU."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    h.update(json.dumps([_versions(), providers, _cpu()]).encode())
    return f"{path.stem}.check-{h.hexdigest()[:24]}.json"


@lru_cache(maxsize=1)
def _versions() -> dict[str, str]:
    """The releases whose arithmetic the check compared (read without importing them)."""
    return {name: metadata.version(name) for name in ("torch", "onnxruntime", "numpy")}


@lru_cache(maxsize=1)
def _cpu() -> str:
    """What the CPU is (kernels are chosen by its instruction sets): its model and flags on Linux."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.platform() + platform.processor()
    first = text.split("\n\n", 1)[0]
    wanted = [line for line in first.splitlines() if line.split(":")[0].strip() in ("model name", "flags", "Features")]
    return platform.machine() + "|" + "|".join(wanted)


def _copy(source: Path, target: Path) -> None:
    """Copy ``source`` to ``target`` whole or not at all (readers never see half a graph)."""
    _write(target, source.read_bytes())


def _write(target: Path, data: bytes) -> None:
    try:
        atomic_write(target, data, durable=False)  # a torn file is a different graph: checked again
    except StoreWriteError as exc:  # a full or read-only disk: only a cache, said by the caller's OSError
        raise OSError(str(exc)) from None
