"""Pairwise joint-type fits, confidences and the kinematic tree (constraint graph + arborescence).

``infer_tree(tracks)`` is the entry point; ``fit_relation`` / ``fit_all`` fit one pair's relative
motion (``relative_motion``); ``score_pair`` turns fits into type probabilities.
"""

from .fit import JOINT_TYPES, JointHypothesis, fit_all, fit_relation
from .motion import WORLD, RelativeMotion, noise_sigma, relative_motion
from .score import score_pair
from .tree import GraphResult, KinematicTree, LooseTrack, TreeJoint, infer_tree

__all__ = [
    "JOINT_TYPES", "JointHypothesis", "fit_all", "fit_relation", "WORLD", "RelativeMotion",
    "noise_sigma", "relative_motion", "score_pair", "GraphResult", "KinematicTree", "LooseTrack", "TreeJoint",
    "infer_tree",
]
