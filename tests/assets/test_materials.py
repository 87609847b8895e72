"""An OBJ's materials checked at spec load (issue 45, item 5): each bad MTL, missing MTL or bad
texture is one ``error:`` line naming the file, the line and the fix, exit code 2, and the store
as it was; what neither renderer reads only warns. No render: everything is refused at ``plan``.

:data:`BAD_MTLS` and :data:`BAD_TEXTURES` are data (MTL text, the phrase the error must hold) so
that a corpus of bad inputs can take them as they are.
"""

from __future__ import annotations

import hashlib
import io
import math
import zipfile
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from typer.testing import CliRunner

from sweep3d.assets.materials import check_materials
from sweep3d.assets.mtl_values import COLOUR_SLACK, FLOAT32_MAX, check_mtl_text
from sweep3d.cli import app
from tests.helpers import CUBE_OBJ, TINY_SPEC, write_spec

#: (id, the MTL's text, a phrase its one error line holds). The MTL is ``cube.mtl``, named by the
#: cube's ``mtllib``; a line number in the phrase is the bad line's.
BAD_MTLS = [
    ("kd-huge-negative", "newmtl m\nKd 1e300 1e300 -5\n", "cube.mtl line 2 ('Kd 1e300 1e300 -5'): '1e300' is too large"),
    ("kd-nan", "newmtl m\nKd 1 nan 0\n", "cube.mtl line 2 ('Kd 1 nan 0'): 'nan' is not a finite number"),
    ("kd-inf", "newmtl m\nKd inf 0 0\n", "'inf' is not a finite number"),
    ("kd-float32-overflow", "newmtl m\nKd 1e39 0 0\n", "'1e39' is too large to be finite in 32 bits"),
    ("kd-over-one", "newmtl m\nKd 0.5 1.5 0.5\n", "Kd 1.5 is over 1"),
    ("kd-negative", "newmtl m\nKd 0.5 -0.2 0.5\n", "Kd -0.2 is negative"),
    ("kd-two-values", "newmtl m\nKd 0.5 0.5\n", "Kd needs one grey value or three"),
    ("kd-word", "newmtl m\nKd red 0 0\n", "'red' is not a number"),
    ("ks-nan", "newmtl m\nKs nan nan nan\n", "line 2 ('Ks nan nan nan')"),
    ("tf-negative", "newmtl m\nTf -2 0 0\n", "Tf -2 is negative"),
    ("ks-float32-overflow", "newmtl m\nKs 4e38\n", "'4e38' is too large to be finite in 32 bits"),
    ("ke-negative", "newmtl m\nKe -1 0 0\n", "Ke -1 is negative"),
    ("ns-word", "newmtl m\nNs abc\n", "cube.mtl line 2 ('Ns abc'): 'abc' is not a number; give Ns as a number"),
    ("ns-underscore", "newmtl m\nNs 1_0\n", "'1_0' is not a number"),
    ("ni-nan", "newmtl m\nNi nan\n", "'nan' is not a finite number"),
    ("d-infinity", "newmtl m\nd -infinity\n", "'-infinity' is not a finite number"),
    ("illum-fraction", "newmtl m\nillum 2.5\n", "illum must be a whole number"),
    ("second-material", "newmtl a\nKd 0.5 0.5 0.5\n\nnewmtl b\nKd 0.5 0.5 nan\n", "cube.mtl line 5"),
    ("binary", "newmtl m\n\x00\x01\x02", "not a text MTL file"),
    ("missing-texture", "newmtl m\nmap_Kd wood.png\n", "the texture wood.png does not exist beside the MTL"),
    ("missing-bump", "newmtl m\nmap_Bump -bm 0.5 bumps.png\n", "the texture bumps.png does not exist"),
    ("texture-folder", "newmtl m\nmap_Kd .\n", ". is a directory, not a file"),
]

#: (id, the texture's bytes, the phrase): ``map_Kd tex.png`` names a file holding those bytes.
BAD_TEXTURES = [
    ("text", b"not an image\n", "tex.png is not a readable image (no image format recognised"),
    ("empty", b"", "tex.png is not a readable image (the file is empty)"),
    ("truncated-png", None, "tex.png is not a readable image"),  # None: a real PNG cut short
]

#: MTL lines that load: values renderers take, and what neither reads (a warning, not an error).
GOOD_MTLS = [
    "newmtl m\nKd 0.8 0.8 0.8\nKs 1.35 1.35 1.35\nKe 5 5 5\nNs 96.078431\nNi 1.45\nd 1.0\nillum 2\n",
    "newmtl m\nKd 1.000001 0 0 # rounding\nKd spectral file.rfl\nTf xyz 0.5 0.5 0.5\n",
    "newmtl m\nKa nan 0 0\nmap_Ka missing.png\nmap_Disp /Users/someone/rug.jpg\n",  # warnings only
]


def _png(size: int = 4) -> bytes:
    from PIL import Image

    out = io.BytesIO()
    Image.new("RGB", (size, size), (120, 80, 40)).save(out, format="PNG")
    return out.getvalue()


def _checksums(root: Path) -> dict[str, str]:
    """The store's files and their SHA-256 (the lock file records only the last holder's pid)."""
    if not root.exists():
        return {}
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file() and p.name != "lock"}


def _spec(folder: Path, mtl: str | bytes | None, files: dict[str, bytes] | None = None,
          mtllib: str = "cube.mtl") -> Path:
    """TINY_SPEC with its cube naming ``mtllib`` (written from ``mtl`` unless None) and ``files`` beside it."""
    spec = write_spec(folder, TINY_SPEC)
    (folder / "cube.obj").write_text(f"mtllib {mtllib}\nusemtl m\n{CUBE_OBJ}")
    if mtl is not None:
        (folder / "cube.mtl").write_bytes(mtl.encode() if isinstance(mtl, str) else mtl)
    for name, data in (files or {}).items():
        (folder / name).write_bytes(data)
    return spec


def _refused(spec: Path, phrase: str, command: str = "plan") -> str:
    """``command`` on ``spec``: exit 2, one error line naming the spec, the mesh key and ``phrase``,
    no traceback, the store's files unchanged (checksums)."""
    store = spec.parent / "store"
    before = _checksums(store)
    result = CliRunner().invoke(app, [command, str(spec)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    assert f"{spec}: objects[0].mesh: " in errors[0], errors[0]
    assert phrase in errors[0], f"{phrase!r} not in {errors[0]!r}"
    assert _checksums(store) == before, "the store changed"
    return errors[0]


@pytest.mark.parametrize("mtl, phrase", [c[1:] for c in BAD_MTLS], ids=[c[0] for c in BAD_MTLS])
def test_a_bad_mtl_is_one_line_and_exit_2(tmp_path: Path, mtl: str, phrase: str) -> None:
    line = _refused(_spec(tmp_path, mtl), phrase)
    assert "fix" in line or "copy" in line or "export" in line or "give" in line, line  # it says what to do


@pytest.mark.parametrize("data, phrase", [c[1:] for c in BAD_TEXTURES], ids=[c[0] for c in BAD_TEXTURES])
def test_a_texture_that_is_not_an_image_is_one_line(tmp_path: Path, data: bytes | None, phrase: str) -> None:
    data = _png(64)[:-30] if data is None else data
    line = _refused(_spec(tmp_path, "newmtl m\nmap_Kd tex.png\n", {"tex.png": data}), phrase)
    assert "cube.mtl line 2 ('map_Kd tex.png')" in line and "save it again as PNG" in line


def test_a_missing_mtl_is_one_line_naming_the_obj_line(tmp_path: Path) -> None:
    line = _refused(_spec(tmp_path, None, mtllib="gone.mtl"), "cube.obj line 1 ('mtllib gone.mtl'): gone.mtl does not exist")
    assert "copy the MTL there or remove the mtllib line" in line


def test_run_refuses_a_bad_mtl_before_anything_renders(tmp_path: Path) -> None:
    _refused(_spec(tmp_path, "newmtl m\nKd 1 nan 0\n"), "'nan' is not a finite number", command="run")


@pytest.mark.parametrize("mtl", GOOD_MTLS)
def test_good_materials_load(tmp_path: Path, mtl: str) -> None:
    result = CliRunner().invoke(app, ["plan", str(_spec(tmp_path, mtl))])
    assert result.exit_code == 0, result.output
    assert "error:" not in result.output


def test_what_neither_renderer_reads_is_a_warning(tmp_path: Path) -> None:
    """A NaN ``Ka`` and a missing ``map_Ka`` change no pixel: one warning line each, and the plan goes on."""
    audit = check_materials(str(_spec(tmp_path, GOOD_MTLS[2]).parent / "cube.obj"))
    assert len(audit.warnings) == 3
    assert "line 2 ('Ka nan 0 0')" in audit.warnings[0] and "reads Ka, so it is ignored" in audit.warnings[0]
    assert "line 3 ('map_Ka missing.png')" in audit.warnings[1] and "reads map_Ka" in audit.warnings[1]


def test_a_texture_is_found_as_the_renderers_find_it(tmp_path: Path) -> None:
    """Options before the file, a path with spaces, a Windows path and a sub-folder all resolve."""
    (tmp_path / "tex").mkdir()
    files = {"my wood.png": _png(), "tex/bark.png": _png(), "leaf.png": _png()}
    mtl = ("newmtl a\nmap_Kd -s 1 1 1 -o 0 0 my wood.png\n"
           "newmtl b\nmap_Kd tex\\bark.png\n"
           "newmtl c\nmap_Kd C:\\Users\\someone\\leaf.png\n")  # a bare name beside the MTL, as Blender looks
    spec = _spec(tmp_path, mtl, files)
    audit = check_materials(str(spec.parent / "cube.obj"))
    assert [fmt for _, fmt in audit.base_textures] == ["PNG", "PNG", "PNG"]


def test_several_libraries_on_one_mtllib_line(tmp_path: Path) -> None:
    spec = _spec(tmp_path, "newmtl a\nKd 0.5 0.5 0.5\n", {"b.mtl": b"newmtl b\nKd 0.5 nan 0.5\n"},
                 mtllib="cube.mtl b.mtl")
    _refused(spec, "b.mtl line 2 ('Kd 0.5 nan 0.5')")


def test_a_mesh_in_a_zip_is_checked_among_the_files_extracted_with_it(tmp_path: Path) -> None:
    """Its MTL and texture are read from the archive; a texture in a sub-folder is not extracted with
    the mesh, so it is missing at render time and refused now."""
    archive = tmp_path / "furniture.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        zf.writestr("chair/chair.obj", f"mtllib chair.mtl\nusemtl m\n{CUBE_OBJ}")
        zf.writestr("chair/chair.mtl", "newmtl m\nmap_Kd sub/wood.png\n")
        zf.writestr("chair/sub/wood.png", _png())
    with pytest.raises(Exception) as info:
        check_materials(f"{archive}#chair/chair.obj")
    assert "furniture.zip#chair/chair.mtl line 2 ('map_Kd sub/wood.png'): the texture sub/wood.png does not exist" \
        in str(info.value)
    with zipfile.ZipFile(archive, "w") as zf:
        zf.writestr("chair/chair.obj", f"mtllib chair.mtl\nusemtl m\n{CUBE_OBJ}")
        zf.writestr("chair/chair.mtl", "newmtl m\nmap_Kd wood.png\n")
        zf.writestr("chair/wood.png", b"GIF89a? not really")
    with pytest.raises(Exception) as info:
        check_materials(f"{archive}#chair/chair.obj")
    assert "furniture.zip#chair/wood.png is not a readable image" in str(info.value)


def test_mitsuba_refuses_a_texture_format_it_cannot_read(tmp_path: Path) -> None:
    """A TIFF base-colour texture: Cycles reads it, Mitsuba's bitmap reader fails every job on it."""
    pytest.importorskip("mitsuba")
    from PIL import Image

    Image.new("RGB", (4, 4)).save(tmp_path / "wood.tif")
    spec = _spec(tmp_path, "newmtl m\nmap_Kd wood.tif\n")
    spec.write_text(spec.read_text().replace("[render]\n", '[render]\nengine = "mitsuba"\n', 1))
    line = _refused(spec, "cube.mtl line 2 ('map_Kd wood.tif'): a TIFF texture, which the mitsuba engine cannot read")
    assert "save it as PNG" in line


@given(st.floats(allow_nan=True, allow_infinity=True, width=64))
def test_a_colour_channel_is_refused_exactly_outside_its_range(value: float) -> None:
    """At the numeric edges (the slack, 32-bit overflow, NaN, infinities, subnormals): a Kd channel is
    an error exactly when it is not finite in 32 bits or lies outside [−slack, 1 + slack]."""
    problems = check_mtl_text(f"newmtl m\nKd 0.5 {value!r} 0.5\n")
    bad = not math.isfinite(value) or abs(value) > FLOAT32_MAX or not -COLOUR_SLACK <= value <= 1 + COLOUR_SLACK
    assert bool(problems) == bad, (value, problems)
    assert all(p.fatal and p.line == 2 for p in problems)
