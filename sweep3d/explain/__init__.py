"""``sweep3d explain``: the nearest change that fixes each failure (see :mod:`.search`, the pure
search, and :mod:`.driver`, which answers its probes through the stages)."""
