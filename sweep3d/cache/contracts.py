"""Table contracts: what the store knows of each table, declared by the package that writes it.

The store keeps keys, files and their integrity; what a table's rows mean is its writer's. A
:class:`TableContract` says what the store needs and no more: the table's name (its folder under
``tables/``), its key column, the columns every segment has had since it was first written, which
row of a key counts (the first written, or the newest), and optionally the files its rows name in
a folder of the store (:class:`KeptFiles`), which ``cache verify`` checks and ``cache gc`` keeps.

The pipeline's tables (renders, images, predictions, runs, parts, truths) are the store's own,
declared below. A package above the pipeline declares its table in its own package and registers
it (:func:`register_table`). So that every command sees every table, whichever packages it
happened to import, the package root names the modules that declare them
(:func:`~sweep3d.cache.declared.declare_table_modules`, a list of module names, no import): the registry imports them the
first time it is asked for every table, or for one it does not know. The cache layer thus names
no package above it, and imports none until a table of one is needed.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Literal

from sweep3d.cache.declared import load_declared

#: Which of a key's rows counts: the first written (a key names its inputs, so its rows are alike)
#: or the newest (a row written again replaces the earlier one).
Merge = Literal["first", "newest"]
MERGES = ("first", "newest")
_NAME = re.compile(r"[a-z_][a-z0-9_]*")  # a table's name and key: a folder, a view and a column in SQL


@dataclass(frozen=True)
class KeptFiles:
    """Files a table's rows name, each kept as ``<folder>/<value><suffix>`` under the store's root,
    ``value`` being the row's ``column``: the SHA-256 (64 hex digits) of the file it was made from.

    ``cache verify`` checks each one a row names with ``check``; ``cache gc`` removes those no row
    names (files of other names in the folder are the user's and stay); ``cache stats`` counts them.
    """

    folder: tuple[str, ...]  # under the store's root; its first part is a folder the store makes
    column: str
    suffix: str  # ".jpg"
    noun: str  # what one is, in words: "photo" (problems read "corrupt kept photo")
    check: Callable[[Path], str]  # why the file is damaged, "" when whole; raises OSError when unreadable
    missing_fix: str  # how to get a missing one back, for ``cache verify``
    unnamed: str  # how ``cache gc`` says what it removed: "kept photos <unnamed>"

    def path(self, root: Path, value: str) -> Path:
        """Where the file named by ``value`` is kept in the store at ``root``."""
        return root.joinpath(*self.folder, f"{value}{self.suffix}")


@dataclass(frozen=True)
class TableContract:
    """One table of the store: ``tables/<name>/<segment>.parquet``, its rows keyed by ``key``.

    ``columns`` are those every segment has had since the table was first written (its key among
    them): a segment that lists no columns of its own and lacks one was rewritten without it, and is
    damaged. Columns added later are not among them: older segments rightly lack those.
    """

    name: str
    key: str
    columns: tuple[str, ...]
    merge: Merge = "first"
    kept: KeptFiles | None = None

    def __post_init__(self) -> None:
        if not _NAME.fullmatch(self.name) or self.name == "jobs":
            raise ValueError(f"a table's name is lower-case letters, digits and _ (a folder and a view), "
                             f"not {self.name!r}")
        if not _NAME.fullmatch(self.key):
            raise ValueError(f"table {self.name!r}: its key column is named in lower-case letters, digits and _, "
                             f"not {self.key!r}")
        if self.merge not in MERGES:
            raise ValueError(f"table {self.name!r}: merge is one of {MERGES}, not {self.merge!r}")
        if self.key not in self.columns:
            raise ValueError(f"table {self.name!r}: its key {self.key!r} is not among its columns")

    @property
    def row_order(self) -> str:
        """SQL ordering a key's rows so that the one that counts comes first."""
        return "created_at DESC" if self.merge == "newest" else "created_at"


#: The pipeline's tables: the store's own, each row keyed by what made it.
CORE_TABLES = (
    TableContract("renders", "render_key", ("render_key", "width", "height", "valid", "seconds", "created_at")),
    TableContract("images", "image_key", ("image_key", "render_key", "valid", "seconds", "created_at")),
    TableContract("predictions", "pred_key", ("pred_key", "image_key", "model", "model_digest", "seconds",
                                              "created_at")),
    TableContract("runs", "run_id", ("run_id", "experiment", "spec_path", "spec", "jobs", "started_at", "created_at",
                                     "seconds")),
    TableContract("parts", "parts_key", ("parts_key", "render_key", "layout", "parts", "pixels", "object_pixels",
                                         "created_at")),
    TableContract("truths", "truth_key", ("truth_key", "render_key", "passes", "gt_x0", "gt_y0", "gt_x1", "gt_y1",
                                          "visible_pixels", "silhouette_pixels", "visible_fraction", "silhouette",
                                          "truth_seconds", "mask_sha256", "depth_sha256", "created_at")),
)

_tables: dict[str, TableContract] = {contract.name: contract for contract in CORE_TABLES}
_folders: list[str] = []  # top-level folders of the store that registered packages write


def register_table(contract: TableContract) -> TableContract:
    """Make ``contract``'s table known to the store (its views, compaction, verify, gc and stats).

    Registering the same table again is a no-op; a second, different contract of one name is refused.
    """
    known = _tables.get(contract.name)
    if known is not None and _shape(known) != _shape(contract):
        raise ValueError(f"table {contract.name!r} is already declared with another key, columns or merge rule")
    _tables[contract.name] = contract
    if contract.kept is not None:
        register_store_folder(contract.kept.folder[0])
    return contract


def unregister_table(name: str) -> None:
    """Forget the table ``name`` (a test's own table); the store's own tables stay."""
    if name not in {c.name for c in CORE_TABLES}:
        _tables.pop(name, None)


def register_store_folder(name: str) -> None:
    """Declare ``name`` a top-level folder of the store that a registered package writes, so that a
    folder holding only it is known for a store's (see :mod:`sweep3d.cache.store_folder`)."""
    if name not in _folders:
        _folders.append(name)


def table_contract(name: str) -> TableContract | None:
    """The contract of the table ``name``; None when no package declares one."""
    if name not in _tables:
        load_declared()
    return _tables.get(name)


def contract_of(name: str) -> TableContract:
    """The contract of the table ``name``.

    Raises:
        KeyError: no package declares a table of that name.
    """
    contract = table_contract(name)
    if contract is None:
        raise KeyError(f"no table {name!r} is declared (known: {', '.join(table_names())})")
    return contract


def table_names() -> tuple[str, ...]:
    """Every declared table, the store's own first, then in the order they were registered."""
    load_declared()
    return tuple(_tables)


def table_contracts() -> tuple[TableContract, ...]:
    """Every declared table's contract (see :func:`table_names`)."""
    load_declared()
    return tuple(_tables.values())


def store_folders() -> tuple[str, ...]:
    """Top-level folders of the store that registered packages write (their kept files' and others)."""
    load_declared()
    return tuple(_folders)


def known_folder(name: str) -> bool:
    """Whether ``name`` is a top-level folder that a registered package writes (its modules are
    imported only when ``name`` is none that is registered already)."""
    if name not in _folders:
        load_declared()
    return name in _folders


def _shape(contract: TableContract) -> tuple:
    kept = contract.kept
    return (contract.key, contract.columns, contract.merge,
            None if kept is None else (kept.folder, kept.column, kept.suffix))


class _KeyColumns(Mapping[str, str]):
    """Table → its key column, over every declared table (read when used, so a table registered
    later is in it)."""

    def __getitem__(self, table: str) -> str:
        return contract_of(table).key

    def __iter__(self) -> Iterator[str]:
        return iter(table_names())

    def __len__(self) -> int:
        return len(table_names())


class _TableNames(Sequence[str]):
    """Every declared table's name, in :func:`table_names`' order (read when used)."""

    def __getitem__(self, index):  # type: ignore[override]
        return table_names()[index]

    def __len__(self) -> int:
        return len(table_names())

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and table_contract(name) is not None

    def __repr__(self) -> str:
        return repr(table_names())


#: Table → key column, for every declared table (see :func:`contract_of`).
KEY_COLUMN: Mapping[str, str] = _KeyColumns()
#: Every declared table's name (see :func:`table_names`).
TABLES: Sequence[str] = _TableNames()
