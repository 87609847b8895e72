"""One small registry pattern shared by every plug-in kind (controls, policies, models, evaluators).

Plug-ins register under a short name. A spec names them either by that short name or
as ``"package.module:Name"``, which imports the user's own module; an unknown name fails at
spec load with the list of valid names.
"""

from __future__ import annotations

import ast
import difflib
import hashlib
import importlib
import importlib.machinery
import inspect
import sys
import sysconfig
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Generic, Iterator, TypeVar

from sweep3d.core.errors import PluginError, UserError, plugin_failure

T = TypeVar("T")
SWEEP3D = Path(__file__).resolve().parent  # sweep3d's own modules are never a plug-in's local imports


def is_user_plugin(name: str) -> bool:
    """Whether a spec's plug-in name is a user's own (``module:Name``) rather than a built-in's."""
    return ":" in name


@lru_cache(maxsize=None)
def code_identity(plugin: Any) -> str:
    """What a user's plug-in (a class or a factory function) puts into the keys of the stages it
    feeds, so that editing it re-does exactly their work: the ``version`` its author declares on
    it (or on a base class of their own), else a digest of the source of the module defining it
    and of the user's modules it imports (:func:`local_imports`).

    A module's source is the whole file, so an edit anywhere in it counts, and so does an edit of
    a module beside it that it imports (``helper.py`` next to the spec); installed packages' code
    does not: declare a ``version`` when that matters.

    Raises:
        UserError: the source cannot be read (a class defined in a notebook cell or ``python -c``)
            and no ``version`` is declared.
    """
    declared = _declared_version(plugin)
    if declared is not None:
        return f"version:{declared}"
    module = sys.modules.get(getattr(plugin, "__module__", ""), None)
    try:
        path = Path(inspect.getsourcefile(module) or "") if module is not None else None
        source = path.read_bytes() if path is not None and path.is_file() else inspect.getsource(plugin).encode()
    except (OSError, TypeError):
        raise UserError(f"cannot read the source of {_name(plugin)} to key its results; declare a version on it "
                        "(version = '1', changed whenever its output changes)") from None
    digest = hashlib.sha256(source)
    for name, data in local_imports(module):  # none: the digest of the module's source alone, as before
        digest.update(b"\0" + name.encode() + b"\0" + hashlib.sha256(data).digest())
    return "source:" + digest.hexdigest()[:16]


def local_imports(module: Any) -> list[tuple[str, bytes]]:
    """(module name, file content) of each module that ``module`` imports, directly or through one
    another, whose file lies under the folder it was imported from (the spec's folder for a spec's
    plug-in), sorted by name; none for a module installed with Python or a package.

    Found from the import statements of the sources (those inside functions too), resolved as an
    import would, without importing anything.
    """
    path = Path(getattr(module, "__file__", None) or "")
    root = _import_root(getattr(module, "__name__", ""), path)
    if root is None:
        return []
    found: dict[str, Path] = {}
    todo = [(module.__name__, path)]
    while todo:
        name, file = todo.pop()
        for imported in _imports(name, file):
            located = _locate(imported, root)
            if located is not None and imported not in found and located != path:
                found[imported] = located
                todo.append((imported, located))
    out = []
    for name in sorted(found):
        try:
            out.append((name, found[name].read_bytes()))
        except OSError:
            continue  # gone since it was found: the plug-in's own import fails first
    return out


def _import_root(name: str, path: Path) -> Path | None:
    """The ``sys.path`` folder ``name`` was imported from (``path``: its file), or None for a
    module without a file, sweep3d's own, or one installed with Python or a package."""
    if not name or not path.is_file():
        return None
    root = path.resolve().parent
    for _ in range(name.count(".") + (path.name == "__init__.py")):
        root = root.parent
    installed = {Path(sysconfig.get_paths()[k]).resolve() for k in ("stdlib", "platstdlib", "purelib", "platlib")}
    return None if any(root == folder or folder in root.parents for folder in installed) else root


def _imports(name: str, file: Path) -> set[str]:
    """The absolute names of the modules the source ``file`` (module ``name``) imports, each
    ``from a import b`` also as ``a.b`` (b may be a module)."""
    if file.suffix != ".py":
        return set()
    try:
        tree = ast.parse(file.read_bytes(), str(file))
    except (OSError, SyntaxError, ValueError):
        return set()
    package = name if file.name == "__init__.py" else name.rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = _absolute(node.module or "", node.level, package)
            if base is None:
                continue
            names.update(f"{base}.{alias.name}" if base else alias.name for alias in node.names if alias.name != "*")
            if base:
                names.add(base)
    return names


def _absolute(module: str, level: int, package: str) -> str | None:
    """``from {'.' * level}{module} import ...`` in ``package``, as an absolute name (None: beyond the top)."""
    if not level:
        return module
    parts = package.split(".") if package else []
    if level - 1 > len(parts):
        return None
    base = ".".join(parts[:len(parts) - (level - 1)])
    return f"{base}.{module}".strip(".") if module else base


def _locate(name: str, root: Path) -> Path | None:
    """The file of module ``name`` when it lies under ``root``: the imported module's, else where
    an import from ``root`` would find it (without importing it); None otherwise."""
    loaded = sys.modules.get(name)
    file = getattr(loaded, "__file__", None) if loaded is not None else None
    if file is None and loaded is None:
        file = _find(name, root)
    if not file:
        return None
    path = Path(file).resolve()
    return path if root in path.parents and SWEEP3D not in path.parents and path.is_file() else None


def _find(name: str, root: Path) -> str | None:
    """Where module ``name`` would be found under ``root``, component by component, importing nothing."""
    locations = [str(root)]
    spec = None
    parts = name.split(".")
    for i in range(len(parts)):
        spec = importlib.machinery.PathFinder.find_spec(".".join(parts[:i + 1]), locations)
        if spec is None:
            return None
        locations = list(spec.submodule_search_locations or [])
    return spec.origin if spec is not None and spec.has_location else None


_imported: dict[str, tuple[int, int]] = {}  # a user module's file (mtime, size) when it was imported


def _fresh(module: Any) -> Any:
    """``module``, imported again when its file changed since (a notebook or a long-lived process
    whose user edits a plug-in between runs sees the edit, and keys it)."""
    try:
        stat = Path(module.__file__).stat()
    except (AttributeError, TypeError, OSError):
        return module
    seen = (stat.st_mtime_ns, stat.st_size)
    if _imported.setdefault(module.__name__, seen) != seen:
        module = importlib.reload(module)
        _imported[module.__name__] = seen
    return module


def _declared_version(plugin: Any) -> Any:
    """The ``version`` set on ``plugin`` or a base class outside sweep3d; None when none is."""
    for klass in inspect.getmro(plugin) if inspect.isclass(plugin) else (plugin,):
        if getattr(klass, "__module__", "").split(".")[0] == "sweep3d":
            return None
        if "version" in vars(klass):
            return vars(klass)["version"]
    return None


def _name(plugin: Any) -> str:
    return f"{getattr(plugin, '__module__', '?')}:{getattr(plugin, '__qualname__', plugin)}"


class Registry(Generic[T]):
    """Maps short names to plug-ins of one kind.

    Each stage owns the registries of its plug-ins (rendered controls, post controls, policies,
    models, evaluators); the spec loader is handed them through a catalogue, so the spec layer
    never imports a stage.

    Args:
        kind: what the plug-ins are, for error messages ("control", "policy", ...).
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._items: dict[str, T] = {}

    @classmethod
    def union(cls, kind: str, *parts: "Registry[T]") -> "Registry[T]":
        """One registry holding the plug-ins of ``parts`` (e.g. rendered and post controls).

        Raises:
            ValueError: if two parts register the same name.
        """
        merged: Registry[T] = cls(kind)
        for part in parts:
            for name in part.names():
                merged.register(name)(part.get(name))
        return merged

    def register(self, name: str) -> Callable[[T], T]:
        """Class or function decorator that registers the plug-in under ``name``."""

        def decorator(item: T) -> T:
            existing = self._items.get(name)
            if existing is not None and existing is not item:
                raise ValueError(f"{self.kind} {name!r} is already registered")
            self._items[name] = item
            return item

        return decorator

    def unregister(self, name: str) -> None:
        """Take back the plug-in registered as ``name`` (a test's, or a host's temporary one); none: nothing."""
        self._items.pop(name, None)

    def names(self) -> list[str]:
        return sorted(self._items)

    def __contains__(self, name: str) -> bool:
        """True for registered short names (``module:Name`` references are checked by :meth:`get`)."""
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def get(self, name: str) -> T:
        """Return the plug-in called ``name``, importing ``module:attr`` names on demand.

        Raises:
            UserError: if the name is unknown or the user's module cannot be imported.
        """
        if name in self._items:
            return self._items[name]
        if ":" in name:
            return self._import(name)
        close = difflib.get_close_matches(name, self._items, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise UserError(
            f"unknown {self.kind} {name!r}{hint}; valid: {', '.join(self.names())}, "
            f"or 'package.module:Name' for your own"
        )

    def _import(self, dotted: str) -> T:
        module_name, _, attr = dotted.partition(":")
        try:
            module = _fresh(importlib.import_module(module_name))
        except ModuleNotFoundError as exc:
            if exc.name != module_name.split(".")[0] and exc.name != module_name:  # one it imports is missing
                raise plugin_failure(f"{self.kind} module {module_name!r}", exc, "failed to import") from None
            raise UserError(
                f"cannot import {self.kind} module {module_name!r}: {exc}; put {module_name.replace('.', '/')}.py "
                "beside the spec, or install it, or add its folder to PYTHONPATH"
            ) from None
        except SystemExit as exc:  # sys.exit at the module's top level: named as the plug-in asked for
            raise plugin_failure(f"{self.kind} {dotted!r}", exc, during="on import") from None
        except Exception as exc:  # noqa: BLE001  (a syntax error or a raise in the user's module)
            if isinstance(exc, SyntaxError) and exc.filename:
                where = f" ({Path(exc.filename).name}:{exc.lineno})"
                raise PluginError(f"{self.kind} module {module_name!r}{where} failed to import: SyntaxError: "
                                  f"{exc.msg}") from None
            raise plugin_failure(f"{self.kind} module {module_name!r}", exc, "failed to import") from None
        try:
            return getattr(module, attr)
        except AttributeError:
            raise UserError(f"module {module_name!r} has no {self.kind} named {attr!r}") from None
