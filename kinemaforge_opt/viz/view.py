"""The scene ``kinemaforge view`` writes: clouds, the model, recorded vs simulated motion."""

from __future__ import annotations

import os
from collections.abc import Mapping

import numpy as np

from ..model import ArticulatedModel
from .scene import Scene

SIMULATED_COLOR = 0x9E9E9E


def build_view(
    model: ArticulatedModel,
    mesh_dir: str | os.PathLike | None = None,
    recorded: tuple[np.ndarray, np.ndarray] | None = None,
    simulated: tuple[np.ndarray, np.ndarray] | None = None,
    clouds: Mapping[str, np.ndarray] | None = None,
) -> Scene:
    """A scene with the point clouds (part -> (N, 3) [m]) and the model.

    recorded / simulated: (t (T,) [s], q (T, n)) motions.  Each given motion gets its own copy
    of the model (groups ``recorded`` and ``simulated``, the latter grey and half transparent)
    and one animation plays them together.  Without motions the model is shown at q = 0 in
    group ``model``."""
    scene = Scene()
    if clouds:
        scene.add_point_clouds(clouds)
    motions = {}
    if recorded is not None:
        motions["recorded"] = recorded
    if simulated is not None:
        motions["simulated"] = simulated
    if not motions:
        scene.add_model(model, "model", mesh_dir=mesh_dir)
        return scene
    for group, (_, q) in motions.items():
        grey = group == "simulated"
        scene.add_model(model, group, q=np.asarray(q)[0], mesh_dir=mesh_dir,
                        color=SIMULATED_COLOR if grey else None, opacity=0.5 if grey else 1.0)
    scene.animate(model, motions)
    return scene
