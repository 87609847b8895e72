"""The model's preprocessing in words (``Preprocess.describe``, recorded in ``verdicts.preprocess``):
the built-in EfficientNet-Lites normalise with mean = std = 0.5 (timm's ``tf_efficientnet_lite*``
configuration: inputs in [-1, 1]), not ImageNet's mean and std, and the words say so with numbers
that read back exactly; saying it changes no cache key."""

from __future__ import annotations

import ast
import re

from hypothesis import given
from hypothesis import strategies as st

from sweep3d.followups.realism.score import model_preprocess
from sweep3d.spec.framing import Framing
from sweep3d.stages.infer import ModelHandle
from sweep3d.stages.infer.models import IMAGENET_MEAN, LITE_PREPROCESS, Preprocess, builtin_model


def numbers(words: str, name: str) -> tuple[float, ...]:
    return ast.literal_eval(re.search(rf"{name} = (\([^)]*\))", words).group(1))


def test_the_built_in_models_say_mean_and_std_one_half() -> None:
    for variant, side in ((0, 224), (1, 240), (2, 260)):
        preprocess = builtin_model(f"efficientnet-lite{variant}")[1]
        assert preprocess is LITE_PREPROCESS[variant]
        words = preprocess.describe()
        assert numbers(words, "mean") == numbers(words, "std") == (0.5, 0.5, 0.5), words
        assert f"short side resized to {round(side / 0.875)} " in words and f"centre crop {side}x{side}" in words
    assert LITE_PREPROCESS[0].key_part() == {"resize": 256, "crop": 224, "mean": [0.5] * 3, "std": [0.5] * 3}
    assert numbers(Preprocess().describe(), "mean") == IMAGENET_MEAN  # a user's default: ImageNet's


def test_a_model_framed_handle_describes_the_preprocessing_inference_applies() -> None:
    handle = ModelHandle("efficientnet-lite0", None, Framing.of_model(256, 224), "", LITE_PREPROCESS[0])
    assert "short side resized to 224 " in model_preprocess(handle)
    handle.framing = Framing.full(224)
    assert model_preprocess(handle) == LITE_PREPROCESS[0].describe()
    handle.preprocess = lambda images: images  # a factory's own callable: its numbers are unknown
    assert "cannot read" in model_preprocess(handle)


channel = st.floats(min_value=1e-300, max_value=1e300, allow_nan=False) | st.integers(0, 255)


@given(st.tuples(channel, channel, channel), st.tuples(channel, channel, channel))
def test_the_numbers_read_back_exactly(mean, std) -> None:
    words = Preprocess(mean=mean, std=std).describe()
    assert numbers(words, "mean") == tuple(float(v) for v in mean)
    assert numbers(words, "std") == tuple(float(v) for v in std)
