"""Perception: depth -> world point clouds -> moving/static points -> part proposals -> SE(3) tracks.

``perceive(seq)`` runs the stages on a loaded sequence and returns a :class:`Perception` whose
``tracks`` feed ``graph.infer_tree``; ``reconstruct_sequence(SEQ, OUT)`` is the whole RGB-D flow
(URDF, meshes, reconstruction.json, clouds.npz).  Modules: ``clouds`` (back-projection, noise,
fusion), ``change`` (free-space tests; per-pixel status for static cameras), ``segment``
(DBSCAN proposals, environment planes), ``track`` (KD-tree ICP tracking, growth, merging), ``perceive`` (the stages in order),
``resegment`` (motion-consistent per-point split of tracked proposals), ``surface`` (meshes, mass),
``solids`` (each part's solid over its fitted motion claims its inside), ``reconstruct`` (the flow).
"""

from .change import MOVING, STATIC, UNKNOWN, free_space_test, motion_status
from .clouds import DepthNoise, FrameCloud, TimeCloud, backproject, estimate_depth_noise
from .perceive import Perception, perceive
from .reconstruct import BASE, ENVIRONMENT, Reconstruction, pixel_labels, reconstruct_sequence
from .track import Proposal, Tracker

__all__ = [
    "BASE", "ENVIRONMENT", "MOVING", "STATIC", "UNKNOWN", "DepthNoise", "FrameCloud", "Perception",
    "Proposal", "Reconstruction", "TimeCloud", "Tracker", "backproject", "estimate_depth_noise",
    "free_space_test", "motion_status", "perceive", "pixel_labels", "reconstruct_sequence",
]
