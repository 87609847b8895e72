"""The tree's architecture, checked: every import points down the layers, and between packages only
through the imported package's ``__init__``; one public way to load a spec.

The layers, lowest first (docs/architecture.md draws them). A *unit* is one of these packages: a
module may import anything of its own unit, and of a lower unit only what that unit's ``__init__``
exports (``from sweep3d.core import UserError``, never ``from sweep3d.core.errors import ...``).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "sweep3d"

#: Lowest first. The root (``sweep3d``: ``__init__``, ``api``, ``plugins``, ``__main__``) is the top.
UNITS = (
    "sweep3d.core",                # vocabulary: errors, typed values, registry, contracts, pixels, truth, UV cells
    "sweep3d.cache",               # storage: canonical keys, the Parquet/DuckDB store, blobs
    "sweep3d.assets",              # mesh and HDRI files read without Blender
    "sweep3d.spec",                # the spec: models, loader, search space, columns
    "sweep3d.driver",              # the stage protocol, the loop that runs stages, jobs, passes, progress
    "sweep3d.stages.render",       # the stages, each owning its plug-ins
    "sweep3d.stages.postprocess",
    "sweep3d.stages.infer",
    "sweep3d.stages.plan",
    "sweep3d.runner",              # one run: pipeline, plan status, the built-in catalogue
    "sweep3d.results",             # SQL views over a store
    "sweep3d.export",
    "sweep3d.bench",
    "sweep3d.followups.stability", # follow-ups of a finished run, side by side: which verdicts are fragile,
    "sweep3d.followups.explain",   # the nearest fix of each failure,
    "sweep3d.followups.confirm",   # findings confirmed on fresh renders,
    "sweep3d.followups.realism",   # agreement with photographs and another renderer,
    "sweep3d.followups.grade",     # one grade per finding from the checks above, under one budget
    "sweep3d.report",              # the HTML report (its panels read the follow-ups' results)
    "sweep3d",                     # the public API: sweep3d.load, Experiment, plugins
    "sweep3d.cli",                 # the command line, over the API (and ``python -m sweep3d``)
)

#: Packages that only group units (their ``__init__`` a docstring): each member is a unit of its own.
GROUPS = ("sweep3d.stages", "sweep3d.followups")

#: Imports that point up a layer, made inside a function (so at call time, never at import time),
#: each to look a plug-in up in a registry its layer cannot own. Adding one needs a reason here.
UPWARD_AT_CALL_TIME = {  # none from the driver into the stages: it reads evaluators and models from the spec's catalogue
    ("sweep3d.spec.loader", "sweep3d.stages.plan"): "a [policy] type must name a Policy subclass",
}


def unit_of(module: str) -> str:
    if module == "sweep3d.__main__":
        return "sweep3d.cli"
    return max((u for u in UNITS if module == u or module.startswith(u + ".")), key=len)


def modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(REPO).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = modules()


def bound_names(module: str) -> set[str]:
    """The names a package's ``__init__`` binds itself or exports lazily (``from P import X`` of one
    of them imports a name, even where P also has a module X)."""
    path = MODULES.get(module)
    if path is None or path.name != "__init__.py":
        return set()
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Dict):  # the lazy export table
            names |= {k.value for k in node.keys if isinstance(k, ast.Constant) and isinstance(k.value, str)}
    return names


def imports(path: Path) -> list[tuple[int, str, bool]]:
    """(line, the sweep3d module imported, whether at call time) for every import in ``path``."""
    tree = ast.parse(path.read_text())
    nested = {id(n) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
              for n in ast.walk(f)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            bound = bound_names(node.module)
            targets = [f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in MODULES and a.name not in bound
                       else node.module for a in node.names]
        else:
            continue
        found += [(node.lineno, t, id(node) in nested) for t in dict.fromkeys(targets)
                  if t == "sweep3d" or t.startswith("sweep3d.")]
    return found


def violations() -> tuple[list[str], list[str]]:
    upward, around = [], []
    for module, path in MODULES.items():
        here = unit_of(module)
        for line, target, at_call in imports(path):
            there = unit_of(target)
            where = f"{path.relative_to(REPO)}:{line} imports {target}"
            if UNITS.index(there) > UNITS.index(here) and not (at_call and (module, there) in UPWARD_AT_CALL_TIME):
                upward.append(f"{where}: {here} is below {there}")
            if there != here and target != there and there != "sweep3d":
                around.append(f"{where}: import it from {there} (its __init__ is the only way in)")
    return upward, around


def test_every_module_belongs_to_a_unit_of_the_layer_order() -> None:
    loose = sorted(m for m, p in MODULES.items() if m.count(".") == 1 and p.name != "__init__.py")
    assert loose == ["sweep3d.__main__", "sweep3d.api", "sweep3d.plugins"], (
        "a module at the root: put it in the package of its role (the root is the public API)")
    packages = sorted(m for m, p in MODULES.items() if m.count(".") == 1 and p.name == "__init__.py")
    assert set(packages) <= {*UNITS, *GROUPS}, "a package that is in no layer: add it to UNITS"
    unplaced = [m for m in MODULES if m.startswith(tuple(g + "." for g in GROUPS)) and unit_of(m) == "sweep3d"]
    assert not unplaced, f"a stage or follow-up package without a layer: {unplaced}"
    importing = [g for g in GROUPS if imports(MODULES[g])]
    assert not importing, f"a group's __init__ imports (each member is reached through its own): {importing}"


def test_no_import_points_up_a_layer() -> None:
    upward, _ = violations()
    assert not upward, "\n".join(upward)


def test_no_import_reaches_past_another_package_s_init() -> None:
    _, around = violations()
    assert not around, "\n".join(around)


def test_the_allowed_upward_imports_still_exist() -> None:
    """An allowance nobody needs any more goes (so the list says only what is true)."""
    used = {(m, unit_of(t)) for m, p in MODULES.items() for _, t, at_call in imports(p) if at_call}
    assert set(UPWARD_AT_CALL_TIME) <= used


def test_there_is_one_public_spec_loader() -> None:
    import sweep3d

    assert "load" in sweep3d.__all__
    loaders = []
    for module, path in MODULES.items():
        tree = ast.parse(path.read_text())
        loaders += [f"{module}.{n.name}" for n in tree.body if isinstance(n, ast.FunctionDef)
                    and re.fullmatch(r"load(_spec)?", n.name) and module != "sweep3d.api"]
    assert not loaders, f"a second public spec loader: {loaders} (sweep3d.load is the one)"
    for unit in (u for u in UNITS if u != "sweep3d"):
        exported = getattr(__import__(unit, fromlist=["__all__"]), "__all__", [])
        assert not [n for n in exported if re.fullmatch(r"load(_spec)?", n)], unit


@pytest.mark.parametrize("unit", UNITS)
def test_each_unit_s_exports_resolve(unit: str) -> None:
    """Every name a unit's ``__init__`` lists is there (a lazy export naming a moved module fails here)."""
    package = __import__(unit, fromlist=["__all__"])
    missing = [n for n in getattr(package, "__all__", []) if not hasattr(package, n)]
    assert not missing, f"{unit} lists {missing}"


@pytest.mark.parametrize("code", ["import sweep3d.plugins",
                                  "from sweep3d.plugins import ControlParams, RenderedControl, PostControl"])
def test_a_plug_in_s_import_loads_neither_duckdb_nor_pyarrow(code: str) -> None:
    """Every render worker imports the user's control module, which imports ``sweep3d.plugins``: it
    must not pay for the store's libraries (RESULTS.md: 427 → 5 ms)."""
    import json
    import subprocess
    import sys

    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, check=True)
    loaded = set(json.loads(out.stdout.splitlines()[-1]))
    assert not {"duckdb", "pyarrow", "pandas", "torch", "bpy"} & loaded


def test_no_test_imports_another_test_file_or_a_benchmark() -> None:
    """Tests share pieces through ``tests/helpers/`` (and conftest's fixtures), never by importing
    another test module or ``benchmarks/`` (a benchmark is run as a program, not imported)."""
    wrong = []
    for path in sorted((REPO / "tests").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else []
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module == "tests":
                names = [f"tests.{a.name}" for a in node.names]
            for name in names:
                last = name.rsplit(".", 1)[-1]
                if name.startswith("benchmarks") or (name.startswith("tests.") and last.startswith("test_")):
                    wrong.append(f"{path.relative_to(REPO)}:{node.lineno} imports {name}")
    assert not wrong, "\n".join(wrong)
