"""Designs a protocol can state: listed values crossed with the draws, jobs from a table (and the
jobs of any plan written as one), shared tables from included files. Plans only, nothing rendered."""

from __future__ import annotations

import csv
import random
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.core.errors import SpecError
from sweep3d.spec.framing import Framing
from sweep3d.stages.plan import count_jobs, make_plan
from sweep3d.stages.plan.design import write_design
from tests.helpers import (
    every_job,
    load_spec,
    make_store,
    paired_spec,
    rows_of,
    scene_values,
    spec_toml,
    write_cube,
    write_spec,
)


#: Two objects on white, plus two backgrounds; skins on white only. What a published protocol asks:
#: the same poses everywhere, and every skin on the first few of them.
def protocol_spec(*, seed: int, samples: int, first: int, skins: str) -> str:
    return spec_toml("protocol", seed=seed, render={"resolution": 32, "samples": 1}, objects=("box", "crate"),
                     environments=("white", "grey", ("black", {"color": [0.0, 0.0, 0.0]})), body=f"""\
[[controls]]
type = "orientation"
yaw = {{ range = [-180, 180] }}
pitch = {{ range = [-20, 20] }}

[[controls]]
type = "material"
skin = {skins}
environments = ["white"]

[policy]
type = "random"
samples = {samples}
cross = {{ environment = true, "material.skin" = {first} }}
""")


SKINS = '["original", "zebra", "tiger", "cow"]'


def planned(folder: Path, body: str, name: str = "spec.toml"):
    folder.mkdir(parents=True, exist_ok=True)
    return make_plan(load_spec(write_spec(folder, body, name=name)), framing=Framing.full(32), model_digest="m",
                     blender="4.5.0")


def poses(plan, scene: tuple[str, str]) -> list[tuple[float, float]]:
    return [(v["yaw"], v["pitch"]) for v in scene_values(plan, "orientation")[scene]]


def skins_of(plan, scene: tuple[str, str]) -> list[str]:
    return [j.values["material"]["skin"] for j in sorted(every_job(plan), key=lambda j: j.index) if j.scene == scene]


def protocol(folder: Path, *, seed: int = 1, samples: int = 20, first: int = 5, skins: str = SKINS):
    return planned(folder, protocol_spec(seed=seed, samples=samples, first=first, skins=skins))


# -- crossing ----------------------------------------------------------------------------------------


def test_crossing_puts_every_skin_on_the_same_first_poses_and_every_environment_on_all(tmp_path: Path) -> None:
    plan = protocol(tmp_path / "a")
    for obj in ("box", "crate"):
        white = poses(plan, (obj, "white"))
        skins = skins_of(plan, (obj, "white"))
        assert len(white) == 20 + 5 * 3  # 20 draws in the original, 3 more skins on the first 5
        drawn = list(dict.fromkeys(white))
        assert len(drawn) == 20
        assert poses(plan, (obj, "grey")) == drawn == poses(plan, (obj, "black"))  # the same poses everywhere
        for skin in ("zebra", "tiger", "cow"):
            assert [p for p, s in zip(white, skins) if s == skin] == drawn[:5]
        assert [p for p, s in zip(white, skins) if s == "original"] == drawn
        assert skins[:4] == ["original", "zebra", "tiger", "cow"]  # draw by draw, in list order
    assert poses(plan, ("box", "white")) != poses(plan, ("crate", "white"))  # paired per object
    assert count_jobs(plan.spec) == len(every_job(plan)) == 2 * (35 + 20 + 20)


def test_crossed_draws_do_not_depend_on_the_crossed_list_or_on_how_many_draws_it_crosses(tmp_path: Path) -> None:
    """The policy draws the rest without the crossed list: a skin more, or crossing all 20 draws,
    keeps the poses (so renders already made are reused)."""
    base = protocol(tmp_path / "a")
    for i, variant in enumerate([dict(skins='["original", "zebra"]'), dict(first=20), dict(samples=30)]):
        other = protocol(tmp_path / f"v{i}", **variant)
        drawn = list(dict.fromkeys(poses(other, ("box", "grey"))))
        assert drawn[:20] == poses(base, ("box", "grey"))


def test_crossing_every_draw_is_the_product_with_the_list(tmp_path: Path) -> None:
    body = paired_spec(seed=3, policy='type = "sobol"\nsamples = 4\ncross = ["blur.sigma", "orientation.pitch"]')
    plan = planned(tmp_path / "a", body)
    for scene, values in scene_values(plan, "blur").items():
        pitches = [v["pitch"] for v in scene_values(plan, "orientation")[scene]]
        combos = list(zip([v["sigma"] for v in values], pitches))
        assert len(combos) == 4 * 3 * 3 and len(set(combos)) == 9
        assert all(combos.count(c) == 4 for c in set(combos))
    assert count_jobs(plan.spec) == len(every_job(plan))


# -- a paired protocol in one spec: its statistics ----------------------------------------------------


def test_one_protocol_spec_gives_paired_statistics_for_environments_and_skins(tmp_path: Path) -> None:
    """Results of the protocol (a made-up model's answers) pair each skin with the original on
    the same 5 poses, and each background with white on the same 20 poses."""
    plan = protocol(tmp_path / "a")
    table = plan.jobs.columns.table("e", plan.spec.parameter_columns)
    rng = random.Random(0)
    rows = [{k: r[k] for k in ("object", "environment", "orientation_yaw", "orientation_pitch", "material_skin")}
            | {"correct": rng.random() < 0.6} for r in table.to_pylist()]
    con = make_store(tmp_path / "s", rows)
    values = {(r["parameter"], r["value_a"], r["value_b"]): r for r in rows_of(con, "SELECT * FROM paired_values")}
    for skin in ("zebra", "tiger", "cow"):
        pair = values.get(("material_skin", "original", skin))
        flipped = pair is None  # this store has no list order: values come in text order
        pair = pair or values[("material_skin", skin, "original")]
        assert pair["n"] == 2 * 5
        expected = sum(a["correct"] and not b["correct"] for a, b in _twins(rows, "original", skin))
        assert pair["a_wrong_b_right" if flipped else "a_right_b_wrong"] == expected
    for env in ("grey", "black"):
        assert values[("environment", "white", env)]["n"] == 2 * 20
    # white's twin of a background job is the original-skin job of the same pose
    jobs = rows_of(con, "SELECT job_a FROM paired_jobs WHERE parameter = 'environment' AND value_b = 'grey'")
    assert len(jobs) == 40 and {rows[j["job_a"]]["material_skin"] for j in jobs} == {"original"}


def _twins(rows: list[dict], a: str, b: str) -> list[tuple[dict, dict]]:
    by_pose = {(r["object"], r["orientation_yaw"], r["orientation_pitch"]): r for r in rows
               if r["environment"] == "white" and r["material_skin"] == a}
    return [(by_pose[(r["object"], r["orientation_yaw"], r["orientation_pitch"])], r) for r in rows
            if r["environment"] == "white" and r["material_skin"] == b]


# -- designs from a table -----------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_design_written_by_one_plan_replays_as_the_same_jobs(tmp_path: Path, suffix: str) -> None:
    first = protocol(tmp_path / "a")
    design = tmp_path / f"design{suffix}"
    rows = write_design(first.jobs.columns.table("e", first.spec.parameter_columns), first.spec.parameter_columns,
                        design)
    body = protocol_spec(seed=99, samples=3, first=1, skins=SKINS).replace(
        "[policy]\ntype = \"random\"", f"[policy]\ntype = \"table\"\nfile = \"../{design.name}\"\n[unused]")
    body = body[: body.index("[unused]")]
    again = planned(tmp_path / "b", body)
    key = lambda j: (j.object, j.environment, j.values, j.render_key, j.image_key, j.pred_key)  # noqa: E731
    assert rows == len(every_job(first))
    assert [key(j) for j in every_job(again)] == [key(j) for j in every_job(first)]


def test_the_jobs_table_equals_the_design_table_given(tmp_path: Path) -> None:
    rng = random.Random(5)
    given = [["object", "environment", "orientation_yaw", "orientation_pitch", "material_skin"]]
    for obj in ("box", "crate"):
        for env in ("white", "grey", "black"):
            for _ in range(4):
                given.append([obj, env, repr(rng.uniform(-180, 180)), repr(rng.uniform(-20, 20)),
                              rng.choice(["zebra", "cow"]) if env == "white" else ""])
    _write_csv(tmp_path / "given.csv", given)
    plan = planned(tmp_path / "s", _table_spec("../given.csv"))
    table = plan.jobs.columns.table("e", plan.spec.parameter_columns)
    got = [[str(v) if not isinstance(v, float) else repr(v) for v in row]
           for row in zip(*(table.column(n).to_pylist() for n in given[0]))]
    assert [[c if c != "" else "None" for c in row] for row in given[1:]] == got


def _table_spec(file: str) -> str:
    body = protocol_spec(seed=1, samples=1, first=1, skins=SKINS)
    return body[: body.index("[policy]")] + f'[policy]\ntype = "table"\nfile = "{file}"\n'


def _write_csv(path: Path, rows: list[list[str]]) -> None:
    with path.open("w", newline="") as handle:
        csv.writer(handle).writerows(rows)


HEADER = ["object", "environment", "orientation_yaw", "orientation_pitch", "material_skin"]


@pytest.mark.parametrize("row, where, problem", [
    (["box", "white", "400", "0", "zebra"], "row 2, column orientation_yaw", "outside the range [-180, 180]"),
    (["box", "white", "ten", "0", "zebra"], "row 2, column orientation_yaw", "not a number"),
    (["box", "white", "nan", "0", "zebra"], "row 2, column orientation_yaw", "not a finite number"),
    (["boxx", "white", "0", "0", "zebra"], "row 2, column object", "did you mean 'box'"),
    (["box", "mauve", "0", "0", "zebra"], "row 2, column environment", "not one of the spec's environments"),
    (["box", "white", "0", "0", "okapi"], "row 2, column material_skin", "not one of the values the spec lists"),
    (["box", "grey", "0", "0", "zebra"], "row 2, column material_skin", "does not apply"),
    (["box", "white", "0", "", "zebra"], "row 2, column orientation_pitch", "is empty"),
    (["box", "white", "0", "0"], "row 2", "has 4 cells where the header has 5"),
])
def test_a_bad_design_row_is_one_line_naming_the_row_and_column(tmp_path: Path, row: list[str], where: str,
                                                                 problem: str) -> None:
    _write_csv(tmp_path / "d.csv", [HEADER, ["box", "white", "0", "0", "zebra"], row])
    with pytest.raises(SpecError) as caught:
        load_spec(write_spec(tmp_path, _table_spec("d.csv")))
    assert caught.value.file.endswith("d.csv") and caught.value.key == where
    assert problem in caught.value.problem and "\n" not in str(caught.value)


@pytest.mark.parametrize("header, where, problem", [
    (["object", "environment", "orientation_yaw", "orientation_pitch", "material_skn"], "column material_skn",
     "did you mean 'material_skin'"),
    (["object", "orientation_yaw", "orientation_pitch", "material_skin"], "column environment", "is missing"),
    (["object", "environment", "orientation_yaw", "material_skin"], "column orientation_pitch", "is missing"),
])
def test_a_bad_design_header_is_one_line_naming_the_column(tmp_path: Path, header: list[str], where: str,
                                                           problem: str) -> None:
    cells = {"object": "box", "environment": "white", "material_skin": "zebra"}
    _write_csv(tmp_path / "d.csv", [header, [cells.get(name, "0") for name in header]])
    with pytest.raises(SpecError) as caught:
        load_spec(write_spec(tmp_path, _table_spec("d.csv")))
    assert caught.value.key == where and problem in caught.value.problem


def test_a_design_without_rows_is_refused(tmp_path: Path) -> None:
    _write_csv(tmp_path / "d.csv", [HEADER])
    with pytest.raises(SpecError, match="has no rows"):
        load_spec(write_spec(tmp_path, _table_spec("d.csv")))


def test_plan_design_writes_the_table_and_refuses_a_bad_file_before_planning(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, protocol_spec(seed=1, samples=2, first=1, skins=SKINS))
    runner = CliRunner()
    out = runner.invoke(app, ["plan", str(spec), "--design", str(tmp_path / "d.csv")])
    assert out.exit_code == 0, out.output
    with (tmp_path / "d.csv").open() as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == HEADER and len(rows) == 1 + 2 * ((4 + 1) + 2 + 2)  # white: 4 skins on draw 1, 1 on draw 2
    bad = runner.invoke(app, ["plan", str(spec), "--design", str(tmp_path / "d.txt")])
    assert bad.exit_code == 2 and ".csv or .parquet" in bad.output and not (tmp_path / "d.txt").exists()


# -- include ------------------------------------------------------------------------------------------


def _shared(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    write_cube(folder)
    (folder / "shared.toml").write_text(
        '[render]\nresolution = 32\nsamples = 1\n\n[[objects]]\nname = "box"\nmesh = "cube.obj"\nlabels = ["carton"]\n\n'
        '[[environments]]\nname = "white"\ncolor = [1.0, 1.0, 1.0]\n')


def test_include_joins_lists_merges_tables_and_resolves_paths_against_the_included_file(tmp_path: Path) -> None:
    _shared(tmp_path / "common")
    study = tmp_path / "study"
    study.mkdir()
    (study / "spec.toml").write_text(
        'include = ["../common/shared.toml"]\n[experiment]\nname = "s"\n[render]\nsamples = 2\n\n'
        '[[objects]]\nname = "crate"\nmesh = "../common/cube.obj"\nlabels = ["crate"]\n')
    loaded = load_spec(study / "spec.toml")
    assert [o.name for o in loaded.objects] == ["box", "crate"]
    assert loaded.meshes["box"] == str((tmp_path / "common" / "cube.obj").resolve())
    assert (loaded.render.resolution, loaded.render.samples) == (32, 2)  # the including file's keys win
    assert "# ---- included:" in loaded.text() and 'name = "box"' in loaded.text()


def test_an_error_in_an_included_entry_names_its_file_and_index(tmp_path: Path) -> None:
    _shared(tmp_path)
    (tmp_path / "shared.toml").write_text((tmp_path / "shared.toml").read_text().replace("carton", "cartonx"))
    (tmp_path / "spec.toml").write_text('include = "shared.toml"\n[experiment]\nname = "s"\n')
    with pytest.raises(SpecError) as caught:
        load_spec(tmp_path / "spec.toml")
    assert caught.value.file == str(tmp_path / "shared.toml") and caught.value.key == "objects[0].labels[0]"


@pytest.mark.parametrize("include, problem", [
    ('"missing.toml"', "cannot read 'missing.toml'"),
    ('["shared.toml", "shared.toml"]', "included twice"),
    ('"spec.toml"', "includes itself"),
    ("3", "must be a path or a list of paths"),
    ('"bad.toml"', "must be an array of tables"),
])
def test_a_bad_include_is_one_line(tmp_path: Path, include: str, problem: str) -> None:
    _shared(tmp_path)
    (tmp_path / "bad.toml").write_text('objects = "box"\n')
    (tmp_path / "spec.toml").write_text(f'include = {include}\n[experiment]\nname = "s"\n')
    with pytest.raises(SpecError) as caught:
        load_spec(tmp_path / "spec.toml")
    assert caught.value.key in ("include", "objects") and problem in caught.value.problem


# -- what a new user ran into ---------------------------------------------------------------------------


def test_sobol_crossed_with_the_environment_pairs_scenes_that_differ_only_in_a_crossed_control(
        tmp_path: Path) -> None:
    """The skin applies on white only; crossed, it leaves nothing to draw, so it leaves Sobol's seed
    and white gets grey's points."""
    body = protocol_spec(seed=1, samples=8, first=2, skins=SKINS).replace('type = "random"', 'type = "sobol"')
    plan = planned(tmp_path / "a", body)
    for obj in ("box", "crate"):
        assert list(dict.fromkeys(poses(plan, (obj, "white")))) == poses(plan, (obj, "grey")) == \
            poses(plan, (obj, "black"))


def test_a_csv_design_reads_back_an_empty_listed_value_a_bom_and_blank_lines(tmp_path: Path) -> None:
    body = paired_spec(seed=3, policy='type = "random"\nsamples = 3') + \
        '\n[[controls]]\ntype = "background"\ncolor = ["", "#ffffff"]\n'
    first = planned(tmp_path / "a", body.replace("[policy]", "[policy]\n", 1))
    design = tmp_path / "d.csv"
    write_design(first.jobs.columns.table("e", first.spec.parameter_columns), first.spec.parameter_columns, design)
    assert ",," in design.read_text() or design.read_text().count(",\n")  # "" is written as an empty cell
    design.write_text("\ufeff" + design.read_text() + "\n\n")  # Excel's byte order mark, blank lines at the end
    table = body[: body.index("[policy]")] + '[policy]\ntype = "table"\nfile = "../d.csv"\n' + \
        body[body.index("[policy]") + len('[policy]\ntype = "random"\nsamples = 3'):]
    again = planned(tmp_path / "b", table)
    key = lambda j: (j.scene, j.values, j.render_key)  # noqa: E731
    assert [key(j) for j in every_job(again)] == [key(j) for j in every_job(first)]


def test_a_design_cell_may_name_a_file_as_the_spec_does(tmp_path: Path) -> None:
    from PIL import Image

    Image.new("RGB", (4, 4), (200, 10, 10)).save(tmp_path / "a.png")
    Image.new("RGB", (4, 4), (10, 10, 200)).save(tmp_path / "b.png")
    spec = _table_spec("d.csv").replace('skin = ["original", "zebra", "tiger", "cow"]',
                                        'skin = "image"\nimage = ["a.png", "b.png"]')
    _write_csv(tmp_path / "d.csv", [["object", "environment", "orientation_yaw", "orientation_pitch",
                                     "material_image"], ["box", "white", "0", "0", "b.png"],
                                    ["box", "white", "0", "0", str(tmp_path / "a.png")]])
    plan = planned(tmp_path, spec)
    images = [j.values["material"]["image"] for j in every_job(plan)]
    assert images == [str((tmp_path / "b.png").resolve()), str((tmp_path / "a.png").resolve())]


def test_errors_after_an_include_name_the_entry_in_its_own_file(tmp_path: Path) -> None:
    _shared(tmp_path)
    (tmp_path / "shared.toml").write_text((tmp_path / "shared.toml").read_text()
                                          + '\n[[controls]]\ntype = "orientation"\nyaw = [0, 90]\n')
    (tmp_path / "spec.toml").write_text('include = "shared.toml"\n[experiment]\nname = "s"\n\n'
                                        '[[controls]]\ntype = "blur"\nsigma = [0, -1]\n')
    with pytest.raises(SpecError) as caught:
        load_spec(tmp_path / "spec.toml")
    assert caught.value.file == str(tmp_path / "spec.toml") and caught.value.key == "controls[0].sigma"
    (tmp_path / "shared.toml").write_text('[experiment]\nnmae = "x"\n' + (tmp_path / "shared.toml").read_text())
    (tmp_path / "spec.toml").write_text('include = "shared.toml"\n[experiment]\nname = "s"\n')
    with pytest.raises(SpecError) as caught:
        load_spec(tmp_path / "spec.toml")
    assert caught.value.file == str(tmp_path / "shared.toml") and caught.value.key == "experiment.nmae"


def test_a_policy_of_another_type_replaces_the_included_one_whole(tmp_path: Path) -> None:
    _shared(tmp_path)
    (tmp_path / "shared.toml").write_text((tmp_path / "shared.toml").read_text()
                                          + '\n[policy]\ntype = "grid"\nsamples_per_dim = 3\n')
    (tmp_path / "spec.toml").write_text('include = "shared.toml"\n[experiment]\nname = "s"\n'
                                        '[policy]\ntype = "random"\nsamples = 5\n')
    assert load_spec(tmp_path / "spec.toml").spec.policy.model_extra == {"samples": 5}
    (tmp_path / "spec.toml").write_text('include = "shared.toml"\n[experiment]\nname = "s"\n'
                                        '[policy]\nsamples_per_dim = 2\n')
    assert load_spec(tmp_path / "spec.toml").policy.params.samples_per_dim == 2  # same type: merged


def test_a_plug_in_beside_an_included_file_is_found(tmp_path: Path) -> None:
    shared = tmp_path / "common"
    _shared(shared)
    (shared / "sharedpost.py").write_text(
        "from sweep3d.plugins import PostControl, ControlParams\n\n"
        "class Dim(PostControl):\n    class Params(ControlParams):\n        by: float = 1.0\n\n"
        "    def apply(self, image, params, rng):\n        return image * params.by\n")
    (shared / "shared.toml").write_text((shared / "shared.toml").read_text()
                                        + '\n[[controls]]\ntype = "sharedpost:Dim"\nby = [1.0, 0.5]\n')
    (tmp_path / "spec.toml").write_text('include = "common/shared.toml"\n[experiment]\nname = "s"\n')
    assert [c.id for c in load_spec(tmp_path / "spec.toml").controls] == ["Dim"]
