"""Everything a user's plug-in subclasses or returns, from one module.

Controls (rendered: edit the :class:`SceneState` Blender draws; post: map one image to another),
policies (turn a :class:`SpaceShape` into :class:`Point` objects), models (a factory returning a
:class:`Classifier`, :class:`Detector` or :class:`Segmenter`, with its :class:`Preprocess`) and
evaluators. None of these imports torch or bpy: a model's factory imports torch itself.
"""

from sweep3d.controls import ControlParams, SpecPath
from sweep3d.spec.space import Point, SpaceShape
from sweep3d.stages.infer import Classifier, Detector, Evaluator, Normalize, Preprocess, Segmenter
from sweep3d.stages.plan.policies import Outcome, Policy, PolicyParams
from sweep3d.stages.postprocess import PostControl
from sweep3d.stages.render.controls import RenderedControl
from sweep3d.stages.render.state import SceneState

__all__ = ["Classifier", "ControlParams", "Detector", "Evaluator", "Normalize", "Outcome", "Point", "Policy",
           "PolicyParams", "PostControl", "Preprocess", "RenderedControl", "SceneState", "Segmenter", "SpaceShape",
           "SpecPath"]
