"""sweep3d.spec.load_spec: user mistakes become one-line SpecErrors; valid specs load into spaces."""

from __future__ import annotations

import sys
import textwrap
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.errors import SpecError
from sweep3d.spec import Choice, Fixed, Range
from sweep3d.spec.space import Point, SearchSpace
from sweep3d.stages import load_spec
from tests.conftest import CUBE_OBJ, TINY_SPEC, write_cube, write_spec

BASE = TINY_SPEC.replace('name = "tiny"\nseed = 7\nstore = "store"', 'name = "mistakes"\nseed = 3')

# A user's control plug-in with a string and an integer parameter (no built-in has either).
USER_MODULE = "sweep3d_test_user_controls"
USER_CONTROLS = '''\
from pydantic import Field

from sweep3d.controls import ControlParams
from sweep3d.stages.postprocess.controls import PostControl


class Tint(PostControl):
    class Params(ControlParams):
        mode: str = "none"
        count: int = Field(0, ge=0, le=100)

    def apply(self, image, params, rng):
        return image


class Pair(PostControl):
    """Parameters whose columns can collide with the tables' own or with each other's."""

    class Params(ControlParams):
        key: str = ""
        a_b: str = ""
        b: str = ""

    def apply(self, image, params, rng):
        return image


class NotAControl:
    pass
'''


@pytest.fixture
def user_controls(tmp_path_factory, monkeypatch) -> str:
    folder = tmp_path_factory.mktemp("user_module")
    (folder / f"{USER_MODULE}.py").write_text(USER_CONTROLS)
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.delitem(sys.modules, USER_MODULE, raising=False)
    return USER_MODULE


def edit(old: str, new: str) -> Callable[[str], str]:
    def apply(body: str) -> str:
        assert old in body, old
        return body.replace(old, new, 1)

    return apply


def append(extra: str) -> Callable[[str], str]:
    return lambda body: body + "\n" + textwrap.dedent(extra)


@dataclass
class Mistake:
    id: str
    change: Callable[[str], str]
    key: str
    expect: tuple[str, ...]  # substrings of the message that say what is expected
    setup: Callable[[Path], None] | None = None


def _zip_with_other_member(folder: Path) -> None:
    with zipfile.ZipFile(folder / "furniture.zip", "w") as zf:
        zf.writestr("chairs/chair.obj", CUBE_OBJ)  # a real mesh: a vertex-only OBJ fails the load-time check


def _text_mesh(folder: Path) -> None:
    (folder / "cube.txt").write_text("v 0 0 0\n")


USER_TYPE = f'type = "{USER_MODULE}:Tint"'

MISTAKES = [
    Mistake("invalid-toml", lambda body: body.replace('[render]', '[render', 1), "", ("not valid TOML",)),
    Mistake("unknown-top-level", append("[extras]\nx = 1\n"), "extras", ("unknown key", "spelling")),
    Mistake("missing-experiment", lambda body: body.replace('[experiment]\nname = "mistakes"\nseed = 3\n', ""),
            "experiment", ("required",)),
    Mistake("misspelt-render-key", edit("samples = 1", "sampels = 1"), "render.sampels", ("unknown key",)),
    Mistake("samples-wrong-type", edit("samples = 1", 'samples = "many"'), "render.samples",
            ("valid integer", "'many'")),
    Mistake("samples-negative", edit("samples = 1", "samples = -3"), "render.samples",
            ("greater than or equal to 1", "-3")),
    Mistake("timeout-infinite", edit("samples = 1", "samples = 1\ntimeout = inf"), "render.timeout", ("finite",)),
    Mistake("mesh-missing", edit('mesh = "cube.obj"', 'mesh = "missing.obj"'), "objects[0].mesh",
            ("missing.obj", "does not exist", "relative to the spec")),
    Mistake("mesh-suffix", edit('mesh = "cube.obj"', 'mesh = "cube.txt"'), "objects[0].mesh",
            ("unsupported mesh format", ".txt", ".obj", ".glb"), _text_mesh),
    Mistake("zip-member-missing", edit('mesh = "cube.obj"', 'mesh = "furniture.zip#chairs/table.obj"'),
            "objects[0].mesh", ("no member", "chairs/table.obj"), _zip_with_other_member),
    Mistake("hdri-builtin-unknown", edit('"builtin:studio"', '"builtin:nope"'), "environments[1].hdri",
            ("'nope'", "builtin:studio")),
    Mistake("hdri-path-missing", edit('"builtin:studio"', '"maps/sky.exr"'), "environments[1].hdri",
            ("sky.exr", "does not exist", "builtin:NAME")),
    Mistake("env-hdri-and-color", edit('hdri = "builtin:studio"', 'hdri = "builtin:studio"\ncolor = [0.0, 0.0, 0.0]'),
            "environments[1]", ("exactly one of hdri", "color")),
    Mistake("env-neither", edit('hdri = "builtin:studio"', "strength = 2.0"), "environments[1]", ("exactly one",)),
    Mistake("color-out-of-range", edit("color = [1.0, 1.0, 1.0]", "color = [1.0, 1.5, 1.0]"),
            "environments[0].color", ("between 0 and 1", "1.5")),
    Mistake("label-unknown", edit('labels = ["carton"]', 'labels = ["cartn"]'), "objects[0].labels[0]",
            ("'cartn'", "did you mean", "'carton'")),
    Mistake("label-id-out-of-range", edit('labels = ["carton"]', "labels = [1000]"), "objects[0].labels[0]",
            ("1000", "out of range", "0..999")),
    Mistake("labels-empty", edit('labels = ["carton"]', "labels = []"), "objects[0].labels", ("at least 1",)),
    Mistake("control-type-unknown", edit('type = "orientation"', 'type = "orientaton"'), "controls[0].type",
            ("'orientaton'", "did you mean 'orientation'", "valid:", "blur", "camera", "scale")),
    Mistake("control-type-missing", edit('type = "orientation"\n', ""), "controls[0].type",
            ("required", "orientation", "blur")),
    Mistake("control-type-not-a-control", edit('type = "blur"', f'type = "{USER_MODULE}:NotAControl"'),
            "controls[1].type", ("not a sweep3d Control",)),
    Mistake("control-param-unknown", edit("yaw = [0, 45]", "yaww = [0, 45]"), "controls[0].yaww",
            ("unknown parameter", "did you mean 'yaw'", "pitch", "roll")),
    Mistake("control-value-out-of-bounds", edit("sigma = [0.0, 1.5]", "sigma = -1.0"), "controls[1].sigma",
            ("greater than or equal to 0", "-1.0")),
    Mistake("range-empty", edit("yaw = [0, 45]", "yaw = { range = [5, 5] }"), "controls[0].yaw",
            ("empty range", "low must be below high")),
    Mistake("range-reversed", edit("yaw = [0, 45]", "yaw = { range = [90, -90] }"), "controls[0].yaw",
            ("low must be below high",)),
    Mistake("range-nan", edit("yaw = [0, 45]", "yaw = { range = [nan, 10] }"), "controls[0].yaw",
            ("finite", "nan")),
    Mistake("range-inf", edit("yaw = [0, 45]", "yaw = { range = [0, inf] }"), "controls[0].yaw",
            ("finite", "inf")),
    Mistake("range-minus-inf", edit("sigma = [0.0, 1.5]", "sigma = { range = [-inf, 1] }"), "controls[1].sigma",
            ("finite",)),
    Mistake("scalar-nan", edit("yaw = [0, 45]", "yaw = nan"), "controls[0].yaw", ("not a finite number",)),
    Mistake("choice-inf", edit("yaw = [0, 45]", "yaw = [0, inf]"), "controls[0].yaw", ("not a finite number",)),
    Mistake("range-bad-keys", edit("yaw = [0, 45]", "yaw = { from = 0, to = 90 }"), "controls[0].yaw",
            ("range = [low, high]",)),
    Mistake("range-log-low-zero", edit("sigma = [0.0, 1.5]", "sigma = { range = [0, 2], log = true }"),
            "controls[1].sigma", ("log range needs low > 0",)),
    Mistake("range-on-string-param", append(f'[[controls]]\n{USER_TYPE}\nmode = {{ range = [0, 1] }}\n'),
            "controls[2].mode", ("needs a numeric parameter", "use a list")),
    Mistake("range-int-param-fraction", append(f'[[controls]]\n{USER_TYPE}\ncount = {{ range = [0.5, 3] }}\n'),
            "controls[2].count", ("integer", "0.5")),
    Mistake("control-id-duplicate", append('[[controls]]\ntype = "blur"\nsigma = 2.0\n'), "controls[2].id",
            ("'blur'", "used twice", "id = ")),
    Mistake("control-id-invalid", append('[[controls]]\ntype = "blur"\nid = "my blur"\n'), "controls[2].id",
            ("letters, digits and underscores",)),
    Mistake("control-objects-unknown", edit("yaw = [0, 45]", 'yaw = [0, 45]\nobjects = ["nope"]'),
            "controls[0].objects", ("'nope'", "valid: box")),
    Mistake("control-environments-unknown", edit("yaw = [0, 45]", 'yaw = [0, 45]\nenvironments = ["whit"]'),
            "controls[0].environments", ("'whit'", "studio", "white")),
    Mistake("policy-type-unknown", edit('type = "grid"', 'type = "gird"'), "policy.type",
            ("'gird'", "did you mean 'grid'", "random")),
    Mistake("policy-param-unknown", edit('type = "grid"', 'type = "grid"\nsamples_per_dimm = 3'),
            "policy.samples_per_dimm", ("unknown key",)),
    Mistake("policy-samples-zero", edit('type = "grid"', 'type = "random"\nsamples = 0'), "policy.samples",
            ("greater than or equal to 1",)),
    Mistake("object-name-duplicate", append('[[objects]]\nname = "box"\nmesh = "cube.obj"\nlabels = ["carton"]\n'),
            "objects", ("duplicate object name 'box'", "[1]", "unique")),
    Mistake("environment-name-duplicate", append('[[environments]]\nname = "white"\ncolor = [0.0, 0.0, 0.0]\n'),
            "environments", ("duplicate environment name 'white'", "[2]")),
    Mistake("material-image-missing",
            append('[[controls]]\ntype = "material"\nskin = "image"\nimage = ["textures/none.png"]\n'),
            "controls[2].image", ("textures/none.png", "no such file", "relative to the spec file")),
    Mistake("part-visibility-not-a-bool", append('[report]\npart_visibility = "yes please"\n'),
            "report.part_visibility", ("valid boolean",)),
    Mistake("report-key-unknown", append("[report]\npart_visiblity = true\n"), "report.part_visiblity",
            ("unknown key",)),
    Mistake("column-shadows-a-key", append(f'[[controls]]\ntype = "{USER_MODULE}:Pair"\nid = "render"\nkey = "x"\n'),
            "controls[2].key", ("'render_key'", "results table's own", "id = ")),
    Mistake("columns-collide", append(f'[[controls]]\ntype = "{USER_MODULE}:Pair"\nid = "p"\na_b = "x"\n'
                                      f'[[controls]]\ntype = "{USER_MODULE}:Pair"\nid = "p_a"\nb = "y"\n'),
            "controls[3].b", ("'p_a_b'", "controls[2]", "id = ")),
    Mistake("model-unknown", edit("[model]\n", '[model]\nname = "efficientnet-lite1"\n'),
            "model.name", ("'efficientnet-lite1'", "efficientnet-lite0", "module:Name")),
]


@pytest.mark.parametrize("mistake", MISTAKES, ids=[m.id for m in MISTAKES])
def test_user_mistake_is_a_spec_error_naming_file_and_key(tmp_path, user_controls, mistake: Mistake):
    if mistake.setup is not None:
        mistake.setup(tmp_path)
    path = write_spec(tmp_path, mistake.change(BASE))

    with pytest.raises(SpecError) as caught:
        load_spec(path)

    err = caught.value
    message = str(err)
    assert err.file == str(path)
    assert message.startswith(str(path))
    assert err.key == mistake.key
    if mistake.key:
        assert f"{path}: {mistake.key}: " in message
    for text in mistake.expect:
        assert text in message, f"{text!r} not in {message!r}"
    assert "\n" not in message


def test_base_spec_of_the_mistakes_table_is_valid(tmp_path, user_controls):
    """The table above must fail because of its one edit, not because the base is broken."""
    loaded = load_spec(write_spec(tmp_path, BASE))
    assert [c.id for c in loaded.controls] == ["orientation", "blur"]


def test_missing_spec_file(tmp_path):
    path = tmp_path / "nowhere" / "spec.toml"
    with pytest.raises(SpecError) as caught:
        load_spec(path)
    assert caught.value.file == str(path)
    assert str(path) in str(caught.value)
    assert "no such spec file" in str(caught.value)


@pytest.mark.parametrize(
    "make",
    [
        lambda folder: write_spec(folder, BASE.replace('samples = 1', 'samples = "many"')),
        lambda folder: folder / "absent.toml",
    ],
    ids=["bad-value", "missing-file"],
)
def test_cli_prints_one_line_and_exits_2(tmp_path, make):
    path = make(tmp_path)
    result = CliRunner().invoke(app, ["plan", str(path)])
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("error:")
    assert path.name in lines[0]


# -- valid specs -----------------------------------------------------------------------------


def test_relative_paths_resolve_against_the_spec_folder(tmp_path, monkeypatch):
    project = tmp_path / "project"
    (project / "specs").mkdir(parents=True)
    (project / "meshes").mkdir()
    mesh = write_cube(project / "meshes")
    body = BASE.replace('mesh = "cube.obj"', 'mesh = "../meshes/cube.obj"').replace(
        'seed = 3', 'seed = 3\nstore = "../cache"'
    )
    write_spec(project / "specs", body, cube=False)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)

    loaded = load_spec(Path("..") / "project" / "specs" / "spec.toml")

    assert Path(loaded.meshes["box"]) == mesh.resolve()
    assert loaded.store.resolve() == (project / "cache").resolve()
    # a control's file parameter (a material's image texture) resolves the same way
    texture = project / "specs" / "textures" / "wood.png"
    texture.parent.mkdir()
    texture.write_bytes(b"not looked into at load")
    spec = project / "specs" / "spec.toml"
    spec.write_text(spec.read_text() + '[[controls]]\ntype = "material"\nskin = "image"\nimage = "textures/wood.png"\n')
    material = load_spec(Path("..") / "project" / "specs" / "spec.toml").controls[-1]
    assert material.spaces["image"] == Fixed(str(texture.resolve()))
    assert Path(loaded.hdris["studio"]).is_file()
    assert loaded.hdris["white"] is None


def test_zip_member_mesh_resolves(tmp_path):
    _zip_with_other_member(tmp_path)
    path = write_spec(tmp_path, BASE.replace('mesh = "cube.obj"', 'mesh = "furniture.zip#chairs/chair.obj"'))
    loaded = load_spec(path)
    archive, _, member = loaded.meshes["box"].partition("#")
    assert Path(archive) == (tmp_path / "furniture.zip").resolve()
    assert member == "chairs/chair.obj"


def _spaces(tmp_path: Path, controls: str) -> dict[str, dict]:
    body = BASE.split("[[controls]]")[0] + textwrap.dedent(controls)
    loaded = load_spec(write_spec(tmp_path, body))
    return {c.id: c.spaces for c in loaded.controls}


def test_scalar_is_fixed_list_is_choice_table_is_range(tmp_path):
    spaces = _spaces(
        tmp_path,
        """
        [[controls]]
        type = "orientation"
        yaw = 30
        pitch = [0, 90, 0, 90.0, 45]
        roll = { range = [-10, 10] }

        [[controls]]
        type = "camera"
        zoom = { range = [0.5, 4], log = true }
        elevation = [10]
        """,
    )
    yaw, pitch, roll = (spaces["orientation"][k] for k in ("yaw", "pitch", "roll"))
    assert yaw == Fixed(30.0) and isinstance(yaw.value, float)
    assert pitch == Choice((0.0, 90.0, 45.0))
    assert roll == Range(-10.0, 10.0, log=False, integer=False)
    assert spaces["camera"]["zoom"] == Range(0.5, 4.0, log=True, integer=False)
    assert spaces["camera"]["elevation"] == Fixed(10.0)  # a one-element list fixes the value
    assert set(spaces["camera"]) == {"zoom", "elevation"}  # unset parameters keep their defaults


def test_int_params_get_integer_ranges(tmp_path, user_controls):
    spaces = _spaces(
        tmp_path,
        f"""
        [[controls]]
        {USER_TYPE}
        id = "tint"
        count = {{ range = [1, 6] }}
        mode = ["warm", "cold", "warm"]
        """,
    )
    count = spaces["tint"]["count"]
    assert count == Range(1.0, 6.0, integer=True)
    assert spaces["tint"]["mode"] == Choice(("warm", "cold"))
    values = {count.at(i / 20) for i in range(21)}
    assert all(isinstance(v, int) for v in values)
    assert values == set(range(1, 7))


def test_int_range_through_search_space(tmp_path, user_controls):
    body = BASE.split("[[controls]]")[0] + f'[[controls]]\n{USER_TYPE}\ncount = {{ range = [0, 3] }}\n'
    loaded = load_spec(write_spec(tmp_path, body))
    space = SearchSpace(loaded.controls)
    assert space.shape.n_continuous == 1
    got = space.values(Point((0.7,), ()))["Tint"]["count"]
    assert got == 2 and isinstance(got, int)


def test_labels_resolve_to_imagenet_ids(tmp_path):
    body = BASE.replace('labels = ["carton"]', 'labels = ["Carton", "carton", 478]')
    loaded = load_spec(write_spec(tmp_path, body))
    from sweep3d.stages.infer.labels import IMAGENET

    carton = IMAGENET.index("carton")
    assert loaded.labels["box"] == tuple(sorted({carton, 478}))


def test_control_filters_are_kept(tmp_path):
    body = BASE + textwrap.dedent(
        """
        [[controls]]
        type = "scale"
        factor = 2.0
        objects = ["box"]
        environments = ["studio"]
        """
    )
    loaded = load_spec(write_spec(tmp_path, body))
    scale = loaded.controls[-1]
    assert scale.objects == frozenset({"box"}) and scale.environments == frozenset({"studio"})
    assert scale.applies_to("box", "studio")
    assert not scale.applies_to("box", "white")
    assert loaded.controls[0].applies_to("box", "white")
