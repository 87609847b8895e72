"""What ``sweep3d explain`` keeps in the store: a Parquet file per experiment under ``explain/``
(:func:`sweep3d.results.counterfactuals_path`), rewritten whole by each explain run. It is no
table of the store (no key per row, no segments); declaring its folder tells the store that a
folder holding it is a store's. The package root names this module.
"""

from __future__ import annotations

from sweep3d.cache import register_store_folder

FOLDER = "explain"
register_store_folder(FOLDER)
