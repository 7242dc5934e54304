"""The synthetic world: procedural articulated objects, independent ground-truth physics in
MuJoCo with concealed effects, ray-cast RGB-D rendering with a D435-like sensor model, and the
generation of benchmark cases (catalogue in ``problems/``).

Modules: ``objects`` (generators), ``meshes`` (mesh blocks, inertia from volume × density),
``effects`` (concealed effects), ``groundtruth`` (MJCF + hand-driven episodes), ``render``
(RaycastingScene), ``sensor`` (noise), ``case`` (the Case record), ``generate`` (writes a case).
"""

from .case import Case
from .effects import EFFECT_TYPES, ConcealedEffect, true_model
from .generate import CasePaths, generate_case
from .groundtruth import Episode, HandPlan, simulate
from .objects import GENERATORS, SynthObject, make_object
from .sensor import CLEAN, D435, SensorModel

__all__ = [
    "CLEAN",
    "D435",
    "EFFECT_TYPES",
    "GENERATORS",
    "Case",
    "CasePaths",
    "ConcealedEffect",
    "Episode",
    "HandPlan",
    "SensorModel",
    "SynthObject",
    "generate_case",
    "make_object",
    "simulate",
    "true_model",
]
