"""The modules that declare tables to the store, named by the package root and imported by the
registry (:mod:`sweep3d.cache.contracts`) when it first needs every table. Apart from it, so that
naming them costs every ``import sweep3d`` (a render worker's included) no import of its own."""

from __future__ import annotations

import importlib

_declared: list[str] = []  # modules that declare tables, not imported yet


def declare_table_modules(*modules: str) -> None:
    """Name modules that register tables (by :func:`~sweep3d.cache.contracts.register_table`) when
    imported; each is imported the first time the registry is asked for every table, or for one it
    does not know."""
    _declared.extend(m for m in modules if m not in _declared)


def load_declared() -> None:
    """Import the named modules not imported yet."""
    while _declared:
        importlib.import_module(_declared.pop(0))  # taken off first: one that asks the registry sees no loop
