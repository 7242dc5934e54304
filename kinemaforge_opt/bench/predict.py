"""Held-out prediction for the baselines: the nominal model (optionally with its inertia scaled)
plus a fitted passive force law, simulated from the first state of a recording under its recorded
forcing — the same protocol as :func:`kinemaforge_opt.physics.diagnose.diagnose` uses."""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..calibration import apply_parameters
from ..model.articulated import ArticulatedModel
from ..physics.predict import simulate_recording as predict  # noqa: F401  (the shared protocol)

ForceLaw = Callable[[float, float], float]


def augmented(model: ArticulatedModel, inertia_ratio: dict[str, float]) -> ArticulatedModel:
    """``model`` with the child link of each joint in ``inertia_ratio`` scaled by its ratio."""
    values = {f"{model.joint(j).child}.inertia_ratio": np.array([r]) for j, r in inertia_ratio.items()}
    return apply_parameters(model, values)


