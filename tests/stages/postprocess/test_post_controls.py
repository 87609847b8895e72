"""Post-processing controls on plain arrays: each changes the image, stays finite at its range
ends, is reproducible from the job's key, and is the identity at its neutral values."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sweep3d.core.control import ControlParams
from sweep3d.runner import builtin_catalogue as catalogue
from sweep3d.stages.postprocess import PostControl, apply_post
from sweep3d.stages.postprocess.controls import CORRUPTIONS
from tests.helpers import examples

CONTROLS = catalogue().controls

RNG_KEY = "0123456789abcdef0123"


def photo(size: int = 48) -> np.ndarray:
    """A smooth colourful test image, float32 (size, size, 3)."""
    y, x = np.mgrid[0:size, 0:size] / (size - 1)
    return np.stack([x, y, 0.5 + 0.4 * np.sin(6 * x * y)], axis=-1).astype(np.float32)


def post_control(name: str) -> PostControl:
    control = CONTROLS.get(name)(name, name)
    assert isinstance(control, PostControl)
    return control


def run(control: PostControl, image: np.ndarray, key: str = RNG_KEY, **values) -> np.ndarray:
    rng = np.random.default_rng(int(key[:16], 16))
    return control.apply(image, control.params(values), rng)


# (control, values that change the image, the far ends of its range)
CASES = [
    ("blur", {"sigma": 2.0}, [{"sigma": 1000.0}]),
    ("noise", {"std": 0.1}, [{"std": 100.0}]),
    ("brightness_contrast", {"brightness": 0.2}, [{"brightness": -1.0, "contrast": 0.0}, {"brightness": 1.0, "contrast": 100.0}]),
    ("color_jitter", {"hue": 0.25}, [{"hue": -0.5, "saturation": 0.0}, {"hue": 0.5, "saturation": 10.0}]),
    ("jpeg", {"quality": 5}, [{"quality": 1}]),
    ("cutout", {"size": 0.3}, [{"size": 1.0, "x": 1.0, "y": -1.0, "value": 0.0}, {"size": 1.0, "value": 1.0}]),
] + [("corruption", {"name": name, "severity": 3}, [{"name": name, "severity": 1}, {"name": name, "severity": 5}])
     for name in CORRUPTIONS]


@pytest.mark.parametrize("name, values, extremes", CASES, ids=[
    c[0] if c[0] != "corruption" else f"corruption-{c[1]['name']}" for c in CASES])
def test_control_changes_the_image_and_stays_finite(name, values, extremes) -> None:
    control = post_control(name)
    image = photo()
    assert control.is_identity(control.Params().model_dump())
    assert np.array_equal(run(control, image, **control.Params().model_dump()), image)
    changed = run(control, image, **values)
    assert changed.shape == image.shape and changed.dtype == np.float32
    assert np.abs(changed - image).mean() > 1e-3, f"{name} {values} left the image unchanged"
    assert not control.is_identity(values)
    for extreme in extremes:
        out = run(control, image, **extreme)
        assert out.shape == image.shape and np.isfinite(out).all()
        assert out.min() >= 0.0 and out.max() <= 1.0


@pytest.mark.parametrize("name, values", [("noise", {"std": 0.2})] + [
    ("corruption", {"name": n, "severity": 4}) for n in CORRUPTIONS])
def test_random_controls_are_reproducible_from_the_key(name, values) -> None:
    control = post_control(name)
    first = run(control, photo(), **values)
    np.random.seed(12345)  # a polluted global generator must not matter
    again = run(control, photo(), **values)
    assert np.array_equal(first, again)


def test_different_keys_give_different_noise() -> None:
    control = post_control("noise")
    a = run(control, photo(), key="1" * 20, std=0.2)
    b = run(control, photo(), key="2" * 20, std=0.2)
    assert not np.array_equal(a, b)


def test_corruptions_refuse_tiny_images_with_a_fix() -> None:
    from sweep3d.core.errors import UserError

    with pytest.raises(UserError, match="render.resolution"):
        run(post_control("corruption"), photo(16), name="fog", severity=2)


def test_apply_post_skips_identity_controls_and_keeps_order() -> None:
    from sweep3d.spec.loader import ControlInstance

    blur = ControlInstance(post_control("blur"), {})
    cut = ControlInstance(CONTROLS.get("cutout")("cut", "cutout"), {})
    image = photo()
    values = {"blur": {"sigma": 0.0}, "cut": {"size": 0.5, "x": 0.0, "y": 0.0, "value": 0.0}}
    out = apply_post(image, [blur, cut], values, RNG_KEY)
    assert out[24, 24].max() == 0.0  # the cutout, not blurred afterwards
    assert np.array_equal(out[0], image[0])


@settings(max_examples=examples(60), deadline=None)
@given(st.floats(0, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(0, 1))
def test_cutout_never_leaves_the_range(size, x, y, value) -> None:
    out = run(post_control("cutout"), photo(), size=size, x=x, y=y, value=value)
    assert out.shape == (48, 48, 3) and np.isfinite(out).all() and 0 <= out.min() <= out.max() <= 1


def test_a_users_post_control_that_raises_or_returns_no_image_is_one_line_naming_it() -> None:
    from sweep3d.core.errors import PluginError
    from sweep3d.spec.loader import ControlInstance

    class Broken(PostControl):
        class Params(ControlParams):
            mode: str = ""  # neutral: the modes below are not

        def apply(self, image, params, rng):
            if params.mode == "raise":
                raise RuntimeError("no vignette today")
            return "not an image" if params.mode == "text" else image[:2]

    inst = ControlInstance(Broken("broken", "mypost:Broken"), {})
    image = np.zeros((8, 8, 3), np.float32)
    expected = {"raise": "(test_post_controls.py:", "text": "returned a str from apply()",
                "crop": "returned an array of shape (2, 8, 3) from apply(); return the image as a float array of "
                        "shape (8, 8, 3)"}
    for mode, says in expected.items():
        with pytest.raises(PluginError) as caught:
            apply_post(image, [inst], {"broken": {"mode": mode}}, "ab" * 10)
        message = str(caught.value)
        assert message.startswith("control 'mypost:Broken' (id 'broken')") and says in message, message
        assert "\n" not in message
    assert "RuntimeError: no vignette today" in str(pytest.raises(PluginError, apply_post, image, [inst],
                                                                  {"broken": {"mode": "raise"}}, "ab" * 10).value)
