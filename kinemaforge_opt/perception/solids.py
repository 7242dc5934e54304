"""A moving part's solid over the whole recording: the points it ever showed, moved with the fitted
joints, claim what lies inside them at every step.

A drawer's interior floor is seen only while the drawer is open; where the drawer then rests, the
floor's readings stop changing, the free-space test calls them static and the labels leave them
BASE (10–12 % of the open drawer's pixels at each open step of the held-out eval_drawer_0).  One
step's own part points do not enclose it either (only the walls' top edges are labelled toward
the back), but the union of the part's points over every step does: the front from the closed
steps, the walls and floor from the open ones.  Moved with the *fitted* joint motion (one rigid
motion per part, along a straight axis), the union does not smear the way the per-step tracks do
(a track that sags 1–3 cm swept the chest's hull over the body's rails; see docs/NOTES.md).

What the hull would take wrongly is the static body next to a part (rails, the carcass's edge):
such a place stays occupied at steps when the part has moved away from it, so a point whose place
is seen at half or more of the steps where it lies clearly outside the moved hull is left as it is.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from ..model import ArticulatedModel
from ..nlp.reconstruction import transforms_world0_t
from ..parallel import thread_map
from ..spatial import transform_points

# A candidate seen at this share (or more) of the steps where it lies clearly outside the moved
# hull is static body, not the part's inside.
STATIC_SHARE = 0.5


def part_motions(model: ArticulatedModel, q: np.ndarray) -> dict[str, np.ndarray]:
    """Moving link name -> (T, 4, 4) T_world_t · T_world_0⁻¹ (its motion from the zero
    configuration to each step) for joint values ``q`` (T, n) [rad or m] in the order of
    ``model.movable_joints``; NaN rows where a joint it hangs from is unknown."""
    return {j.child: transforms_world0_t(model, j.child, q) for j in model.movable_joints}


def fill_part_solids(points: list[np.ndarray], labels: list[np.ndarray], motions: dict[str, np.ndarray],
                     margin: float, base: str, trees: list[cKDTree] | None = None) -> list[np.ndarray]:
    """Per step, (M_t,) labels with the ``base`` points inside a moving part's solid given that
    part's name.

    points: per step (M_t, 3) fused points [m].  labels: per step (M_t,) part names.  motions: part
    name -> (T, 4, 4) motion from the zero configuration (:func:`part_motions`).  margin [m]: a
    point must lie deeper than this inside the hull (the cloud's voxel), and "clearly outside" is
    beyond it.  The solid is the convex hull of the part's points of every step with a finite
    motion, moved to the zero configuration; a point inside several solids takes the part whose
    hull point is nearest.  A candidate is refused when something is seen at its place (within
    ``margin``) at ≥ :data:`STATIC_SHARE` of the steps where the moved solid is clearly elsewhere.
    trees: per step the KD-tree of ``points``, when already built."""
    if len(labels) != len(points):
        raise ValueError(f"labels has {len(labels)} steps, points {len(points)}")
    for part, T in motions.items():
        if np.shape(T) != (len(points), 4, 4):
            raise ValueError(f"motion of part {part!r} has shape {np.shape(T)}; expected ({len(points)}, 4, 4), "
                             "one pose per step of points")
    trees = thread_map(cKDTree, points) if trees is None else trees
    out = [lab.copy() for lab in labels]
    nearest = [np.full(len(lab), np.inf) for lab in labels]
    for part, T in sorted(motions.items()):
        valid = np.flatnonzero(np.isfinite(T).all(axis=(1, 2)))
        T_inv = {s: np.linalg.inv(T[s]) for s in valid}
        union = np.concatenate([transform_points(T_inv[s], points[s][labels[s] == part]) for s in valid] or [np.empty((0, 3))])
        try:
            faces = ConvexHull(union).equations  # (F, 4): outward unit normal, offset
        except (QhullError, ValueError):  # too few or coplanar points: no volume to fill
            continue
        union_tree = cKDTree(union)

        def depth_outside(x: np.ndarray, s: int) -> np.ndarray:
            """(N,) largest face distance of world points x at step s (< 0 inside the solid)."""
            return (transform_points(T_inv[s], x) @ faces[:, :3].T + faces[:, 3]).max(axis=1)

        def fill_step(s: int) -> None:
            """This part's solid at step s: writes out[s] and nearest[s] only, so steps run in parallel."""
            cand = np.flatnonzero(labels[s] == base)
            cand = cand[depth_outside(points[s][cand], s) < -margin]
            if not cand.size:
                return
            x = points[s][cand]
            outside_steps, seen_steps = np.zeros(cand.size), np.zeros(cand.size)
            for k in valid:
                if k == s:
                    continue
                away = depth_outside(x, k) > margin
                outside_steps += away
                seen_steps += away & np.isfinite(trees[k].query(x, distance_upper_bound=margin)[0])
            cand = cand[(outside_steps == 0) | (seen_steps < STATIC_SHARE * outside_steps)]
            d = union_tree.query(transform_points(T_inv[s], points[s][cand]))[0]
            take = d < nearest[s][cand]
            out[s][cand[take]] = part
            nearest[s][cand[take]] = d[take]

        thread_map(fill_step, valid)
    return out
