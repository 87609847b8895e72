"""sweep3d.core.registry.Registry: short names, suggestions, and user plug-ins named 'module:Name'."""

from __future__ import annotations

import hashlib
import importlib
import sys
import textwrap

import pytest

from sweep3d.core.errors import UserError
from sweep3d.core.registry import Registry, code_identity, local_imports
from sweep3d.runner import builtin_catalogue as catalogue
from tests.helpers import TINY_SPEC, load_spec, plan_for, write_spec

CONTROLS = catalogue().controls


def make_registry() -> Registry:
    registry: Registry = Registry("widget")

    @registry.register("sprocket")
    class Sprocket:
        pass

    @registry.register("gear")
    def gear():
        return "gear"

    return registry


def test_register_and_get():
    registry = make_registry()
    assert registry.get("gear")() == "gear"
    assert registry.get("sprocket").__name__ == "Sprocket"
    assert registry.names() == ["gear", "sprocket"]
    assert list(registry) == ["gear", "sprocket"]
    assert "gear" in registry and "cog" not in registry


def test_registering_a_name_twice_is_refused_unless_it_is_the_same_item():
    registry = make_registry()
    gear = registry.get("gear")
    assert registry.register("gear")(gear) is gear  # re-import of the same module is harmless
    with pytest.raises(ValueError, match="'gear' is already registered"):
        registry.register("gear")(lambda: "other")
    assert registry.get("gear") is gear


def test_unknown_name_lists_valid_names_and_suggests_a_close_one():
    with pytest.raises(UserError) as caught:
        make_registry().get("sprockett")
    message = str(caught.value)
    assert "unknown widget 'sprockett'" in message
    assert "did you mean 'sprocket'?" in message
    assert "valid: gear, sprocket" in message
    assert "module:Name" in message


def test_unknown_name_without_a_close_match_has_no_suggestion():
    with pytest.raises(UserError) as caught:
        make_registry().get("zzzzzz")
    assert "did you mean" not in str(caught.value)
    assert "valid: gear, sprocket" in str(caught.value)


def test_union_holds_every_part_and_refuses_a_name_twice():
    first, second = make_registry(), Registry("widget")
    second.register("flange")(object)
    union = Registry.union("widget", first, second)
    assert union.names() == sorted(first.names() + ["flange"])
    assert union.get("flange") is object and union.get("gear") is first.get("gear")
    with pytest.raises(ValueError, match="already registered"):
        Registry.union("widget", first, make_registry())


def test_builtin_controls_come_from_both_stages():
    names = CONTROLS.names()
    assert {"orientation", "camera", "scale", "position", "blur", "noise", "brightness_contrast"} <= set(names)
    with pytest.raises(UserError, match="did you mean 'orientation'"):
        CONTROLS.get("orientaton")


# -- user modules ----------------------------------------------------------------------------


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    """Write modules into a folder on sys.path; they are forgotten after the test."""
    monkeypatch.syspath_prepend(str(tmp_path))
    written = []

    def write(name: str, source: str) -> str:
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(source))
        monkeypatch.delitem(sys.modules, name, raising=False)
        written.append(name)
        return name

    yield write
    for name in written:
        sys.modules.pop(name, None)


def test_module_colon_name_imports_the_users_plugin(user_module):
    module = user_module("sweep3d_test_widgets", """
        class Flange:
            size = 3
    """)
    registry = make_registry()
    name = f"{module}:Flange"
    assert name not in registry  # only registered short names are members; get() imports
    flange = registry.get(name)
    assert flange.size == 3
    assert flange is sys.modules[module].Flange
    assert registry.names() == ["gear", "sprocket"]  # user plug-ins are not added to the list


def test_dotted_package_path(user_module, tmp_path):
    package = tmp_path / "sweep3d_test_pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "plugins.py").write_text("class Cog:\n    teeth = 12\n")
    try:
        assert make_registry().get("sweep3d_test_pkg.plugins:Cog").teeth == 12
    finally:
        for name in ("sweep3d_test_pkg.plugins", "sweep3d_test_pkg"):
            sys.modules.pop(name, None)


@pytest.mark.parametrize(
    "source, attr, text",
    [
        (None, "Flange", "cannot import widget module"),
        ("class Other: pass\n", "Flange", "has no widget named 'Flange'"),
        ("class Broken(:\n", "Broken", "SyntaxError"),
        ("raise RuntimeError('needs a GPU')\n", "X", "needs a GPU"),
    ],
    ids=["no-such-module", "no-such-name", "syntax-error", "raises-on-import"],
)
def test_bad_user_module_is_a_user_error(user_module, source, attr, text):
    module = "sweep3d_test_missing_module"
    if source is not None:
        module = user_module("sweep3d_test_bad_module", source)
    with pytest.raises(UserError) as caught:
        make_registry().get(f"{module}:{attr}")
    assert text in str(caught.value)
    assert module in str(caught.value)


def test_empty_module_name_is_a_user_error():
    with pytest.raises(UserError):
        make_registry().get(":Flange")


HELPED = """
    import json

    import numpy as np
    from pydantic import Field
    from sweep3d.plugins import ControlParams, PostControl
    from sweep3d_test_helper import FACTOR


    class Dim(PostControl):
        class Params(ControlParams):
            strength: float = Field(0.0)

        def apply(self, image, params, rng):
            from sweep3d_test_lazy import OFFSET
            return image * (1.0 - FACTOR * params.strength) + OFFSET
"""


def test_a_plug_ins_identity_covers_the_modules_beside_the_spec_it_imports(user_module, tmp_path):
    """Editing helper.py, which the post control's module imports, redoes the images (it left
    them cached); an import inside a method counts too, installed packages do not."""
    user_module("sweep3d_test_helper", "FACTOR = 0.5\n")
    user_module("sweep3d_test_lazy", "OFFSET = 0.0\n")
    name = user_module("sweep3d_test_helped", HELPED)
    spec = write_spec(tmp_path, TINY_SPEC.replace("[policy]", f'[[controls]]\ntype = "{name}:Dim"\nstrength = [0.5]'
                                                               "\n\n[policy]"))

    def keys() -> tuple[set[str], set[str]]:
        code_identity.cache_clear()  # as a new process would
        plan = plan_for(load_spec(spec), "m")
        return {j.render_key for j in plan.jobs}, {j.image_key for j in plan.jobs}

    renders, images = keys()
    assert [n for n, _ in local_imports(sys.modules[name])] == ["sweep3d_test_helper", "sweep3d_test_lazy"]
    assert keys() == (renders, images)
    (tmp_path / "sweep3d_test_helper.py").write_text("FACTOR = 0.25\n")
    edited = keys()
    assert edited[0] == renders and edited[1].isdisjoint(images)
    (tmp_path / "sweep3d_test_lazy.py").write_text("OFFSET = 0.1\n")
    assert keys()[1].isdisjoint(edited[1])


def test_a_plug_in_that_imports_nothing_of_its_own_keeps_the_identity_of_its_source(user_module, tmp_path):
    """Stores keyed before local imports counted stay valid for such plug-ins."""
    name = user_module("sweep3d_test_plain", "import json\nimport numpy as np\n\n\nclass Plain:\n    pass\n")
    module = importlib.import_module(name)
    assert local_imports(module) == []
    source = (tmp_path / f"{name}.py").read_bytes()
    assert code_identity(module.Plain) == "source:" + hashlib.sha256(source).hexdigest()[:16]


def test_relative_and_package_imports_are_found_without_importing_them(tmp_path, monkeypatch):
    package = tmp_path / "sweep3d_test_kit"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "sub" / "__init__.py").write_text("")
    (package / "plugin.py").write_text("from . import tools\nfrom .sub import deep\n\n\nclass P:\n    pass\n")
    (package / "tools.py").write_text("from .sub.deeper import X\n")
    (package / "sub" / "deep.py").write_text("Y = 1\n")
    (package / "sub" / "deeper.py").write_text("X = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    plugin = importlib.import_module("sweep3d_test_kit.plugin")
    try:
        for name in ("sweep3d_test_kit.tools", "sweep3d_test_kit.sub.deeper"):
            sys.modules.pop(name, None)  # not imported: found where an import would look
        assert [n for n, _ in local_imports(plugin)] == [
            "sweep3d_test_kit", "sweep3d_test_kit.sub", "sweep3d_test_kit.sub.deep", "sweep3d_test_kit.sub.deeper",
            "sweep3d_test_kit.tools"]
        assert "sweep3d_test_kit.tools" not in sys.modules
    finally:
        for name in [n for n in sys.modules if n.startswith("sweep3d_test_kit")]:
            sys.modules.pop(name, None)
