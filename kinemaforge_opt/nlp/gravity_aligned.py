"""Gravity-aligned joint axes: the hypothesis that a joint's axis is plumb or level.

Furniture and appliances are built square to gravity: door and lid hinges are vertical or
horizontal, drawer slides level.  The screw NLP fits every axis freely, and a fit whose visual
term barely prefers a tilt of a few tenths of a degree leaves a model that is not in equilibrium
where the recording rests: a frictionless door on an axis tilted 0.2° swings to the lowest point
of its circle within the 50-s replay (protocol_refrigerator_1: 0.59 m of drift for the true
model's 0.05 m).

For every joint whose fitted axis lies within :data:`NEAR_DEG` of parallel or perpendicular to
gravity, the constrained fit (``aligned:<joint>`` linear constraints on its axis variable) is a
nested model with fewer parameters: two for a plumb axis (its direction is fixed), one for a
level one (its rise is fixed).  It is chosen by the Bayesian information criterion on the
screw NLP's terms (each ≈ ½ χ²): kept when Δχ² = 2 n (J_aligned − J_free) is at most k ln n, n
the number of visual residuals and k the parameters it saves.  The visual part of each J is
scored on the fit's own correspondences (refreshed under its motion until they settle, points
left out of the gates charged the loss at the gate; :func:`~.reconstruction.refine_screws`), so
that neither hypothesis is judged on pairs made under the other.  A tilt the data support (a
concealed axis tilt of a degree, a hinge mounted askew) costs far more than that and stays.
"""

from __future__ import annotations

import numpy as np

from ..model import ArticulatedModel
from ..spatial import tangent_basis

# Axes within this angle of plumb or level are tested (a larger tilt is a design, not an error).
NEAR_DEG = 3.0


def world_rotation(model: ArticulatedModel, joint_name: str) -> np.ndarray:
    """(3, 3) rotation of ``joint_name``'s frame in the world at the zero configuration (the root
    link's frame is the world)."""
    by_child = {j.child: j for j in model.joints}
    R = np.eye(3)
    j = model.joint(joint_name)
    while j is not None:
        R = j.T_parent_joint[:3, :3] @ R
        j = by_child.get(j.parent)
    return R


def alignment(model: ArticulatedModel, joint_name: str, axis: np.ndarray) -> str | None:
    """"plumb", "level" or None: whether the axis (3,) in the joint frame lies within NEAR_DEG of
    parallel or perpendicular to the model's gravity."""
    g = np.asarray(model.gravity, float)
    if not np.linalg.norm(g) > 0:
        return None
    a = world_rotation(model, joint_name) @ (axis / np.linalg.norm(axis))
    off_plumb = np.degrees(np.arccos(min(1.0, abs(a @ g) / np.linalg.norm(g))))
    if off_plumb <= NEAR_DEG:
        return "plumb"
    if abs(90.0 - off_plumb) <= NEAR_DEG:
        return "level"
    return None


def constraint_rows(model: ArticulatedModel, joint_name: str, kind: str) -> np.ndarray:
    """(k, 3) rows C with C · axis = 0 (axis in the joint frame) for ``kind`` "plumb" (k = 2: the
    axis has no horizontal component) or "level" (k = 1: it has no vertical one)."""
    R = world_rotation(model, joint_name)
    up = -np.asarray(model.gravity, float)
    up = R.T @ (up / np.linalg.norm(up))
    return up[None, :] if kind == "level" else tangent_basis(up).T


def project(axis: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The unit axis nearest ``axis`` (3,) that satisfies rows · axis = 0."""
    a = axis - rows.T @ np.linalg.lstsq(rows.T, axis, rcond=None)[0]
    return a / np.linalg.norm(a)


def bic_test(j_free: float, j_aligned: float, n: int, k: int) -> tuple[float, float]:
    """(Δχ², bound) of the BIC test: Δχ² = 2 n (j_aligned − j_free) of the aligned fit (k fewer
    parameters) against the free one, bound = k ln n; objectives normalised by n as the screw
    NLP's are (each term ≈ ½ χ² / n)."""
    return 2.0 * n * (j_aligned - j_free), k * float(np.log(max(n, 2)))


def prefer_aligned(j_free: float, j_aligned: float, n: int, k: int) -> bool:
    """BIC: the aligned fit is preferred when its Δχ² is at most the bound (:func:`bic_test`)."""
    dchi2, bound = bic_test(j_free, j_aligned, n, k)
    return bool(dchi2 <= bound)
