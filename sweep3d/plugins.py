"""Everything a user's plug-in subclasses or returns, from one module.

Controls (rendered: set the :class:`SceneState` Blender draws and/or edit the live scene through a
:class:`SceneEdit`; post: map one image to another),
policies (turn a :class:`SpaceShape` into :class:`Point` objects), models (a factory returning a
:class:`Classifier`, :class:`Detector` or :class:`Segmenter`, with its :class:`Preprocess`),
evaluators and export formats (a :class:`DatasetWriter`, named by ``sweep3d export --format
module:Name``). None of these imports torch or bpy: a model's factory imports torch itself. Each name
is imported on first use (PEP 562), so a render worker importing a user's control module loads the
control classes it names and neither DuckDB nor pyarrow.
"""

from __future__ import annotations

__all__ = ["Classifier", "ControlParams", "DatasetWriter", "Detector", "Evaluator", "EvaluatorParams", "Normalize",
           "Outcome", "Point", "Policy", "PolicyParams", "PostControl", "Preprocess", "RenderFrame", "RenderedControl",
           "Roles", "SceneEdit", "SceneState", "Segmenter", "SpaceShape", "SpecPath", "Truth"]

# Lazy exports (PEP 562): a name's module is imported when first used, so importing this package
# stays light and free of cycles.
from typing import TYPE_CHECKING as _TYPE_CHECKING  # noqa: E402

from sweep3d.core import exports as _exports  # noqa: E402

if _TYPE_CHECKING:
    from sweep3d.core import ControlParams, SpecPath
    from sweep3d.export import DatasetWriter
    from sweep3d.spec import Point, SpaceShape
    from sweep3d.stages.infer import (
        Classifier,
        Detector,
        Evaluator,
        EvaluatorParams,
        Normalize,
        Preprocess,
        Roles,
        Segmenter,
        Truth,
    )
    from sweep3d.stages.plan import Outcome, Policy, PolicyParams
    from sweep3d.stages.postprocess import PostControl, RenderFrame
    from sweep3d.stages.render import RenderedControl, SceneEdit, SceneState

__getattr__, __dir__ = _exports(__name__, {
    'Classifier': ('sweep3d.stages.infer', 'Classifier'),
    'ControlParams': ('sweep3d.core.control', 'ControlParams'),
    'DatasetWriter': ('sweep3d.export.formats', 'DatasetWriter'),
    'Detector': ('sweep3d.stages.infer', 'Detector'),
    'Evaluator': ('sweep3d.stages.infer', 'Evaluator'),
    'EvaluatorParams': ('sweep3d.stages.infer', 'EvaluatorParams'),
    'Normalize': ('sweep3d.stages.infer', 'Normalize'),
    'Outcome': ('sweep3d.stages.plan.policies', 'Outcome'),
    'Point': ('sweep3d.spec.space', 'Point'),
    'Policy': ('sweep3d.stages.plan.policies', 'Policy'),
    'PolicyParams': ('sweep3d.stages.plan.policies', 'PolicyParams'),
    'PostControl': ('sweep3d.stages.postprocess', 'PostControl'),
    'Preprocess': ('sweep3d.stages.infer', 'Preprocess'),
    'RenderFrame': ('sweep3d.stages.postprocess.frame', 'RenderFrame'),
    'RenderedControl': ('sweep3d.stages.render.controls', 'RenderedControl'),
    'Roles': ('sweep3d.stages.infer', 'Roles'),
    'SceneEdit': ('sweep3d.stages.render.cycles.scene_edit', 'SceneEdit'),
    'SceneState': ('sweep3d.stages.render.state', 'SceneState'),
    'Segmenter': ('sweep3d.stages.infer', 'Segmenter'),
    'SpaceShape': ('sweep3d.spec.space', 'SpaceShape'),
    'SpecPath': ('sweep3d.core.control', 'SpecPath'),
    'Truth': ('sweep3d.stages.infer.evaluators', 'Truth'),
})
