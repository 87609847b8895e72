"""Everything a user's plug-in subclasses or returns, from one module.

Controls (rendered: set the :class:`SceneState` Blender draws and/or edit the live scene through a
:class:`SceneEdit`; post: map one image to another),
policies (turn a :class:`SpaceShape` into :class:`Point` objects), models (a factory returning a
:class:`Classifier`, :class:`Detector` or :class:`Segmenter`, with its :class:`Preprocess`) and
evaluators. None of these imports torch or bpy: a model's factory imports torch itself.
"""

from sweep3d.controls import ControlParams, SpecPath
from sweep3d.spec.space import Point, SpaceShape
from sweep3d.stages.infer import (
    Classifier,
    Detector,
    Evaluator,
    EvaluatorParams,
    Normalize,
    Preprocess,
    Roles,
    Segmenter,
)
from sweep3d.stages.infer.evaluators import Truth
from sweep3d.stages.plan.policies import Outcome, Policy, PolicyParams
from sweep3d.stages.postprocess import PostControl
from sweep3d.stages.postprocess.frame import RenderFrame
from sweep3d.stages.render.controls import RenderedControl
from sweep3d.stages.render.scene_edit import SceneEdit
from sweep3d.stages.render.state import SceneState

__all__ = ["Classifier", "ControlParams", "Detector", "Evaluator", "EvaluatorParams", "Normalize", "Outcome", "Point",
           "Policy", "PolicyParams", "PostControl", "Preprocess", "RenderFrame", "RenderedControl", "Roles", "SceneEdit", "SceneState",
           "Segmenter", "SpaceShape", "SpecPath", "Truth"]
