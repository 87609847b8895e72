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

from sweep3d.errors import SpecError, UserError
from sweep3d.spec.framing import Framing
from sweep3d.spec.loader import LoadedSpec
from sweep3d.stages.infer.models import (
    Classifier,
    Preprocess,
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
        framing: the frame renders are made in (the model's view for ``resolution = "model"``).
        digest: the model's part of prediction keys (weights and the preprocessing for this framing).
        preprocess: the model's own preprocessing, as its factory gives it (before framing).
    """

    name: str
    framing: Framing
    digest: str
    preprocess: Any
    _classifier: Classifier | None = field(default=None, repr=False)

    @classmethod
    def resolve(cls, spec: LoadedSpec) -> ModelHandle:
        """Resolve ``spec``'s model and frame; a user's factory is called here, once.

        Raises:
            SpecError: naming ``model.name`` when the factory fails, or ``render.resolution`` when
                the model's input size cannot be known.
        """
        name = spec.model.name
        builtin = builtin_model(name)
        loaded = None
        try:
            if builtin is not None:
                weights, preprocess = builtin[0](), builtin[1]
            else:
                loaded = load_model(name)
                weights, preprocess = loaded.weights_digest or module_digest(loaded.module), loaded.preprocess
        except SpecError:
            raise
        except UserError as exc:
            raise SpecError(str(spec.path), "model.name", str(exc)) from None
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
        return cls(name, framing, model_key(name, weights, preprocess), own, loaded)

    @property
    def view(self) -> Preprocess | None:
        """The model's resize and crop when they are known (a :class:`Preprocess`), else None."""
        return self.preprocess if isinstance(self.preprocess, Preprocess) else None

    def classifier(self) -> Classifier:
        """The model ready for inference (loaded on first use), preprocessing for this framing."""
        if self._classifier is None:
            model = load_model(self.name)
            if self.framing.model:  # the image is the model's input already: no resize or crop again
                model = dataclasses.replace(model, preprocess=for_model_framing(model.preprocess, self.name))
            self._classifier = model
        return self._classifier
