"""sweep3d.spec.load_spec: user mistakes become one-line SpecErrors; valid specs load into spaces."""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import subprocess
import sys
import textwrap
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.core.errors import SpecError
from sweep3d.spec import Choice, Fixed, Range
from sweep3d.spec.space import Point, SearchSpace
from tests.helpers import CUBE_OBJ, TINY_SPEC, files, load_spec, write_cube, write_spec

BASE = TINY_SPEC.replace('name = "tiny"\nseed = 7\nstore = "store"', 'name = "mistakes"\nseed = 3')

# A user's control plug-in with a string and an integer parameter (no built-in has either).
USER_MODULE = "sweep3d_test_user_controls"
USER_CONTROLS = '''\
from pydantic import Field

from sweep3d.core.control import ControlParams
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


def mesh_mistake(name: str, mesh: str, expect: tuple[str, ...], setup: Callable[[Path], None] | None = None) -> Mistake:
    return Mistake(f"mesh-{name}", edit('mesh = "cube.obj"', f'mesh = "{mesh}"'), "objects[0].mesh", expect, setup)


def hdri_mistake(name: str, data: bytes, expect: tuple[str, ...]) -> Mistake:
    return Mistake(f"hdri-{name}", edit('"builtin:studio"', f'"{name}"'), "environments[1].hdri", (name, *expect),
                   writes(name, data))


def writes(name: str, data: bytes) -> Callable[[Path], None]:
    return lambda folder: (folder / name).write_bytes(data)


def _zip(path: Path, member: str, text: str) -> None:
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(member, text)


def _png(pixels: np.ndarray) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="PNG")
    return buffer.getvalue()


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
            "controls[2].image", ("textures/none.png", "does not exist", "relative to the spec file")),
    Mistake("part-visibility-not-a-bool", append('[report]\npart_visibility = "yes please"\n'),
            "report.part_visibility", ("valid boolean",)),
    Mistake("report-key-unknown", append("[report]\npart_visiblity = true\n"), "report.part_visiblity",
            ("unknown key",)),
    Mistake("column-shadows-a-key", append(f'[[controls]]\ntype = "{USER_MODULE}:Pair"\nid = "render"\nkey = "x"\n'),
            "controls[2].key", ("'render_key'", "results table's own", "id = ")),
    Mistake("columns-collide", append(f'[[controls]]\ntype = "{USER_MODULE}:Pair"\nid = "p"\na_b = "x"\n'
                                      f'[[controls]]\ntype = "{USER_MODULE}:Pair"\nid = "p_a"\nb = "y"\n'),
            "controls[3].b", ("'p_a_b'", "controls[2]", "id = ")),
    Mistake("model-unknown", edit("[model]\n", '[model]\nname = "efficientnet-lite3"\n'),
            "model.name", ("'efficientnet-lite3'", "efficientnet-lite2", "module:Name")),
    # the store and the size of the plan
    Mistake("store-empty", edit("seed = 3", 'seed = 3\nstore = ""'), "experiment.store",
            ("must name the store's folder", "spec's own folder")),
    Mistake("store-blank", edit("seed = 3", 'seed = 3\nstore = "  "'), "experiment.store", ("must name",)),
    Mistake("max-jobs-zero", edit("seed = 3", "seed = 3\nmax_jobs = 0"), "experiment.max_jobs",
            ("greater than or equal to 1",)),
    # paths that are not files: said as what they are, and never opened (a FIFO would block)
    mesh_mistake("directory", "meshes.obj", ("is a directory", "not a file"),
                 lambda folder: (folder / "meshes.obj").mkdir()),
    mesh_mistake("fifo", "pipe.obj", ("is a FIFO",), lambda folder: os.mkfifo(folder / "pipe.obj")),
    mesh_mistake("device", "/dev/zero", ("/dev/zero", "is a device file")),
    Mistake("hdri-directory", edit('"builtin:studio"', '"maps"'), "environments[1].hdri", ("is a directory",),
            lambda folder: (folder / "maps").mkdir()),
    Mistake("hdri-fifo", edit('"builtin:studio"', '"sky.hdr"'), "environments[1].hdri", ("is a FIFO",),
            lambda folder: os.mkfifo(folder / "sky.hdr")),
    Mistake("material-image-fifo", append('[[controls]]\ntype = "material"\nskin = "image"\nimage = "wood.png"\n'),
            "controls[2].image", ("wood.png", "is a FIFO"), lambda folder: os.mkfifo(folder / "wood.png")),
    # vertices Blender would silently replace
    mesh_mistake("obj-nan", "nan.obj", ("vertex 7 of the OBJ file (line 8)", "nan", "not a finite number"),
                 writes("nan.obj", CUBE_OBJ.replace("v 1 1 1", "v 1 nan 1").encode())),
    mesh_mistake("obj-inf", "inf.obj", ("vertex 1", "-inf", "not a finite number"),
                 writes("inf.obj", CUBE_OBJ.replace("v -1 -1 -1", "v -inf -1 -1").encode())),
    mesh_mistake("obj-float32-overflow", "far.obj", ("1e39", "not a finite number"),
                 writes("far.obj", CUBE_OBJ.replace("v 1 1 1", "v 1 1e39 1").encode())),
    mesh_mistake("ply-ascii-nan", "nan.ply", ("vertex 2 of the PLY file", "NaN"),
                 writes("nan.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                   b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                   b"end_header\n0 0 0\n1 NaN 0\n0 1 0\n3 0 1 2\n")),
    mesh_mistake("ply-binary-inf", "inf.ply", ("vertex 3 of the PLY file", "inf"),
                 writes("inf.ply", files.ply_binary([(0, 0, 0), (1, 0, 0), (0, math.inf, 0)]))),
    mesh_mistake("stl-binary-nan", "nan.stl", ("triangle 2 of the STL file", "nan"),
                 writes("nan.stl", files.stl_binary([[(0, 0, 0), (1, 0, 0), (0, 1, 0)],
                                                     [(0, 0, 0), (1, 0, 0), (0, math.nan, 0)]]))),
    mesh_mistake("stl-ascii-inf", "inf.stl", ("vertex 3 of the STL file", "inf"),
                 writes("inf.stl", b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                                   b"vertex 0 inf 0\nendloop\nendfacet\nendsolid t\n")),
    mesh_mistake("glb-nan", "nan.glb", ("vertex 3 of mesh 0 of the .glb file", "nan"),
                 writes("nan.glb", files.glb([(0, 0, 0), (1, 0, 0), (0, math.nan, 0)]))),
    Mistake("zip-member-obj-nan", edit('mesh = "cube.obj"', 'mesh = "kit.zip#box/box.obj"'), "objects[0].mesh",
            ("kit.zip#box/box.obj", "vertex 7", "nan"), lambda folder: _zip(folder / "kit.zip", "box/box.obj",
                                                                             CUBE_OBJ.replace("v 1 1 1", "v nan 1 1"))),
    # maps that hold no light: every render would be black
    hdri_mistake("black.hdr", files.hdr(np.zeros((4, 64, 3))), ("black (every pixel is 0)",)),
    hdri_mistake("black.exr", files.exr(np.zeros((4, 8, 3))), ("holds no light", "every pixel is 0")),
    hdri_mistake("negative.exr", files.exr(-np.ones((4, 8, 3))), ("holds no light", "96 of its 96", "negative")),
    hdri_mistake("negative-zip.exr", files.exr(np.full((40, 8, 3), -0.5), zip_compressed=True),
                 ("holds no light", "negative")),
    hdri_mistake("black.png", _png(np.zeros((8, 8, 3), np.uint8)), ("black (every pixel is 0)",)),
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


# -- maps with light, and the size of a plan ---------------------------------------------------


def test_maps_with_light_load_and_a_few_negative_pixels_only_warn(tmp_path, caplog):
    sky = np.full((40, 16, 3), 0.8)
    sky[3, 5] = -0.01  # filtering rings around a sun are legal, but not physical: 3 of 1920 values
    (tmp_path / "sky.exr").write_bytes(files.exr(sky, zip_compressed=True))
    (tmp_path / "lit.hdr").write_bytes(files.hdr(np.random.default_rng(0).random((6, 64, 3))))
    (tmp_path / "lit.exr").write_bytes(files.exr(np.full((4, 8, 3), 2.0)))
    warnings = {}
    for name in ("sky.exr", "lit.hdr", "lit.exr"):
        caplog.clear()
        path = write_spec(tmp_path, BASE.replace('"builtin:studio"', f'"{name}"'))
        assert load_spec(path).hdris["studio"] == str(tmp_path / name)
        warnings[name] = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert warnings["lit.hdr"] == warnings["lit.exr"] == []
    (line,) = warnings["sky.exr"]
    assert line.startswith(f"warning: {path}: environments[1].hdri: sky.exr: 0.16% of the map's colour values")
    assert "negative" in line and "clamp them to 0" in line


def test_plan_refuses_a_billion_jobs_in_one_line_and_warns_of_hours_of_rendering(tmp_path):
    huge = BASE.replace("yaw = [0, 45]", "yaw = { range = [0, 90] }\npitch = { range = [0, 90] }").replace(
        "sigma = [0.0, 1.5]", "sigma = { range = [0, 2] }").replace('type = "grid"', 'type = "grid"\nsamples_per_dim = 800')
    result = CliRunner().invoke(app, ["plan", str(write_spec(tmp_path, huge))])
    assert result.exit_code == 2
    (line,) = [line for line in result.output.splitlines() if line.strip()]
    assert "policy: the spec expands to 1,024,000,000 jobs, over the limit of 1,000,000" in line

    slow = BASE.replace("resolution = 32", "resolution = 224").replace("samples = 1", "samples = 65536")
    result = CliRunner().invoke(app, ["plan", str(write_spec(tmp_path, slow))])
    assert result.exit_code == 0, result.output
    warning = [line for line in result.output.splitlines() if line.startswith("warning:")]
    assert len(warning) == 1 and "4 renders at about 37.1 min each" in result.output
    assert "over render.timeout = 600 s" in result.output and "lower [render] samples" in result.output


# -- files this user may not read ------------------------------------------------------------
#
# Root reads any file whatever its mode, so these run `sweep3d plan` in a child process without
# the capabilities that let root ignore permissions (setpriv), or as they are for any other user.

UNREADABLE_SCRIPT = """
import json, sys
from typer.testing import CliRunner
from sweep3d.cli import app
try:
    open(sys.argv[1], "rb").close()
    print(json.dumps({"skip": "this process reads a chmod 000 file: permissions cannot be tested here"}))
except PermissionError:
    print(json.dumps({case: [r.exit_code, r.output] for case, spec in json.loads(sys.argv[2]).items()
                      for r in [CliRunner().invoke(app, ["plan", spec])]}))
"""
TEXTURED_OBJ = "mtllib box.mtl\nusemtl skin\n" + CUBE_OBJ
UNREADABLE = {  # case: (mesh, HDRI, extra controls, the path made unreadable, the key named)
    "mesh": ("cube.obj", "builtin:studio", "", "cube.obj", "objects[0].mesh"),
    "mesh-folder": ("private/cube.obj", "builtin:studio", "", "private", "objects[0].mesh"),
    "zip-archive": ("kit.zip#box/box.obj", "builtin:studio", "", "kit.zip", "objects[0].mesh"),
    "mtl-library": ("textured.obj", "builtin:studio", "", "box.mtl", "objects[0].mesh"),
    "texture-of-the-mesh": ("textured.obj", "builtin:studio", "", "skin.png", "objects[0].mesh"),
    "hdri": ("cube.obj", "sky.hdr", "", "sky.hdr", "environments[1].hdri"),
    "material-image": ("cube.obj", "builtin:studio", '[[controls]]\ntype = "material"\nskin = "image"\n'
                       'image = "wood.png"\n', "wood.png", "controls[2].image"),
}


def _unreadable_case(folder: Path, mesh: str, hdri: str, controls: str, hidden: str) -> Path:
    folder.mkdir()
    write_cube(folder)
    (folder / "private").mkdir()
    write_cube(folder / "private")
    _zip(folder / "kit.zip", "box/box.obj", CUBE_OBJ)
    (folder / "textured.obj").write_text(TEXTURED_OBJ)
    (folder / "box.mtl").write_text("newmtl skin\nmap_Kd skin.png\n")
    (folder / "skin.png").write_bytes(_png(np.full((4, 4, 3), 200, np.uint8)))
    (folder / "wood.png").write_bytes(_png(np.full((4, 4, 3), 120, np.uint8)))
    (folder / "sky.hdr").write_bytes(files.hdr(np.full((4, 16, 3), 0.5)))
    spec = write_spec(folder, BASE.replace('mesh = "cube.obj"', f'mesh = "{mesh}"')
                      .replace('"builtin:studio"', f'"{hdri}"') + controls, cube=False)
    (folder / hidden).chmod(0)
    return spec


@pytest.fixture(scope="module")
def unreadable(tmp_path_factory) -> dict[str, tuple[Path, int, str]]:
    """case -> (spec, exit code, output) of `sweep3d plan` by a user who may not read one of its files."""
    root = tmp_path_factory.mktemp("unreadable")
    specs = {case: _unreadable_case(root / case, *setup[:4]) for case, setup in UNREADABLE.items()}
    probe = root / "probe"
    probe.write_bytes(b"")
    probe.chmod(0)
    command = [sys.executable, "-c", UNREADABLE_SCRIPT, str(probe), json.dumps({c: str(s) for c, s in specs.items()})]
    if os.geteuid() == 0:
        if shutil.which("setpriv") is None:
            pytest.skip("running as root without setpriv: cannot drop the right to read any file")
        command = ["setpriv", "--bounding-set", "-dac_override,-dac_read_search", *command]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])})
    if done.returncode != 0 and "setpriv" in done.stderr:
        pytest.skip(f"setpriv cannot drop capabilities here: {done.stderr.strip()}")
    assert done.returncode == 0, done.stderr
    results = json.loads(done.stdout.strip().splitlines()[-1])
    if "skip" in results:
        pytest.skip(results["skip"])
    return {case: (specs[case], *results[case]) for case in specs}


@pytest.mark.parametrize("case", UNREADABLE)
def test_a_file_this_user_cannot_read_is_one_line_naming_the_key_and_the_file(unreadable, case):
    spec, code, output = unreadable[case]
    key, hidden = UNREADABLE[case][4], UNREADABLE[case][3]
    assert code == 2, output
    assert "Traceback" not in output
    (line,) = [line for line in output.splitlines() if line.strip()]
    assert line.startswith(f"error: {spec}: {key}: ") and "permission denied" in line, line
    fix = "chmod a+x" if case == "mesh-folder" else "chmod a+r"  # a folder that may not be searched
    assert str(spec.parent / hidden) in line and fix in line, line


def test_run_warns_before_hours_of_rendering_but_not_before_minutes(tmp_path):
    from rich.console import Console

    from sweep3d.cache.store import Store
    from sweep3d.runner.pipeline import _warn_if_slow
    from sweep3d.stages.render import LOCAL
    from tests.helpers import plan_for

    console = Console(record=True, width=400)
    big = BASE.replace("resolution = 32", "resolution = 4096").replace("samples = 1", "samples = 4")
    _warn_if_slow([plan_for(load_spec(write_spec(tmp_path, big)), "m")], Store(tmp_path / "store"), LOCAL, console)
    assert console.export_text() == ""  # 4 renders of about a minute: no warning
    slow = BASE.replace("resolution = 32", "resolution = 1024").replace("samples = 1", "samples = 2048")
    _warn_if_slow([plan_for(load_spec(write_spec(tmp_path, slow)), "m")], Store(tmp_path / "store"), LOCAL, console)
    (line,) = console.export_text().splitlines()
    assert line.startswith("warning: 4 renders at about 24.3 min each (1024² pixels, 2048 samples) would take "
                           "about 1.6 h on 2 CPU cores, and each is over render.timeout = 600 s"), line
