"""sweep3d.registry.Registry: short names, suggestions, and user plug-ins named 'module:Name'."""

from __future__ import annotations

import sys
import textwrap

import pytest

from sweep3d.errors import UserError
from sweep3d.registry import Registry
from sweep3d.stages import catalogue

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
