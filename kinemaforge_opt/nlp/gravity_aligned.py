"""Gravity-aligned joint axes: the hypothesis that a joint's axis is plumb, level, or square to its
parent.

Furniture and appliances are built square to gravity: door and lid hinges are vertical or
horizontal, drawer slides level.  They are built square to themselves too: a drawer slides
straight out of its carcass.  The screw NLP fits every axis freely, and a fit whose visual
term barely prefers a tilt of a few tenths of a degree leaves a model that is not in equilibrium
where the recording rests: a frictionless door on an axis tilted 0.2° swings to the lowest point
of its circle within the 50-s replay (protocol_refrigerator_1: 0.59 m of drift for the true
model's 0.05 m).  And a drawer's front moving along its own normal leaves the slide's heading
(its yaw about the vertical) to the few points on its edges: the free fit of a chest's drawer
kept 3.9° of the closed form's heading error.

For every joint whose fitted axis lies within :data:`NEAR_DEG` of parallel or perpendicular to
gravity, the constrained fit (``aligned:<joint>`` linear constraints on its axis variable) is a
nested model with fewer parameters: two for a plumb axis (its direction is fixed), one for a
level one (its rise is fixed).  A level slide within :data:`SQUARE_NEAR_DEG` of a horizontal
face direction of its parent part (:func:`face_directions`, measured on the parent's own points)
is first tested "square": its direction fixed to that face direction, two parameters
(:func:`square_direction`); refused, it is tested level.  Each hypothesis is judged by the
Bayesian information criterion on the screw NLP's terms (each ≈ ½ χ²), Δχ² = 2 n (J_aligned −
J_free) against k ln n (n the number of visual residuals, k the parameters it saves), and by
Vuong's test of how far beyond that bound Δχ² lies against its own spread over the time steps
(:func:`alignment_test`): the aligned fit, the simpler one, is kept unless the free one is better
beyond both.  The visual part of each J is scored on the fit's own correspondences (refreshed
under its motion until they settle, points left out of the gates charged the loss at the gate;
:func:`~.reconstruction.refine_screws`), so that neither hypothesis is judged on pairs made
under the other.  A tilt the data support (a concealed axis tilt of a degree over a handful of
steps, a hinge mounted askew) costs far more than that and stays; on eight steps of a door seen
with 3 mm noise, a tilt of half a degree does not (Δχ² 22.5 against 14.8, z 0.64 against 1.89).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import stdtrit  # the inverse of Student t's CDF (scipy.stats costs 0.3 s to import)

from ..model import ArticulatedModel
from ..spatial import tangent_basis

# Axes within this angle of plumb or level are tested (a larger tilt is a design, not an error).
NEAR_DEG = 3.0
# Normals within this angle of horizontal vote for a part's face directions (a box's side faces;
# its top and bottom, and the noisy normals along its edges, do not).
FACE_VOTE_DEG = 30.0
# A part's horizontal normals name its face directions when their four-fold circular mean has at
# least this resultant length (1: every vote on a box's four sides; a cylinder's about 0).
MIN_SQUARENESS = 0.5
# The directions are the mean again over the votes within this angle of the first mean's square.
FACE_INLIER_DEG = 5.0
# A level slide within this angle of a face direction of its parent is tested square.  Wider than
# NEAR_DEG: the visual term hardly corrects a slide's heading, so the free fit's is about as far
# off as the closed form's (perception's track directions, up to 3.8° on held-out chests; 4.5°
# after the NLP on protocol_drawer_1@s1); a slide built that far askew is a design, and the BIC
# keeps its heading where the points show it.
SQUARE_NEAR_DEG = 10.0


def face_directions(normals: np.ndarray, gravity: np.ndarray) -> np.ndarray | None:
    """(2, 3) the two horizontal directions [world, unit] a part's side faces look along, from its
    surface normals (K, 3) [unit, any sign], or None when its horizontal normals do not agree on
    a square (:data:`MIN_SQUARENESS`) or there is no gravity.

    Each normal within FACE_VOTE_DEG of horizontal votes with its heading φ about the vertical,
    weighted by its horizontal length squared; four-fold (e^{4iφ}) so that a box's four sides and
    either sign of a normal vote alike.  The mean heading φ₀ = arg(Σ w e^{4iφ}) / 4 and φ₀ + 90°
    are the directions."""
    g = np.asarray(gravity, float)
    if not np.linalg.norm(g) > 0:
        return None
    up = -g / np.linalg.norm(g)
    n = np.asarray(normals, float)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    e1, e2 = tangent_basis(up).T
    x, y = n @ e1, n @ e2
    w = x**2 + y**2
    vote = w >= np.cos(np.radians(FACE_VOTE_DEG)) ** 2
    if not vote.any():
        return None
    w, e4 = w[vote], np.exp(4j * np.arctan2(y[vote], x[vote]))
    z = np.sum(w * e4) / np.sum(w)
    if abs(z) < MIN_SQUARENESS:
        return None
    # again over the votes within FACE_INLIER_DEG of that square (edges, handles and the insides
    # of openings lean the first mean)
    inlier = np.real(e4 * np.conj(z / abs(z))) >= np.cos(np.radians(4.0 * FACE_INLIER_DEG))
    phi = np.angle(np.sum(w[inlier] * e4[inlier])) / 4.0
    return np.stack([np.cos(phi) * e1 + np.sin(phi) * e2, -np.sin(phi) * e1 + np.cos(phi) * e2])


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


def square_direction(model: ArticulatedModel, joint_name: str, axis: np.ndarray,
                     faces: np.ndarray | None) -> np.ndarray | None:
    """The face direction (3,) [world, unit, signed as the axis] of ``faces`` (2, 3) (the joint's
    parent part's, :func:`face_directions`) within SQUARE_NEAR_DEG of the level axis (3,) in the
    joint frame of a prismatic joint, or None (no faces, not prismatic, the axis not level, or no
    face direction near it).  Only slides: their heading is what point-to-plane pairs see least (a
    face moving along its normal or within its plane), while a hinge's turning part shows its
    axis better than the parent's faces do (on Table 1's laptops the square hinge was kept by
    the BIC 0.04–0.17° off the truth, the free one 0.006–0.04°)."""
    if faces is None or model.joint(joint_name).type != "prismatic" or alignment(model, joint_name, axis) != "level":
        return None
    a = world_rotation(model, joint_name) @ (axis / np.linalg.norm(axis))
    cosines = np.asarray(faces, float) @ a
    k = int(np.argmax(np.abs(cosines)))
    if np.degrees(np.arccos(min(1.0, abs(cosines[k])))) > SQUARE_NEAR_DEG:
        return None
    return np.sign(cosines[k]) * np.asarray(faces[k], float)


def constraint_rows(model: ArticulatedModel, joint_name: str, kind: str,
                    direction: np.ndarray | None = None) -> np.ndarray:
    """(k, 3) rows C with C · axis = 0 (axis in the joint frame) for ``kind`` "plumb" (k = 2: the
    axis has no horizontal component), "level" (k = 1: it has no vertical one) or "square" (k = 2:
    it lies along ``direction`` (3,), a world direction from :func:`square_direction`)."""
    R = world_rotation(model, joint_name)
    if kind == "square":
        d = R.T @ (np.asarray(direction, float) / np.linalg.norm(direction))
        return tangent_basis(d).T
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


# Vuong's test at the conventional 5 % level, one-sided (only "the free fit is better" refuses the
# aligned one), against Student's t with F − 1 degrees of freedom
VUONG_LEVEL = 0.05


@dataclass(frozen=True)
class AlignmentTest:
    """The verdict on an aligned hypothesis.  dchi2, bound: the BIC test (:func:`bic_test`);
    z: Vuong's statistic (Δχ² − bound) / ω̂ with ω̂ the spread of Δχ² estimated from its
    per-step contributions, and critical its one-sided :data:`VUONG_LEVEL` quantile (both None
    when the steps cannot estimate ω̂).

    Why not the BIC alone: Δχ² is a difference of two separately settled fits, each on pairs
    refreshed under its own motion, so it is much noisier than the χ²_k of a likelihood ratio
    (on aligned truths it spread −76 … +52 against bounds of ~16, docs/NOTES.md).  Vuong (1989,
    "Likelihood ratio tests for model selection and non-nested hypotheses", Econometrica 57)
    measures that noise from the per-observation differences themselves; the time steps are the
    observations here, since a step's points and its stretch of dynamics share that step's pose
    and pairing.  The aligned fit, the simpler one, is kept unless the free fit is better beyond
    both the penalty and that noise.  (The graph's choice between non-nested parent fits uses the
    same statistic on its samples, :func:`~kinemaforge_opt.graph.score.closeness_z`.)"""

    dchi2: float
    bound: float
    z: float | None = None
    critical: float | None = None

    @property
    def kept(self) -> bool:
        return bool(self.dchi2 <= self.bound or (self.z is not None and self.z <= self.critical))

    def describe(self) -> str:
        vuong = "" if self.z is None else f", Vuong z {self.z:.2f} vs {self.critical:.2f}"
        return f"Δχ² {self.dchi2:.1f} vs {self.bound:.1f}{vuong}"


def step_shares(free: np.ndarray, aligned: np.ndarray) -> np.ndarray:
    """Each time step's share of Δχ² (χ² units) from the two fits' per-step scores ``free`` and
    ``aligned`` (T,) (½ χ² units), over the steps where either fit has anything to score: a step
    where no part is seen and no dynamics run is no observation of either hypothesis."""
    free, aligned = np.asarray(free, float), np.asarray(aligned, float)
    scored = (free != 0.0) | (aligned != 0.0)
    return 2.0 * (aligned - free)[scored]


def alignment_test(j_free: float, j_aligned: float, n: int, k: int,
                   per_step: np.ndarray | None = None) -> AlignmentTest:
    """The BIC test of the aligned fit (k fewer parameters, objectives as in :func:`bic_test`)
    with Vuong's test beside it.  per_step (F,): each time step's share of Δχ² (the aligned fit's
    per-step score minus the free fit's, χ² units); what is left of Δχ² (priors, terms of the
    whole recording) counts in the mean only.  ω̂² = F/(F−1) Σ (d_f − d̄)² is the spread of Δχ²
    over F independent steps."""
    dchi2, bound = bic_test(j_free, j_aligned, n, k)
    d = None if per_step is None else np.asarray(per_step, float)
    if d is None or d.size < 3:
        return AlignmentTest(dchi2, bound)
    spread = float(np.sqrt(d.size / (d.size - 1) * np.sum((d - d.mean()) ** 2)))
    if not spread > 0.0:
        return AlignmentTest(dchi2, bound)
    critical = float(stdtrit(d.size - 1, 1.0 - VUONG_LEVEL))
    return AlignmentTest(dchi2, bound, (dchi2 - bound) / spread, critical)
