"""What a notebook or a shell gets back is the right answer, one line and exit code 2, or a clear
message, never a traceback (issue 35, items 7, 8, 12 and 14): numpy values in a dict spec, a
misspelt table, a multi-model run's stages, an export folder that holds files, an export that
selects nothing or meets a full disk, pandas types, a post control's pixel range, a policy that
is not a Policy. Runs are faked without Blender or a model (see tests/runner/test_own_jobs.py)."""

from __future__ import annotations

import errno
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import sweep3d
import sweep3d.export.parquet as export_parquet
from sweep3d.cli import app
from sweep3d.core.control import ControlParams
from sweep3d.core.errors import PluginError, SpecError, UserError
from sweep3d.driver.outcome import StageOutcome
from sweep3d.export.target import Staging
from sweep3d.runner.pipeline import RunResult
from sweep3d.spec.loader import ControlInstance
from sweep3d.stages.plan.policies import GridPolicy
from sweep3d.stages.postprocess import PostControl, apply_post
from tests.helpers import SPEC_02, TINY_SPEC, fake_run, write_cube


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    write_cube(tmp_path)
    return tmp_path


@pytest.fixture
def ran(folder: Path) -> Path:
    """A spec file (blur 0 and 2, 8 jobs) with a faked run in its store: blur 2 fails."""
    spec = folder / "spec.toml"
    spec.write_text(SPEC_02)
    fake_run(sweep3d.load(spec))
    return spec


def one_error_line(args: list[str]) -> str:
    """The command's single output line, checked to be an ``error:`` line with exit code 2."""
    result = CliRunner().invoke(app, args)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error:"), result.output
    return lines[0]


def raw(text: str = TINY_SPEC) -> dict[str, Any]:
    return tomllib.loads(text)


# -- item 7: a dict spec, a misspelt table, a run's stages ----------------------------------------
def test_numpy_arrays_and_scalars_in_a_dict_spec_are_its_lists_and_numbers(folder: Path) -> None:
    spec = raw()
    spec["experiment"]["seed"] = np.int64(7)
    spec["environments"][0]["color"] = np.ones(3)
    spec["controls"][0]["yaw"] = np.array([0, 45])
    spec["controls"][1]["sigma"] = np.linspace(0, 1.5, 2)
    with_numpy = sweep3d.load(spec, base=folder)
    plain = sweep3d.load(raw(), base=folder)
    assert with_numpy.spec.text() == plain.spec.text()  # what the runs table records, and so the keys
    assert [c.spaces for c in with_numpy.spec.controls] == [c.spaces for c in plain.spec.controls]
    spec["controls"][1]["sigma"] = np.array([[0.0, 1.0]])  # a 2-D array is no list of numbers: a SpecError
    with pytest.raises(SpecError, match=r"controls\[1\]\.sigma"):
        sweep3d.load(spec, base=folder)


@pytest.mark.parametrize("old, new, says", [
    ("[[environments]]", "[[enviroments]]", "enviroments: unknown key; remove it or check its spelling (did you mean "
                                            "'environments'?"),
    ('mesh = "cube.obj"', 'mesch = "cube.obj"', "objects[0].mesch: unknown key; remove it or check its spelling (did "
                                                "you mean 'mesh'?"),
])
def test_a_misspelt_key_is_named_with_the_close_match_not_reported_missing(folder: Path, old: str, new: str,
                                                                          says: str) -> None:
    spec = folder / "spec.toml"
    spec.write_text(TINY_SPEC.replace(old, new))
    line = one_error_line(["plan", str(spec)])
    assert says in line and "required key is missing" not in line
    with pytest.raises(SpecError, match=r"<dict>: " + says.split(":")[0].replace("[", r"\[").replace("]", r"\]")):
        sweep3d.load(raw(TINY_SPEC.replace(old, new)), base=folder)


def run_result(folder: Path, models: list[str]) -> RunResult:
    plan = sweep3d.load(TINY_SPEC, base=folder).plan()
    infers = ["infer"] if len(models) == 1 else [f"infer {m}" for m in models]
    outcomes = [StageOutcome(stage, total=8, computed=8) for stage in ("render", "postprocess", *infers)]
    return RunResult("0123456789ab", plan, plans=[plan] * len(models), outcomes=outcomes, seconds=12.5)


def test_a_multi_model_runs_infer_stages_are_asked_for_by_model(folder: Path) -> None:
    result = run_result(folder, ["resnet", "vit"])
    with pytest.raises(UserError, match=r"ran once per model: ask for one of 'render', 'postprocess', "
                                        r"'infer resnet', 'infer vit' \(or give model=\)"):
        result.outcome("infer")
    assert result.outcome("infer", model="vit").stage == "infer vit"
    assert result.outcome("infer resnet").stage == "infer resnet"
    with pytest.raises(UserError, match=r"no stage 'infer bert' in this run; its stages: 'render'"):
        result.outcome("infer", model="bert")
    assert run_result(folder, ["m"]).outcome("infer").stage == "infer"


def test_a_run_results_repr_is_one_short_line(folder: Path) -> None:
    text = repr(run_result(folder, ["resnet", "vit"]))
    assert len(text) < 400 and "\n" not in text, text
    assert text.startswith("RunResult('0123456789ab', jobs=8, models=") and "infer vit: 8 computed" in text


# -- item 7: export folders and selections ---------------------------------------------------------
def export_args(spec: Path, out: Path, *more: str) -> list[str]:
    return ["export", str(spec), "--format", "imagefolder", "-o", str(out), "--where", "blur_sigma = 2", *more]


def test_append_is_suggested_only_where_it_works(ran: Path) -> None:
    other = ran.parent / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    line = one_error_line(export_args(ran, other))
    assert "not a sweep3d export, so --append cannot add to it" in line and "add --append" not in line

    out = ran.parent / "out"
    assert CliRunner().invoke(app, export_args(ran, out)).exit_code == 0
    assert "or add --append to add to the imagefolder export there" in one_error_line(export_args(ran, out))
    appended = CliRunner().invoke(app, export_args(ran, out, "--append"))  # the suggestion works
    assert appended.exit_code == 0 and "4 already in the export" in appended.output, appended.output
    line = one_error_line(["export", str(ran), "--format", "parquet", "-o", str(out)])
    assert "it is a imagefolder export" in line and "--append with --format imagefolder" in line


@pytest.mark.parametrize("form", ["parquet", "imagefolder"])
def test_an_export_that_selects_nothing_says_so_and_writes_nothing(ran: Path, form: str) -> None:
    out = ran.parent / "out"
    result = CliRunner().invoke(app, ["export", str(ran), "--format", form, "-o", str(out), "--where", "false"])
    assert result.exit_code == 0, result.output
    assert result.output.split("\n")[0] == f"nothing to export: no result meets --where 'false'; nothing written to {out}"
    assert not out.exists() and not list(ran.parent.glob(".out*"))
    exported = sweep3d.load(ran).export(form, out, where="false")
    assert (exported.added, exported.total, exported.written) == (0, 0, False) and not out.exists()


def _enospc(*args: Any, **kwargs: Any) -> None:
    raise OSError(errno.ENOSPC, "No space left on device")


def _arrow_enospc(*args: Any, **kwargs: Any) -> None:
    """What pyarrow raises writing Parquet to a full disk."""
    raise OSError(errno.ENOSPC, "Error writing bytes to file. Detail: [errno 28] No space left on device")


@pytest.mark.parametrize("form, patch, says", [
    ("imagefolder", (Staging, "place", _enospc), "No space left on device"),
    ("parquet", (export_parquet, "_write", _arrow_enospc), "Error writing bytes to file. Detail: [errno 28] No "
                                                           "space left on device")])
def test_an_export_on_a_full_disk_is_one_line_naming_the_folder(ran: Path, monkeypatch, form: str,
                                                                patch: tuple[Any, str, Any], says: str) -> None:
    monkeypatch.setattr(*patch)
    out = ran.parent / "out"
    result = CliRunner().invoke(app, ["export", str(ran), "--format", form, "-o", str(out)])
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]  # after the progress bar's
    assert result.exit_code == 2 and len(errors) == 1 and "Traceback" not in result.output, result.output
    assert errors[0] == (f"error: --output {out}: cannot write the export ({says}); nothing was written, free some "
                         "space or choose another folder")
    assert not out.exists() and not list(ran.parent.glob(".out*"))


# -- item 8: what a pandas user expects ------------------------------------------------------------
def test_the_dataframe_is_typed_for_pandas(ran: Path) -> None:
    exp = sweep3d.load(ran)
    frame = exp.dataframe()
    assert list(frame["environment"].cat.categories) == ["white", "studio"]  # spec order, not alphabetical
    assert list(frame["object"].cat.categories) == ["box"]
    assert frame.groupby("environment", observed=True)["correct"].mean().index.tolist() == ["white", "studio"]
    assert "orientation_pitch" in exp.results().column_names  # recorded: the default the spec never set
    assert not {"orientation_pitch", "orientation_roll"} & set(frame.columns)
    assert {"orientation_yaw", "blur_sigma"} <= set(frame.columns)
    assert frame["job"].dtype == pd.Int64Dtype() and frame["gt_x0"].dtype == pd.Int32Dtype()
    assert frame["gt_x0"].isna().all() and frame["blur_sigma"].dtype == np.float64


def test_control_accuracy_gives_each_level_as_a_number(ran: Path) -> None:
    rows = sweep3d.load(ran).sql("SELECT parameter, label, value FROM control_accuracy ORDER BY position, level",
                                 pandas=True)
    assert rows["value"].dtype == np.float64
    blur = rows[rows["parameter"] == "blur_sigma"]
    assert blur["value"].tolist() == [0.0, 2.0] and blur["label"].tolist() == ["0", "2"]
    assert rows[rows["parameter"] == "object"]["value"].isna().all()  # text: no number


def test_a_binned_levels_value_is_the_bins_centre(tmp_path: Path) -> None:
    from tests.helpers import make_store

    con = make_store(tmp_path, [{"c_x": float(x), "correct": x < 10} for x in range(20)])  # 20 values: 10 bins
    rows = con.execute("SELECT label, value FROM control_accuracy WHERE parameter = 'c_x' ORDER BY level").fetchall()
    assert len(rows) == 10 and rows[0] == ("0–1.9", pytest.approx(0.95)) and rows[-1][1] == pytest.approx(18.05)


def test_sql_answers_pandas_with_nullable_integers(ran: Path) -> None:
    exp = sweep3d.load(ran)
    query = "SELECT job, CASE WHEN job > 0 THEN job END AS maybe FROM results ORDER BY job"
    assert exp.sql(query).num_rows == 8  # a pyarrow Table by default
    frame = exp.sql(query, pandas=True)
    assert isinstance(frame, pd.DataFrame) and frame["maybe"].dtype == pd.Int64Dtype()
    assert frame["maybe"].isna().tolist() == [True] + [False] * 7 and frame["maybe"].iloc[1] == 1


def test_the_package_lists_load_and_its_errors() -> None:
    assert {"load", "Experiment", "SpecError", "PluginError", "UserError", "plugins"} <= set(dir(sweep3d))
    assert sweep3d.SpecError is SpecError and sweep3d.UserError is UserError and sweep3d.PluginError is PluginError
    with pytest.raises(sweep3d.SpecError):
        sweep3d.load({"experiment": {}})


# -- item 12: a post control's pixels --------------------------------------------------------------
class Scaled(PostControl):
    class Params(ControlParams):
        by: float = 1.0
        plus: float = 0.0

    def is_identity(self, values: dict[str, Any]) -> bool:
        return False

    def apply(self, image: np.ndarray, params: Any, rng: np.random.Generator) -> np.ndarray:
        return image * params.by + params.plus


def scaled(image: np.ndarray, by: float = 1.0, plus: float = 0.0, name: str = "mypost:Scaled") -> np.ndarray:
    return apply_post(image, [ControlInstance(Scaled("scaled", name), {})], {"scaled": {"by": by, "plus": plus}},
                      "ab" * 10)


@pytest.mark.parametrize("by, plus, says", [
    (255.0, 0.0, "returned values from 0 to 255 from apply(); return the image with values in [0, 1] (divide an "
                 "8-bit image by 255)"),
    (1e30, 0.0, "returned values from 0 to 1e+30 from apply(); return the image with values in [0, 1]"),
    (1.0, -0.5, "returned values from -0.5 to 0.5 from apply()"),
])
def test_a_post_control_out_of_range_is_refused_naming_it(by: float, plus: float, says: str) -> None:
    image = np.linspace(0, 1, 48, dtype=np.float32).reshape(4, 4, 3)
    with pytest.raises(PluginError) as caught:
        scaled(image, by, plus)
    assert str(caught.value).startswith("control 'mypost:Scaled' (id 'scaled') " + says), str(caught.value)


def test_a_post_controls_float_overshoot_is_clipped_and_nan_left_to_mark_the_image_invalid() -> None:
    image = np.linspace(0, 1, 48, dtype=np.float32).reshape(4, 4, 3)
    out = scaled(image, plus=5e-4)
    assert out.max() == 1.0 and out.min() == np.float32(5e-4)
    out = scaled(image, plus=-5e-4)
    assert out.min() == 0.0
    image[0, 0, 0] = np.nan  # non-finite pixels stay: they make the image invalid, counted apart
    assert np.isnan(scaled(image, plus=5e-4)[0, 0, 0]) and np.nanmax(scaled(image, plus=5e-4)) == 1.0


# -- item 14: a policy that is not a Policy --------------------------------------------------------
class NotAPolicy:
    """Has what a policy has but is none (no ``Params``): as a user's typo might name."""


def not_a_policy() -> None:
    """A function where a class is named."""


@pytest.mark.parametrize("name, says", [("mypolicy:NotAPolicy", "is class NotAPolicy"),
                                        ("mypolicy:function", "is a function")])
def test_a_policy_type_that_is_not_a_policy_is_one_line(folder: Path, name: str, says: str) -> None:
    (folder / "mypolicy.py").write_text("class NotAPolicy:\n    pass\n\n\ndef function():\n    pass\n")
    spec = folder / "spec.toml"
    spec.write_text(TINY_SPEC.replace('type = "grid"', f'type = "{name}"'))
    line = one_error_line(["plan", str(spec)])
    assert line == (f"error: {spec}: policy.type: '{name}' {says}, not a sweep3d Policy subclass; a policy "
                    "subclasses sweep3d.plugins.Policy and returns its points from points()")


@pytest.mark.parametrize("policy", [NotAPolicy, not_a_policy])
def test_a_policy_object_that_is_not_a_policy_is_a_spec_error_in_python(folder: Path, policy: Any) -> None:
    spec = raw()
    spec["policy"] = {"type": policy}
    with pytest.raises(SpecError, match=r"<dict>: policy\.type: .* not a sweep3d Policy subclass"):
        sweep3d.load(spec, base=folder)
    spec["policy"] = {"type": GridPolicy}  # a Policy is fine
    assert sweep3d.load(spec, base=folder).spec.policy is not None
