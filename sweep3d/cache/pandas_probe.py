"""Keep pyarrow from importing pandas only to ask whether a list is a pandas object.

The first time pyarrow converts a Python sequence (``pa.array(list)``, ``pa.table(dict)``) it
imports pandas to check whether the sequence is a pandas Series or Index: 0.25–0.5 s that every
``sweep3d`` command which writes or compares keys would pay, although sweep3d never hands pyarrow
a pandas object. :func:`skip_pandas_probe` lets that first check find no pandas, and leaves
pandas importable: pyarrow's conversions that need it (``Table.to_pandas``, used by
:meth:`sweep3d.Experiment.dataframe`) import it when they are called.

Only the command line calls it (the process is sweep3d's own): a Python program that imports
sweep3d keeps pyarrow's behaviour unchanged.
"""

from __future__ import annotations

import sys


def skip_pandas_probe() -> None:
    """Make pyarrow's first "is this a pandas object?" check find no pandas (call it before
    anything converts a Python sequence to Arrow; later calls do nothing)."""
    if "pandas" in sys.modules:  # already imported: pyarrow finds it at no cost
        return
    import pyarrow as pa

    blocker = _NoPandas()
    sys.meta_path.insert(0, blocker)  # an import of pandas now fails at once
    try:
        pa.array([0])  # the probe runs once per process: it now records "no pandas"
    finally:
        sys.meta_path.remove(blocker)


class _NoPandas:
    """An import finder that fails the import of pandas (and only that)."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> None:
        if name == "pandas" or name.startswith("pandas."):
            raise ImportError("pandas is not probed for")
        return None
