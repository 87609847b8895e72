"""Malformed input met at run time: broken meshes and HDRIs, odd values, broken models, an
unwritable store, a full disk. Each one is a single ``error:`` line naming the file, the key and
the fix, exit code 2, and leaves the store exactly as it was.

This is where a spec's mistakes are tested. The loader's table of key-by-key mistakes (unknown keys,
empty ranges, NaN in a range, unknown labels, ...) stays in tests/spec/test_spec.py beside the valid
specs it edits; this file holds what needs the files' contents, Blender, the model or the disk, and
the one-line refusals of a spec's other tables (a policy's pairing and crossing, a light, a post
control's parameters, the render's knobs, the models). A command's mistakes are in
tests/cli/test_bad_input.py, a user's plug-in code that exits in tests/driver/test_bad_input.py.

Cases refused before anything renders or loads a model (the loader's checks of files and values,
the store's folder) run in the fast lane, on a copy of a store holding a synthetic finished run;
those that reach Blender, a model or a full disk run on a copy of the session's real run.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import struct
import sys
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.core.errors import SpecError
from tests.helpers import CUBE_OBJ, TINY_SPEC, TWO_MODELS, files, load_spec, paired_spec, write_cube, write_spec

RNG = np.random.default_rng(0)
GARBAGE = RNG.integers(0, 256, 4096, dtype=np.uint8).tobytes()

PLY_HEADER = ("ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n"
              "property float z\nelement face {f}\nproperty list uchar int vertex_indices\nend_header\n")


def _exr_truncated() -> bytes:
    """The first half of a real OpenEXR map (Blender's studio light)."""
    from sweep3d.assets.sources import builtin_hdris

    data = builtin_hdris()["studio"].read_bytes()
    return data[: len(data) // 2]


def _zip(member: str, data: bytes) -> bytes:
    import io

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr(member, data)
    return buf.getvalue()


USER_MODELS = '''
import torch
from sweep3d.stages.infer import Classifier

class Net(torch.nn.Module):
    def __init__(self, out):
        super().__init__()
        self.out = out
        self.scale = torch.nn.Parameter(torch.ones(1))

    def forward(self, x):
        n = x.shape[0]
        if self.out == "raise":
            raise RuntimeError("CUDA out of imagination")
        if self.out == "4d":
            return x * self.scale
        return torch.zeros(n, self.out) * self.scale

def raises():
    raise ValueError("weights file not found: model.pt")

def a_string():
    return "resnet50"

def four_d():
    return Net("4d")

def ten_classes():
    return Net(10)

def raises_in_forward():
    return Net("raise")

def two_labels():
    return Classifier(Net(2), labels=["cat", "dog"])

def fine():
    return Net(1000)

def own_preprocess():
    return Classifier(Net(1000), preprocess=lambda images: torch.zeros(len(images), 3, 8, 8))
'''


@dataclass
class Case:
    id: str
    edit: tuple[str, str] | None  # (old, new) in the spec text
    key: str  # the spec key the message names ("" for store-level problems)
    expect: tuple[str, ...]  # substrings of the error line
    files: dict[str, bytes] = field(default_factory=dict)
    one_job: bool = False  # reaches Blender: keep it to one render
    full_disk: bool = False  # every fsync fails with ENOSPC
    model_module: bool = False


def mesh(name: str, data: bytes, *expect: str, one_job: bool = False) -> Case:
    return Case(f"mesh-{name}", ('mesh = "cube.obj"', f'mesh = "{name}"'), "objects[0].mesh", expect,
                {name: data}, one_job=one_job)


def hdri(name: str, data: bytes, *expect: str) -> Case:
    return Case(f"hdri-{name}", ('hdri = "builtin:studio"', f'hdri = "{name}"'), "environments[1].hdri", expect,
                {name: data})


def model(factory: str, *expect: str, key: str = "model.name") -> Case:
    return Case(f"model-{factory}", ("[model]\n", f'[model]\nname = "bad_input_models:{factory}"\n'), key, expect,
                model_module=True)


CASES = [
    # meshes that are not what their name says (caught when the spec loads)
    mesh("garbage.obj", GARBAGE, "not a text OBJ", "export"),
    mesh("empty.obj", b"", "empty", "export"),
    mesh("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces", "export it with faces"),
    mesh("faces-only.obj", b"f 1 2 3\n", "no vertices"),
    mesh("utf16.obj", CUBE_OBJ.encode("utf-16"), "binary bytes"),
    mesh("garbage.ply", GARBAGE, "not a PLY file"),
    mesh("truncated.ply", PLY_HEADER.format(n=100, f=10).encode() + b"\0" * 20, "truncated", "100 vertices"),
    mesh("cloud.ply", PLY_HEADER.format(n=3, f=0).encode() + b"\0" * 36, "no faces", "point cloud"),
    mesh("garbage.glb", GARBAGE, "no 'glTF' magic"),
    mesh("truncated.glb", b"glTF" + struct.pack("<II", 2, 5000) + GARBAGE[:100], "truncated", "5000"),
    mesh("broken.gltf", b'{"asset": {"version": "2.0"', "not glTF JSON"),
    mesh("no-asset.gltf", json.dumps({"meshes": []}).encode(), "no 'asset' entry"),
    mesh("garbage.stl", GARBAGE, "not an STL file"),
    Case("mesh-zip-member-garbage", ('mesh = "cube.obj"', 'mesh = "kit.zip#parts/box.obj"'), "objects[0].mesh",
         ("kit.zip#parts/box.obj", "not a text OBJ"), {"kit.zip": _zip("parts/box.obj", GARBAGE)}),
    # meshes Blender would import as nothing to render (caught at load since issue 22's audit)
    mesh("point.obj", b"v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n", "zero area", "export it again"),
    mesh("dangling.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "line 4", "vertex 9", "3 vertices"),
    mesh("flat.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "zero area"),
    # meshes only Blender can judge (the render worker reports a user error)
    mesh("cut.stl", b"solid x\nfacet normal 0 0 1\n outer loop\n  vertex 0 0 0\n", "Blender cannot import",
         "export the mesh again", one_job=True),
    # HDRIs that are not images, or not whole ones (Blender would light the scene magenta)
    hdri("garbage.exr", GARBAGE, "not an OpenEXR image"),
    hdri("truncated.exr", _exr_truncated(), "truncated", "save it again"),
    hdri("text.hdr", b"this is not an image", "not a Radiance .hdr"),
    hdri("headless.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n", "no resolution line"),
    hdri("garbage.png", b"\x89PNG\r\n\x1a\n" + GARBAGE, "not a readable image"),
    hdri("empty.exr", b"", "empty"),
    # values the spec table does not try
    Case("env-strength-nan", ('hdri = "builtin:studio"', 'hdri = "builtin:studio"\nstrength = nan'),
         "environments[1].strength", ("finite number", "nan")),
    Case("env-strength-inf", ('hdri = "builtin:studio"', 'hdri = "builtin:studio"\nstrength = inf'),
         "environments[1].strength", ("finite number", "inf")),
    Case("env-color-nan", ("color = [1.0, 1.0, 1.0]", "color = [nan, 1.0, 1.0]"), "environments[0].color",
         ("between 0 and 1",)),
    Case("policy-samples-negative", ('type = "grid"', 'type = "random"\nsamples = -5'), "policy.samples",
         ("greater than or equal to 1",)),
    Case("resolution-tiny", ("resolution = 32", "resolution = 4"), "render.resolution", ("8..4096 pixels or \"model\"",)),
    Case("resolution-word", ("resolution = 32", 'resolution = "full"'), "render.resolution",
         ("8..4096 pixels or \"model\"", "'full'")),
    Case("resolution-model-of-a-model-with-its-own-preprocessing",
         ("resolution = 32\nsamples = 1\ndenoise = false\n\n[model]\n",
          'resolution = "model"\nsamples = 1\ndenoise = false\n\n[model]\nname = "bad_input_models:own_preprocess"\n'),
         "render.resolution", ("input size is unknown", "resolution = 224"), model_module=True),
    Case("label-boolean", ('labels = ["carton"]', "labels = [true]"), "objects[0].labels",
         ("not a class name or id",)),
    Case("evaluator-unknown", ("[model]\n", '[evaluator]\nkind = "detektion"\n\n[model]\n'), "evaluator.kind",
         ("'detektion'", "classification")),
    Case("camera-zoom-zero", ("[policy]", '[[controls]]\ntype = "camera"\nzoom = 0\n\n[policy]'),
         "controls[2].zoom", ("greater than 0",)),
    Case("camera-elevation-past-the-pole", ("[policy]", '[[controls]]\ntype = "camera"\nelevation = [0, 120]\n\n[policy]'),
         "controls[2].elevation", ("less than or equal to 90", "120")),
    Case("control-value-wrong-type", ("[policy]", '[[controls]]\ntype = "scale"\nfactor = "huge"\n\n[policy]'),
         "controls[2].factor", ("valid number", "huge")),
    # parts and material overrides of an object (tests/assets/test_sub_objects.py has more)
    Case("object-part-unknown", ('labels = ["carton"]', 'labels = ["carton"]\nparts = ["Cube"]'), "objects[0].parts[0]",
         ("no object 'Cube' in cube.obj", "did you mean 'cube'?")),
    Case("object-part-unknown-in-a-ply", ('mesh = "cube.obj"', 'mesh = "tri.ply"\nparts = ["Tri"]'), "objects[0].parts",
         ("no object 'Tri' in tri.ply", "did you mean 'tri'?"), {"tri.ply": files.ply_binary([(0, 0, 0), (1, 0, 0),
                                                                                             (0, 1, 0)])},
         one_job=True),  # only Blender knows a PLY's object names: found by the render worker
    Case("object-material-unknown-key", ('labels = ["carton"]', 'labels = ["carton"]\nmaterial = { opcity = 1.0 }'),
         "objects[0].material.opcity", ("unknown key", "did you mean 'opacity'?")),
    Case("object-material-negative", ('labels = ["carton"]', 'labels = ["carton"]\nmaterial = { roughness = -0.5 }'),
         "objects[0].material.roughness", ("greater than or equal to 0", "-0.5")),
    Case("object-material-nan", ('labels = ["carton"]', 'labels = ["carton"]\nmaterial = { base_color = [nan, 0, 0] }'),
         "objects[0].material.base_color", ("between 0 and 1",)),
    # models (checked on one blank image before anything is rendered)
    model("raises", "(bad_input_models.py:", "raised: ValueError", "weights file not found"),
    model("a_string", "must return a torch.nn.Module", "str"),
    model("four_d", "(batch, classes)"),
    model("ten_classes", "returns 10 classes", "1000"),
    model("raises_in_forward", "raised RuntimeError", "CUDA out of imagination", "fix the model"),
    model("two_labels", "'carton' is not a class of the model", key="objects[0].labels[0]"),
    Case("model-module-missing", ("[model]\n", '[model]\nname = "no_such_module_here:make"\n'), "model.name",
         ("cannot import model module", "PYTHONPATH")),
    # the store
    Case("store-under-a-file", ('store = "store"', 'store = "blocker/store"'), "experiment.store",
         ("not writable", "set experiment.store"), {"blocker": b"a file, not a folder"}),
    Case("disk-full-writing-predictions", ("[model]\n", '[model]\nname = "bad_input_models:fine"\n'), "",
         ("No space left on device", "free some disk space", "experiment.store"), model_module=True, full_disk=True),
    Case("disk-full-writing-an-image", ("sigma = [0.0, 1.5]", "sigma = [0.0, 2.5]"), "",
         ("No space left on device", "free some disk space"), full_disk=True),
]


def _tree(root: Path) -> dict[str, bytes]:
    """The store's files and contents (the lock file only records the last holder's pid)."""
    if not root.exists():
        return {}
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.name != "lock"}


def _one_job(text: str) -> str:
    """The spec cut to one environment, one yaw, no blur: the shortest way to reach Blender."""
    text = text.replace('[[environments]]\nname = "studio"\nhdri = "builtin:studio"\n', "")
    return text.replace("yaw = [0, 45]", "yaw = 0").replace("sigma = [0.0, 1.5]", "sigma = 0.0")


def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def _case(param) -> Case:
    return param if isinstance(param, Case) else param.values[0]


def _reaches_a_run(case: Case) -> bool:
    """Whether the case gets past the loader: Blender renders, a model loads, or the disk fills."""
    return case.one_job or case.model_module or case.full_disk


LOADER_CASES = [c for c in CASES if not _reaches_a_run(_case(c))]
RUN_CASES = [c for c in CASES if _reaches_a_run(_case(c))]


def test_the_table_has_at_least_thirty_cases() -> None:
    assert len(CASES) >= 30
    assert len(LOADER_CASES) + len(RUN_CASES) == len(CASES)


@pytest.fixture(scope="module")
def synthetic_run(tmp_path_factory) -> Path:
    """A folder whose store holds a finished run's tables (synthetic results: no Blender, no model)."""
    from tests.helpers import build_store

    folder = build_store(tmp_path_factory.mktemp("synthetic_run"), 64).parent
    write_cube(folder)  # the cube TINY_SPEC names
    return folder


#: The commands that load a spec (issue 45: each bad spec is refused by every one of them alike);
#: SPEC and FOLDER stand for the case's spec and folder.
LOADING_COMMANDS = (("run", "SPEC", "--no-report"), ("plan", "SPEC"), ("realism", "score", "SPEC", "FOLDER"))


@pytest.mark.parametrize("case", LOADER_CASES, ids=[_case(c).id for c in LOADER_CASES])
def test_bad_input_caught_at_load_is_one_line_exit_2_and_leaves_the_store_as_it_was(
        case: Case, synthetic_run: Path, tmp_path: Path, monkeypatch) -> None:
    folder = tmp_path / "case"
    shutil.copytree(synthetic_run, folder)  # a store with a finished (synthetic) run in it
    _check(case, folder, tmp_path, monkeypatch, LOADING_COMMANDS)


@pytest.mark.slow
@pytest.mark.parametrize("case", RUN_CASES, ids=[_case(c).id for c in RUN_CASES])
def test_bad_input_is_one_line_exit_2_and_leaves_the_store_as_it_was(case: Case, tiny_run: Path, tmp_path: Path,
                                                                      monkeypatch) -> None:
    folder = tmp_path / "case"
    shutil.copytree(tiny_run, folder)  # a store with a finished run in it
    _check(case, folder, tmp_path, monkeypatch)


def _check(case: Case, folder: Path, tmp_path: Path, monkeypatch,
           commands: tuple[tuple[str, ...], ...] = (("run", "SPEC", "--no-report"),)) -> None:
    """Run each of ``commands`` on the case's spec in ``folder``: one ``error:`` line, exit code 2,
    the store untouched; the first command's line as the case expects (another may meet another
    mistake first: ``realism score`` a spec without a kit, ``plan`` a store under a file)."""
    spec = folder / "spec.toml"
    text = TINY_SPEC
    if case.edit is not None:
        old, new = case.edit
        assert old in text, old
        text = text.replace(old, new, 1)
    if case.one_job:
        text = _one_job(text)
    spec.write_text(text)
    for name, data in case.files.items():
        (folder / name).write_bytes(data)
    if case.model_module:
        module = tmp_path / "modules"
        module.mkdir()
        (module / "bad_input_models.py").write_text(USER_MODELS)
        monkeypatch.syspath_prepend(str(module))
        monkeypatch.delitem(sys.modules, "bad_input_models", raising=False)
    if case.full_disk:
        monkeypatch.setattr(os, "fsync", _enospc)
    before = _tree(folder / "store")

    for command in commands:
        result = CliRunner().invoke(app, [{"SPEC": str(spec), "FOLDER": str(folder)}.get(a, a) for a in command])

        assert result.exit_code == 2, (command, result.output)
        assert "Traceback" not in result.output
        errors = [line for line in result.output.splitlines() if line.startswith("error:")]
        assert len(errors) == 1, result.output
        line = errors[0]
        if case.key and command is commands[0]:
            assert f"{spec}: {case.key}: " in line, line
        for text in case.expect if command is commands[0] else ():
            assert text in line, f"{text!r} not in {line!r}"
        assert _tree(folder / "store") == before, f"{command[0]} changed the store"


@pytest.mark.slow
def test_a_non_manifold_mesh_is_not_an_error_it_renders(tmp_path: Path) -> None:
    """Two triangles touching at one vertex (non-manifold, open): legal, and most real meshes are
    open somewhere, so sweep3d renders it rather than refusing it."""
    from sweep3d.runner.pipeline import run
    from tests.helpers import load_spec

    (tmp_path / "bowtie.obj").write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv -1 0 0\nv 0 -1 0\nf 1 2 3\nf 1 4 5\n")
    (tmp_path / "spec.toml").write_text(_one_job(TINY_SPEC).replace('mesh = "cube.obj"', 'mesh = "bowtie.obj"'))
    result = run(load_spec(tmp_path / "spec.toml"))
    assert result.failed == 0 and result.outcome("render").computed == 1


def test_a_full_disk_while_extracting_a_mesh_says_the_disk_is_full_and_where(tmp_path: Path, monkeypatch) -> None:
    """A fresh store on a nearly full disk: the first write is the mesh's folder extracted from its
    archive, whose error names no file (it said "cannot read the mesh's file ''")."""
    import sweep3d.assets.sources as assets

    (tmp_path / "kit.zip").write_bytes(_zip("parts/box.obj", CUBE_OBJ.encode()))
    spec = tmp_path / "spec.toml"
    spec.write_text(TINY_SPEC.replace('mesh = "cube.obj"', 'mesh = "kit.zip#parts/box.obj"'))

    def full(source, out, size, name):  # as a write to a full disk fails: some bytes, then ENOSPC, no file named
        out.write(source.read(16))
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(assets, "_copy_at_most", full)
    result = CliRunner().invoke(app, ["plan", str(spec)], terminal_width=400)
    assert result.exit_code == 2, result.output
    (line,) = [line for line in result.output.splitlines() if line.strip()]
    assets_folder = tmp_path / "store" / "assets"
    assert line.startswith(f"error: cannot extract kit.zip#parts/box.obj into {assets_folder}/"), line
    assert ": the disk is full (No space left on device; " in line and " free on the disk mounted at /" in line, line
    assert line.endswith("free some disk space, or set experiment.store to a folder on another disk"), line
    assert not any(assets_folder.iterdir())  # what was extracted is gone: no half folder, the space back


@pytest.mark.parametrize("policy, key, says", [
    ('type = "random"\nsamples = 4\npaired = "sometimes"', "policy.paired", 'true, false or "all"'),
    ('type = "random"\nsamples = 4\npaired = 1', "policy.paired", 'true, false or "all"'),
    ('type = "adaptive"\npaired = true', "policy.paired", "learns per scene"),
    ('type = "random"\nstratify = "yes"', "policy.stratify", "boolean"),
    ('type = "sobol"\nstratify = true', "policy.stratify", "unknown key"),
    ('type = "boundary"\npaired = true', "policy.paired", "learns per scene"),  # the boundary policy refuses pairing
    ('type = "boundary"\ncross = ["environment"]', "policy.cross", "learns per scene"),
    ('type = "boundary"\nmargin = -1', "policy.margin", "greater than or equal to 0"),
])
def test_bad_pairing_is_one_line(tmp_path: Path, policy: str, key: str, says: str) -> None:
    spec = write_spec(tmp_path, TINY_SPEC.replace('[policy]\ntype = "grid"', f"[policy]\n{policy}"))
    result = CliRunner().invoke(app, ["plan", str(spec)])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and says in lines[0], result.output


@pytest.mark.parametrize("cross, problem", [
    ('["blur.radius"]', "names no control parameter"),
    ('["orientation.yaw"]', "a range, which the policy draws"),
    ('["camera.zoom"]', "a range"),
    ('["nothing"]', "names no control parameter"),
    ('{ "blur.sigma" = 0 }', "a number k >= 1"),
    ('{ environment = 3 }', "give true"),
])
def test_a_bad_cross_is_one_line_naming_the_key(tmp_path: Path, cross: str, problem: str) -> None:
    body = paired_spec(seed=3, policy=f'type = "random"\nsamples = 4\ncross = {cross}')
    with pytest.raises(SpecError) as caught:
        load_spec(write_spec(tmp_path, body))
    assert "policy" in caught.value.key and problem in str(caught.value) and "\n" not in str(caught.value)


def test_cross_refuses_a_learning_policy_and_disagreeing_paired(tmp_path: Path) -> None:
    for i, policy in enumerate(['type = "adaptive"\ncross = ["blur.sigma"]',
                                'type = "random"\npaired = false\ncross = ["environment"]']):
        folder = tmp_path / str(i)
        folder.mkdir()
        with pytest.raises(SpecError) as caught:
            load_spec(write_spec(folder, paired_spec(seed=3, policy=policy)))
        assert caught.value.key.startswith("policy") and "\n" not in str(caught.value)


def test_a_key_light_on_an_hdri_is_refused(tmp_path) -> None:
    path = write_spec(tmp_path, TINY_SPEC.replace('hdri = "builtin:studio"\n', 'hdri = "builtin:studio"\nkey_light = true\n'))
    with pytest.raises(SpecError, match=r"environments\[1\]: key_light is for a plain colour"):
        load_spec(path)


# -- spec errors --------------------------------------------------------------------------------
@pytest.mark.parametrize("body, key", [
    ('type = "fog"\ndensity = [0.0, -0.5]', "density"),
    ('type = "fog"\ndensity = 0.2\ncolor = "grey"', "color"),
    ('type = "defocus"\nfstop = -1.0', "fstop"),
    ('type = "defocus"\nfstop = 2.0\nfocus_distance = "near"', "focus_distance"),
])
def test_a_bad_parameter_is_one_line_naming_the_key(tmp_path: Path, body: str, key: str) -> None:
    spec = write_spec(tmp_path, TINY_SPEC.replace('type = "blur"\nsigma = [0.0, 1.5]', body))
    with pytest.raises(SpecError) as caught:
        load_spec(spec)
    message = str(caught.value)
    assert "\n" not in message and f"controls[1].{key}" in message and "spec.toml" in message


def test_a_bad_knob_is_one_line_naming_its_key(tmp_path: Path) -> None:
    for line, key in (("dither = -1", "render.dither"), ('world_sampling = "importance"', "render.world_sampling")):
        folder = tmp_path / key.replace(".", "_")
        folder.mkdir()
        spec = write_spec(folder, TINY_SPEC.replace("denoise = false", f"denoise = false\n{line}"))
        result = CliRunner().invoke(app, ["plan", str(spec)])
        assert result.exit_code == 2
        assert key in result.output and "Traceback" not in result.output


@pytest.mark.parametrize("body, key, says", [
    (TINY_SPEC + "\n" + TWO_MODELS, "model", "either [model] or [[models]]"),
    (TINY_SPEC.replace("[model]\nbatch_size = 8\n", TWO_MODELS.replace('id = "lite0-onnx"\n', "")),
     "models", "give it its own id"),
    (TINY_SPEC.replace("[model]\nbatch_size = 8\n", TWO_MODELS.replace('name = "efficientnet-lite0"\nid',
                                                                       'name = "efficientnet-lite9"\nid')),
     "models[1].name", "unknown model 'efficientnet-lite9' (did you mean"),
])
def test_bad_models_are_one_line(tmp_path: Path, body: str, key: str, says: str) -> None:
    spec = write_spec(tmp_path, body)
    result = CliRunner().invoke(app, ["plan", str(spec)])
    assert result.exit_code == 2, result.output
    [line] = result.output.strip().splitlines()
    assert key in line and says in line
