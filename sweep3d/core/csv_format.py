"""CSV cells that read back as the values written: the one rule the design table and exports share.

Empty for null, ``true``/``false`` for booleans (as DuckDB writes them), floats by ``repr`` (the
shortest text that parses back bit for bit), lists and tables as JSON.
"""

from __future__ import annotations

import csv
import io
import json
from typing import Any, Iterable


def cell(value: Any) -> str:
    """One CSV cell for ``value``."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, dict)):
        return json.dumps(value, allow_nan=False, ensure_ascii=False)
    return repr(value) if isinstance(value, float) else str(value)


def csv_text(columns: list[str], rows: Iterable[Iterable[Any]]) -> str:
    """A header and ``rows`` as CSV text (``\\n`` line ends), each value by :func:`cell`."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows([cell(v) for v in row] for row in rows)
    return buffer.getvalue()
