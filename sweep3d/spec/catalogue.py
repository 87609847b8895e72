"""What a spec may name, handed to the loader by the layer that owns the plug-ins.

The spec layer knows no stage: the render stage owns the engines, the render and postprocess stages own the controls, the plan
stage the policies, the infer stage the models, evaluators and class names. A :class:`Catalogue`
bundles their registries so the loader can check names (with "did you mean") without importing
a stage; ``sweep3d.runner.builtins()`` builds the built-in one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Protocol

from sweep3d.core import Control, Registry


class LabelSpace(Protocol):
    """A model's class names: ``index`` maps a name or id to a class id, raising ValueError."""

    def index(self, label: int | str) -> int: ...


@dataclass(frozen=True)
class Catalogue:
    """The registries a spec's names resolve in.

    Attributes:
        controls: rendered and post-processing controls, by type name.
        policies: search policies, each with a pydantic ``Params`` model.
        models: model factories.
        evaluators: evaluators, each declaring its output columns as a pyarrow ``schema``.
        labels: the class names of a built-in model, or None for a user's model (whose classes
            are known only once it is loaded, at run time).
        engines: the renderers ``[render] engine`` may name (the render stage's backends).
    """

    controls: Registry[type[Control]]
    policies: Registry[Any]
    models: Registry[Any]
    evaluators: Registry[Any]
    labels: Callable[[str], LabelSpace | None]
    engines: Registry[Any]
