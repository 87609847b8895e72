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

import importlib.util
import sys
from importlib.machinery import ModuleSpec
from types import ModuleType


def skip_pandas_probe() -> None:
    """Make pyarrow's first "is this a pandas object?" check find no pandas, until pandas is
    imported (call it before anything converts a Python sequence to Arrow)."""
    if "pandas" in sys.modules:  # already imported: pyarrow finds it at no cost
        return
    import pyarrow as pa

    blocker = _NoPandas()
    sys.meta_path.insert(0, blocker)  # an import of pandas now fails at once
    try:
        pa.array([0])  # the probe runs once per process: it now records "no pandas"
    finally:
        sys.meta_path.remove(blocker)
    sys.meta_path.insert(0, _LookAgainAfterPandas())


class _NoPandas:
    """An import finder that fails the import of pandas (and only that)."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> None:
        if name == "pandas" or name.startswith("pandas."):
            raise ImportError("pandas is not probed for")
        return None


class _LookAgainAfterPandas:
    """An import finder that, when pandas is first imported, lets the import run as usual and
    then has pyarrow look for pandas again (it would otherwise keep the probe's "no pandas")."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> ModuleSpec | None:
        if name != "pandas":
            return None
        sys.meta_path.remove(self)  # once: the other finders now find pandas as usual
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        loader, run = spec.loader, spec.loader.exec_module

        def exec_module(module: ModuleType) -> None:
            run(module)
            import pyarrow as pa

            pa.lib._pandas_api.compat  # noqa: B018  (pyarrow's shim imports pandas' parts now: it is there)

        loader.exec_module = exec_module  # type: ignore[method-assign]
        return spec
