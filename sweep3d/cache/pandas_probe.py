"""Keep pyarrow from importing pandas only to ask whether a list is a pandas object.

The first time pyarrow converts a Python sequence (``pa.array(list)``, ``pa.table(dict)``) it
imports pandas to check whether the sequence is a pandas Series or Index: 0.25–0.5 s that every
``sweep3d`` command which writes or compares keys would pay, although sweep3d never hands pyarrow
a pandas object. :func:`skip_pandas_probe` lets that first check find no pandas, and watches for
pandas: once anything imports it (a user's plug-in, ``Experiment.dataframe``), pyarrow is made to
look again, so a pandas Series converts exactly as it would have (its nulls, its categories).

Only the command line calls it (the process is sweep3d's own): a Python program that imports
sweep3d keeps pyarrow's behaviour unchanged.
"""

from __future__ import annotations

import sys
from importlib.machinery import ModuleSpec
from types import ModuleType
from typing import Any

_skipped = False


def skip_pandas_probe() -> None:
    """Make pyarrow's first "is this a pandas object?" check find no pandas, until pandas is
    imported (call it before anything converts a Python sequence to Arrow; once per process)."""
    global _skipped
    if _skipped or "pandas" in sys.modules:  # done already, or imported: pyarrow finds it at no cost
        return
    import pyarrow as pa

    blocker = _NoPandas()
    sys.meta_path.insert(0, blocker)  # an import of pandas now fails at once
    try:
        pa.array([0])  # the probe runs once per process: it now records "no pandas"
    finally:
        sys.meta_path.remove(blocker)
    sys.meta_path.insert(0, _LookAgainAfterPandas())
    _skipped = True


class _NoPandas:
    """An import finder that fails the import of pandas (and only that)."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> None:
        if name == "pandas" or name.startswith("pandas."):
            raise ImportError("pandas is not probed for")
        return None


class _LookAgainAfterPandas:
    """An import finder that finds pandas as the others do, with a loader that, once pandas has
    run, has pyarrow look for it again (pyarrow would otherwise keep the probe's "no pandas")."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> ModuleSpec | None:
        if name != "pandas":
            return None
        for finder in list(sys.meta_path):  # as the import system would, without this finder
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is not None:
                if spec.loader is not None and hasattr(spec.loader, "exec_module"):
                    spec.loader = _ThenLookAgain(spec.loader, self)  # this spec's own: a shared loader stays as it is
                return spec
        return None

    def done(self) -> None:
        """Leave the import system: pandas is imported and pyarrow knows it."""
        try:
            sys.meta_path.remove(self)
        except ValueError:  # another thread's import of pandas came first
            pass


class _ThenLookAgain:
    """pandas' own loader (everything is asked of it), that tells pyarrow once pandas has run."""

    def __init__(self, loader: Any, finder: _LookAgainAfterPandas) -> None:
        self._loader = loader
        self._finder = finder

    def create_module(self, spec: ModuleSpec) -> ModuleType | None:
        create = getattr(self._loader, "create_module", None)
        return create(spec) if create is not None else None

    def exec_module(self, module: ModuleType) -> None:
        self._loader.exec_module(module)
        self._finder.done()
        try:
            import pyarrow as pa

            pa.lib._pandas_api.compat  # noqa: B018  (pyarrow's shim imports pandas' parts now: it is there)
        except Exception:  # noqa: BLE001  (a pandas pyarrow refuses: as without the probe, it is not used)
            pass

    def __getattr__(self, name: str) -> Any:
        return getattr(self._loader, name)
