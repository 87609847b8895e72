"""The layers' dependencies point down: the spec and the cache know no stage, and loading a spec
or making a plan needs neither Blender nor torch (nor, with a stand-in digest, the model)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from datetime import datetime
from pathlib import Path

import pyarrow as pa

from sweep3d.cache.store import Store
from sweep3d.results import connect
from sweep3d.spec.columns import PARAMETERS_METADATA
from tests.helpers import REPO, TINY_SPEC, write_spec


def _modules_after(code: str) -> set[str]:
    """The modules a fresh interpreter holds after running ``code``."""
    probe = textwrap.dedent(code) + "\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))\n"
    out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_spec_and_cache_import_no_stage_module() -> None:
    loaded = _modules_after("import sweep3d.spec, sweep3d.cache, sweep3d.core.control, sweep3d.core.registry")
    assert not {m for m in loaded if m.startswith("sweep3d.stages")}, "spec/cache must not depend on a stage"
    assert not {"bpy", "torch"} & loaded


def test_loading_and_planning_import_neither_blender_nor_torch(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, TINY_SPEC)
    loaded = _modules_after(f"""
        from sweep3d.runner.pipeline import plan_spec
        from tests.helpers import load_spec
        plan = plan_spec(load_spec({str(spec)!r}))
        assert len(plan.jobs) == 8
    """)
    assert not {"bpy", "torch"} & loaded


def test_a_parameter_named_key_is_still_a_parameter(tmp_path: Path) -> None:
    """The jobs file lists its parameters: a column ending in ``_key`` is not mistaken for a key."""
    store = Store(tmp_path / "store")
    jobs = [{"experiment": "e", "job": i, "object": "o", "environment": "env", "lock_key": f"k{i % 2}",
             "render_key": f"r{i}", "image_key": f"r{i}", "pred_key": f"p{i}", "in_frame": True} for i in range(4)]
    table = pa.Table.from_pylist(jobs).replace_schema_metadata({PARAMETERS_METADATA: json.dumps(["lock_key"])})
    store.write_table_file(store.jobs_path("e"), table)
    store.append("predictions", [{"pred_key": f"p{i}", "image_key": f"r{i}", "valid": True, "correct": i % 2 == 0,
                                  "top1_label": "x", "loss": 1.0, "created_at": datetime(2024, 1, 1)} for i in range(4)])
    rows = connect(store, "e").execute(
        "SELECT parameter, label, accuracy FROM control_accuracy WHERE parameter = 'lock_key' ORDER BY label").fetchall()
    assert rows == [("lock_key", "k0", 1.0), ("lock_key", "k1", 0.0)]


def test_the_command_line_converts_lists_without_importing_pandas_and_pandas_objects_as_ever() -> None:
    loaded = _modules_after("""
        import contextlib, io, sys
        import pyarrow as pa
        from sweep3d.cli import main
        sys.argv = ["sweep3d", "--help"]
        with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):
            main()
        pa.array(["a key"])  # pyarrow's first list conversion: it would import pandas to probe it
        assert "pandas" not in sys.modules
        import importlib.util
        assert importlib.util.find_spec("pandas") is not None  # a plug-in asking whether pandas is there
        import pandas as pd  # a plug-in's: pandas objects then convert as they always do
        assert pa.array(pd.Series([1.0, None])).null_count == 1
        assert pa.types.is_dictionary(pa.array(pd.Categorical(["a", "b"])).type)
        frame = pa.table({"a": [1, 2]}).to_pandas()
        assert type(frame).__name__ == "DataFrame" and len(frame) == 2
    """)
    assert "pandas" in loaded
