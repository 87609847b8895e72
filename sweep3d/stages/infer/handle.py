"""The spec's model, resolved once per run: its name, framing, digest and (lazily) the module.

Resolving a model means knowing its input sizes (for ``resolution = "model"``) and its digest
(for prediction keys). For a built-in model both are known without importing torch; a user's
factory has to be called, and the :class:`ModelHandle` keeps what it returned, so the factory
runs once per run however many parts of the run need the model.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from sweep3d.core import SpecError, UserError, code_identity
from sweep3d.spec import Framing, LoadedSpec, ModelSpec
from sweep3d.stages.infer.labels import LabelMap
from sweep3d.stages.infer.models import (
    MODELS,
    Classifier,
    Preprocess,
    builtin_labels,
    builtin_model,
    for_model_framing,
    load_model,
    model_key,
    module_digest,
)


@dataclass
class ModelHandle:
    """What a run needs to know of its model.

    Attributes:
        name: the model's name in the spec (built-in, or ``module:factory``).
        settings: its entry in the spec (``[model]`` or one of ``[[models]]``).
        framing: the frame renders are made in (the model's view for ``resolution = "model"``).
        digest: the model's part of prediction keys (weights and the preprocessing for this framing).
        preprocess: the model's own preprocessing, as its factory gives it (before framing).
    """

    name: str
    settings: ModelSpec
    framing: Framing
    digest: str
    preprocess: Any
    _classifier: Classifier | None = field(default=None, repr=False)

    @classmethod
    def resolve(cls, spec: LoadedSpec, settings: ModelSpec | None = None) -> ModelHandle:
        """Resolve one of ``spec``'s models (default: its first) and its frame; a user's factory is
        called here, once.

        Raises:
            SpecError: naming the model's ``name`` key when the factory fails, or
                ``render.resolution`` when the model's input size cannot be known.
        """
        settings = settings or spec.model
        name = settings.name
        key = model_key_path(spec, settings)
        builtin = builtin_model(name)
        loaded = None
        try:
            if builtin is not None:
                weights, preprocess = builtin[0](), builtin[1]
            else:
                loaded = load_model(name)
                weights, preprocess = loaded.weights_digest or module_digest(loaded.module), loaded.preprocess
                weights += f"+{code_identity(MODELS.get(name))}"  # the factory's code: editing it re-infers
        except SpecError:
            raise
        except UserError as exc:
            raise SpecError(str(spec.path), key, str(exc)) from None
        try:
            preprocess = with_arithmetic(preprocess, settings.resize_arithmetic, name)
            if loaded is not None:
                loaded = dataclasses.replace(loaded, preprocess=preprocess)
        except UserError as exc:
            raise SpecError(str(spec.path), key.replace(".name", ".resize_arithmetic"), str(exc)) from None
        own = preprocess
        framing = Framing.full(spec.render.resolution) if spec.render.resolution != "model" else None
        if framing is None:
            try:
                framed = for_model_framing(preprocess, name)
            except UserError as exc:
                raise SpecError(str(spec.path), "render.resolution", str(exc)) from None
            framing, preprocess = Framing.of_model(preprocess.resize, preprocess.crop), framed
            if loaded is not None:
                loaded = dataclasses.replace(loaded, preprocess=framed)
        return cls(name, settings, framing, model_key(name, weights, preprocess), own, loaded)

    @property
    def label(self) -> str:
        """What results call the model (its ``id``, else its name)."""
        return self.settings.label

    @property
    def applied(self) -> Any:
        """The preprocessing inference applies in this framing: the model's own, less the resize
        where the render is the model's input already (``resolution = "model"``)."""
        if self.framing.model and isinstance(self.preprocess, Preprocess):
            return for_model_framing(self.preprocess, self.name)
        return self.preprocess

    @property
    def view(self) -> Preprocess | None:
        """The model's resize and crop when they are known (a :class:`Preprocess`), else None."""
        return self.preprocess if isinstance(self.preprocess, Preprocess) else None

    def label_map(self) -> LabelMap | None:
        """The model's class names: a built-in model's without loading it, a user's as its
        factory gave them (None when it has not been called)."""
        if builtin_model(self.name) is not None:
            return builtin_labels(self.name)
        return self._classifier.label_map() if self._classifier is not None else None

    def unloaded(self) -> Classifier:
        """A built-in model's preprocessing for this framing and its classes, its torch module not
        loaded (None): what ONNX Runtime needs to serve it (see ``onnx_backend``)."""
        if builtin_model(self.name) is None:
            raise ValueError(f"{self.name!r} is not a built-in model: its factory gives its preprocessing")
        preprocess = for_model_framing(self.preprocess, self.name) if self.framing.model else self.preprocess
        return Classifier(None, preprocess, None)

    def classifier(self) -> Classifier:
        """The model ready for inference (loaded on first use), preprocessing for this framing."""
        if self._classifier is None:
            model = load_model(self.name)
            model = dataclasses.replace(model, preprocess=with_arithmetic(model.preprocess,
                                                                          self.settings.resize_arithmetic, self.name))
            if self.framing.model:  # the image is the model's input already: no resize or crop again
                model = dataclasses.replace(model, preprocess=for_model_framing(model.preprocess, self.name))
            self._classifier = model
        return self._classifier


def model_key_path(spec: LoadedSpec, settings: ModelSpec) -> str:
    """The spec key naming ``settings``' model: ``model.name`` or ``models[i].name``."""
    for i, model in enumerate(spec.spec.models):
        if model is settings:
            return f"models[{i}].name"
    return "model.name"


def with_arithmetic(preprocess: Any, arithmetic: str, name: str) -> Any:
    """``preprocess`` resizing with ``[model] resize_arithmetic`` (itself for the default).

    Raises:
        UserError: a non-default arithmetic for a model whose preprocessing is not sweep3d's.
    """
    if arithmetic == "float" or getattr(preprocess, "arithmetic", None) == arithmetic:
        return preprocess
    if not isinstance(preprocess, Preprocess):
        raise UserError(f"model {name!r} preprocesses with a {type(preprocess).__name__}, not sweep3d's Preprocess, "
                        f"so resize_arithmetic = {arithmetic!r} cannot apply; remove it or resize in your own preprocessing")
    return dataclasses.replace(preprocess, arithmetic=arithmetic)
