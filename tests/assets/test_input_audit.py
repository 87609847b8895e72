"""The input audit of issue 22: each defect as the audit found it, now one ``error:`` line naming
the file, the key and the fix, exit code 2, and the store as it was (or, for a damaged segment,
found, quarantined and recomputed). Fast unless a case needs the model (7a)."""

from __future__ import annotations

import io
import shutil
import sys
import zipfile
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from tests.helpers import CUBE_OBJ, TINY_SPEC, files, write_spec


def _tree(root: Path) -> dict[str, bytes]:
    """The store's files and contents (the lock file only records the last holder's pid)."""
    if not root.exists():
        return {}
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.name != "lock"}


def _spec(folder: Path, *edits: tuple[str, str], extra: dict[str, bytes] | None = None) -> Path:
    text = TINY_SPEC
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    path = write_spec(folder, text)
    for name, data in (extra or {}).items():
        (folder / name).write_bytes(data)
    return path


def _refused(spec: Path, *expect: str, key: str, command: str = "plan") -> str:
    """Run ``command`` on ``spec``: one error line naming the spec and ``key``, exit 2, no
    traceback, holding ``expect``, and nothing written to the store."""
    store = spec.parent / "store"
    before = _tree(store)
    result = CliRunner().invoke(app, [command, str(spec)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    line = errors[0]
    assert f"{spec}: {key}: " in line, line
    for text in expect:
        assert text in line, f"{text!r} not in {line!r}"
    assert _tree(store) == before, "the store changed"
    return line


# -- 13: spec types, control characters, a control id named like a key's hole ---------------------
WRONG_TYPES = [
    ("samples", ("samples = 1", 'samples = "4"'), "render.samples", ('not the string "4"', "without quotes")),
    ("denoise", ("denoise = false", 'denoise = "yes"'), "render.denoise", ("true or false", '"yes"')),
    ("seed", ("seed = 7", 'seed = "7"'), "experiment.seed", ("must be a number", '"7"')),
    ("top_k", ("[model]\n", '[evaluator]\ntop_k = "5"\n\n[model]\n'), "evaluator.top_k", ("must be a number", '"5"')),
    ("color", ("color = [1.0, 1.0, 1.0]", 'color = ["1", "1", "1"]'), "environments[0].color",
     ("[0] must be a number", '"1"')),
    ("workers", ("denoise = false", "denoise = false\nworkers = true"), "render.workers", ("must be a number, not true",)),
    ("yaw", ("yaw = [0, 45]", 'yaw = ["0", "45"]'), "controls[0].yaw", ("must be a number", '"0"')),
    ("policy-samples", ('type = "grid"', 'type = "random"\nsamples = "5"'), "policy.samples", ("must be a number",)),
]


@pytest.mark.parametrize("edit, key, expect", [c[1:] for c in WRONG_TYPES], ids=[c[0] for c in WRONG_TYPES])
def test_a_string_or_boolean_where_a_number_belongs_is_one_line(tmp_path: Path, edit, key: str, expect) -> None:
    _refused(_spec(tmp_path, edit), *expect, key=key)


def test_a_python_dict_spec_still_takes_ints_where_floats_belong(tmp_path: Path) -> None:
    """Strict about strings, not about numbers: an int strength, colour or yaw is exact."""
    import tomllib

    from sweep3d.api import load

    write_spec(tmp_path, TINY_SPEC)
    raw = tomllib.loads(TINY_SPEC)
    raw["environments"][0]["color"] = (1, 1, 1)
    raw["environments"][1]["strength"] = 2
    raw["controls"][0]["yaw"] = [0, 45]
    spec = load(raw, base=tmp_path).spec
    assert spec.environments[0].color == (1.0, 1.0, 1.0) and spec.environments[1].strength == 2.0


CONTROL_NAMES = [
    ("object-nul", ('name = "box"', 'name = "bo\\u0000x"'), "objects[0].name", "'\\x00'"),
    ("environment-esc", ('name = "white"', 'name = "wh\\u001bite"'), "environments[0].name", "'\\x1b'"),
    ("label-newline", ('labels = ["carton"]', 'labels = ["car\\nton"]'), "objects[0].labels", "'\\n'"),
    ("control-id-newline", ('type = "blur"', 'type = "blur"\nid = "bl\\nur"'), "controls[1].id", "letters, digits"),
]


@pytest.mark.parametrize("edit, key, expect", [c[1:] for c in CONTROL_NAMES], ids=[c[0] for c in CONTROL_NAMES])
def test_a_name_with_a_control_character_is_one_line(tmp_path: Path, edit, key: str, expect: str) -> None:
    _refused(_spec(tmp_path, edit), expect, key=key)


def test_a_control_named_render_plans_as_any_other_id(tmp_path: Path) -> None:
    """``type = "blur"``, ``id = "render"`` made the image key's template ambiguous (a traceback):
    a control's hole is named apart from the render key's, so its keys are the per-job ones."""
    from sweep3d.assets.sources import blender_version
    from sweep3d.spec.framing import Framing
    from sweep3d.stages.plan import make_plan
    from tests.helpers import load_spec, reference_jobs

    colour_only = ('[[environments]]\nname = "studio"\nhdri = "builtin:studio"\n', "")  # the reference's scenes
    spec = load_spec(_spec(tmp_path, ('type = "blur"', 'type = "blur"\nid = "render"'), colour_only))
    framing, blender = Framing.full(32), blender_version()
    plan = make_plan(spec, framing=framing, model_digest="model-x", blender=blender)
    expected = reference_jobs(spec, framing=framing, model_digest="model-x", blender=blender)
    jobs = sorted([*plan.jobs, *plan.out_of_frame], key=lambda j: j.index)
    assert [(j.render_key, j.image_key) for j in jobs] == [(e[4], e[5]) for e in expected]
    assert CliRunner().invoke(app, ["plan", str(tmp_path / "spec.toml")]).exit_code == 0


# -- 14: small ones ---------------------------------------------------------------------------
def test_an_empty_mesh_path_says_it_is_empty(tmp_path: Path) -> None:
    line = _refused(_spec(tmp_path, ('mesh = "cube.obj"', 'mesh = ""')), "the mesh path is empty", key="objects[0].mesh")
    assert "directory" not in line


def test_an_empty_hdri_path_says_it_is_empty(tmp_path: Path) -> None:
    _refused(_spec(tmp_path, ('hdri = "builtin:studio"', 'hdri = ""')), "the HDRI path is empty",
             key="environments[1].hdri")


TRIANGLE = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"
BAD_OBJS = [
    ("short-vertex", b"v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ("line 1", "'v 0 0'", "x y z")),
    ("bad_index", TRIANGLE + b"f 1 2 9\n", ("line 4", "vertex 9", "3 vertices")),
    ("bad_index-zero", TRIANGLE + b"f 0 1 2\n", ("line 4", "vertex 0")),
    ("zero_area-collinear", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", ("zero area",)),
    ("zero_area-repeated", TRIANGLE + b"f 1 1 2\nf 3 3 3\n", ("zero area",)),
    ("zero_area-one-point", b"v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n", ("zero area",)),
]


@pytest.mark.parametrize("data, expect", [c[1:] for c in BAD_OBJS], ids=[c[0] for c in BAD_OBJS])
def test_an_obj_blender_would_misread_is_refused_at_load(tmp_path: Path, data: bytes, expect) -> None:
    spec = _spec(tmp_path, ('mesh = "cube.obj"', 'mesh = "bad.obj"'), extra={"bad.obj": data})
    _refused(spec, "bad.obj", *expect, key="objects[0].mesh")


@pytest.mark.parametrize("data", [CUBE_OBJ.encode(), TRIANGLE + b"f 1/1/1 2/2/2 3//3\n", TRIANGLE + b"f -3 -2 -1\n",
                                  b"v 0 0 0 # a comment\nvt 0 0\nvn 0 0 1\n" + TRIANGLE + b"f 1 2 3 4\n"])
def test_good_objs_pass_the_face_checks(data: bytes) -> None:
    from sweep3d.assets.obj_faces import check_obj_geometry

    check_obj_geometry(data)


def test_a_bench_report_has_its_own_folder(tmp_path: Path) -> None:
    """Experiment ``q-bench``'s report and ``q``'s bench plot were the same file."""
    from sweep3d.cache.store import Store

    store = Store(tmp_path)
    assert store.report_path("q", ".html", "bench") != store.report_path("q-bench")
    assert store.report_path("q", ".html", "bench").parent.name == "bench"


# -- 11: archives ---------------------------------------------------------------------------
def _zip(member: str, data: bytes) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr(member, data)
    return buf.getvalue()


def test_an_archive_member_over_the_limit_is_refused_before_it_is_read(tmp_path: Path) -> None:
    """The audit's bomb scaled down: 3 MB of OBJ in a 3 KB zip, against a 1 MB limit (the default,
    256 MB, refuses the audit's 300 MB the same way)."""
    bomb = _zip("parts/box.obj", CUBE_OBJ.encode() + b"#" + b"x" * 3_000_000 + b"\n")
    spec = _spec(tmp_path, ('mesh = "cube.obj"', 'mesh = "kit.zip#parts/box.obj"'),
                 ("seed = 7", "seed = 7\nmax_archive_mb = 1"), extra={"kit.zip": bomb})
    _refused(spec, "kit.zip#parts/box.obj", "3.0 MB", "max_archive_mb = 1", key="objects[0].mesh")


def test_the_default_archive_limit_refuses_the_audit_bomb() -> None:
    from sweep3d.spec.models import ExperimentSpec

    assert ExperimentSpec(name="x").max_archive_mb * 1e6 < 300e6


def test_extraction_stops_at_the_declared_size() -> None:
    """What the spec check read is a member's declared size; extraction holds it to that."""
    from sweep3d.assets.sources import _copy_at_most
    from sweep3d.core.errors import UserError

    out = io.BytesIO()
    with pytest.raises(UserError, match="more than the 5 bytes"):
        _copy_at_most(io.BytesIO(b"x" * 10), out, 5, "kit.zip#a.obj")
    assert len(out.getvalue()) <= 5


# -- 12: memory -------------------------------------------------------------------------------
def test_a_billion_jobs_is_refused_for_memory_in_one_line(tmp_path: Path) -> None:
    spec = _spec(tmp_path, ("seed = 7", "seed = 7\nmax_jobs = 2000000000"),
                 ("yaw = [0, 45]", "yaw = { range = [0, 360] }\npitch = { range = [-90, 90] }"),
                 ("sigma = [0.0, 1.5]", "sigma = { range = [0, 2] }"),
                 ('type = "grid"', 'type = "grid"\nsamples_per_dim = 794'))
    _refused(spec, "1,001,132,368 jobs", "GB of memory", "available", "lower policy.samples_per_dim", key="policy")


def test_the_memory_estimate_grows_with_parameters() -> None:
    from sweep3d.stages.plan.memory import available_memory, plan_bytes

    assert plan_bytes(10**6, 2) == 10**6 * (500 + 2 * 360)
    assert available_memory() is None or available_memory() > 0


# -- 7b: HDRIs with NaN, inf or absurd radiance ---------------------------------------------------
def _map(value: float, rows: int = 8) -> np.ndarray:
    pixels = np.full((8, 16, 3), 0.5, np.float32)
    pixels[:rows] = value
    return pixels


HDRIS = [
    ("all-nan", _map(np.nan), ("128 of the EXR map's 128 pixels are NaN or infinite",)),
    ("some-inf", _map(np.inf, rows=2), ("32 of the EXR map's 128 pixels are NaN or infinite",)),
    ("1e30", _map(1e30, rows=1), ("16 of the EXR map's 128 pixels are brighter than 1e+06",)),
]


@pytest.mark.parametrize("pixels, expect", [c[1:] for c in HDRIS], ids=[c[0] for c in HDRIS])
@pytest.mark.parametrize("zip_compressed", [False, True], ids=["raw", "zip"])
def test_an_hdri_with_non_finite_or_absurd_radiance_is_refused(tmp_path: Path, pixels, expect,
                                                                zip_compressed: bool) -> None:
    spec = _spec(tmp_path, ('hdri = "builtin:studio"', 'hdri = "sky.exr"'),
                 extra={"sky.exr": files.exr(pixels, zip_compressed=zip_compressed)})
    line = _refused(spec, "sky.exr", *expect, key="environments[1].hdri")
    assert "every pixel is 0" not in line


def test_a_bright_but_captured_sun_passes() -> None:
    from sweep3d.assets.radiance import MAX_RADIANCE, Tally

    tally = Tally()
    tally.add(np.array([[1e5, 0.5], [9e4, 0.5], [8e4, 0.5]], np.float32))
    assert not tally.bad and MAX_RADIANCE == 1e6


# -- 7c: a segment missing a column of its table ------------------------------------------------
def test_a_segment_lacking_a_column_is_damaged_found_and_quarantined(tmp_path: Path, caplog) -> None:
    """The audit dropped ``top1_label`` from a predictions segment: its rows read as NULL labels,
    counted valid, and ``cache verify`` said "store OK". Such a segment is now unreadable: verify
    names it, a run's read quarantines it (so its rows are recomputed), the others are untouched."""
    from sweep3d.cache.maintenance import verify
    from sweep3d.cache.store import Store

    store = Store(tmp_path / "store")
    rows = [{"pred_key": f"k{i}", "top1_label": "carton", "valid": True, "created_at": None} for i in range(3)]
    damaged = store.append("predictions", rows)
    kept = store.append("predictions", [{**rows[0], "pred_key": "other"}])
    table = pq.read_table(damaged)
    pq.write_table(table.drop_columns(["top1_label"]), damaged)

    problems = verify(store.root).problems
    assert [(p.kind, p.path) for p in problems] == [("corrupt segment", damaged)]
    assert "top1_label" in problems[0].detail

    reader = Store(store.root)
    with reader.lock():  # a run's: only the writer lock's holder quarantines
        assert reader.keys("predictions") == {"other"}
    assert not damaged.exists() and (store.root / "quarantine").exists() and kept.exists()
    assert "lacks its column 'top1_label'" in caplog.text


def test_a_segment_written_before_columns_were_listed_is_not_judged_by_a_list(tmp_path: Path) -> None:
    """Such a segment is held to the columns its table's rows always had (issue 35), no more."""
    from sweep3d.cache.store import Store

    store = Store(tmp_path / "store")
    path = store.table_dir("predictions") / "old.parquet"
    listed = store.append("predictions", [{"pred_key": "k", "image_key": "i", "model": "m", "model_digest": "d",
                                           "seconds": 0.0, "created_at": None}])
    pq.write_table(pq.read_table(listed).replace_schema_metadata(None), path)
    listed.unlink()
    assert Store(store.root).keys("predictions") == {"k"}


# -- 7a: a model whose every output is NaN --------------------------------------------------------
NAN_MODELS = '''
import torch

class Nan(torch.nn.Module):
    def __init__(self, value):
        super().__init__()
        self.value = value
        self.scale = torch.nn.Parameter(torch.ones(1))

    def forward(self, x):
        return torch.full((x.shape[0], 1000), self.value) * self.scale

def nan():
    return Nan(float("nan"))

def minus_inf():
    return Nan(float("-inf"))
'''


@pytest.mark.slow
@pytest.mark.parametrize("factory", ["nan", "minus_inf"])
def test_a_model_invalid_on_every_image_is_said_plainly_and_exit_2(factory: str, tiny_run: Path, tmp_path: Path,
                                                                   monkeypatch) -> None:
    """The renders are the tiny run's (cached): only the model runs. Its predictions are stored
    (nothing computed is lost), the findings say all were invalid, and no report is written."""
    folder = tmp_path / "case"
    shutil.copytree(tiny_run, folder)
    modules = tmp_path / "modules"
    modules.mkdir()
    (modules / "nan_models.py").write_text(NAN_MODELS)
    monkeypatch.syspath_prepend(str(modules))
    monkeypatch.delitem(sys.modules, "nan_models", raising=False)
    spec = folder / "spec.toml"
    spec.write_text(TINY_SPEC.replace("[model]\n", f'[model]\nname = "nan_models:{factory}"\n'))

    result = CliRunner().invoke(app, ["run", str(spec)])

    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert "no accuracy: all 8 predictions are invalid" in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "no report was written" in errors[0], result.output
    assert not list((folder / "store" / "reports").glob("*.html")) if (folder / "store" / "reports").exists() else True
