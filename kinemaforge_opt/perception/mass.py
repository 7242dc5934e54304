"""Mass properties of a reconstructed part that a contaminated cloud cannot blow up.

A part's fused cloud is its labelled points of every time step moved into its link frame.  When
the labelling takes in background (a floor patch, a wall, the carcass seen through an open door)
the convex hull of that cloud is a volume of air: on protocol_cabinet_0 (160×120, 4 views) more
than half of a door's points were floor and the hull at 300 kg/m³ weighed 112–130 kg for a true
4.2 kg door (inertia about the hinge 85× too large).  Two independent tests keep the points that
belong to the moving part:

1. **Motion consistency** (:func:`moving_point_masks`): a point of the part at step s, looked at
   in another step s' where the part's motion moved it by more than ``2 r``, has left its world
   position: the cloud of s' has nothing within ``r`` of it (its surface went elsewhere).  A
   background point stays where it was: the cloud of s' still has a point there.  A point whose
   world position stays occupied in at least half of its informative steps is background.  Points
   that never move by ``2 r`` (on the joint axis, or a part that never moves) are uninformative and
   kept.  Limitation: a part surface that slides within its own plane (a drawer's side wall)
   stays occupied too and is dropped — mass is then under-, never over-estimated.
2. **Trimming**: the points outside the 1–99 % quantiles along each principal axis go (a hull is
   an extreme value: a few per cent of leftover background set it).
3. **Statistical outlier removal** (open3d): stray points far from their neighbours.

The mass model is the convex hull of the kept points at the density — the same model as the
mesh, so a clean cloud gives the same answer as before.  A hull that spans no volume (a single
flat face) is given the thickness of one voxel (the resolution of the fused points).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh
from scipy.spatial import cKDTree

from ..errors import DataError
from ..parallel import thread_map

# Informative steps compared per step (evenly spread); more costs time and changes little.
MAX_COMPARED_STEPS = 8
# Statistical outlier removal: neighbours and the multiple of the neighbour-distance spread.
SOR_NEIGHBOURS, SOR_STD_RATIO = 20, 2.0
# Share of points cut at each end of each principal axis before the hull: a hull is an extreme
# value, so a few background points left by the motion test (on protocol_cabinet_1 a floor
# patch at the hinge's foot, 5 % of the kept points) set it (119 kg for an 8.8 kg door; cut at
# 1 %: 18 kg).  A clean cloud loses ~2 % of each extent.
TRIM_QUANTILE = 0.01
# Most points of a part's fused cloud its mass properties use: the same seeded share of every
# step's points.  30 steps at 640x480 fuse ~5e5 on a cabinet door, and the motion test and the
# outlier removal, 3 s of the model stage there, scale with the count.  The trim is unbiased
# under the subsample; the outlier removal drops fewer of a thin part's noise points on the
# sparser cloud (a cabinet door 1 % heavier, a laptop lid 10 %), and the mass no longer grows
# lighter with the episode's length once above the budget.
MASS_POINT_BUDGET = 100_000


@dataclass(frozen=True)
class MassProperties:
    """mass [kg], com (3,) [m] and inertia (3, 3) about the com [kg m²] in the link frame;
    kept / total: points used of the part's fused cloud; method: "hull" or "slab"."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    kept: int
    total: int
    method: str


def moving_point_masks(points_world: list[np.ndarray], clouds_world: list[np.ndarray | cKDTree],
                       Ts_world_part: list[np.ndarray | None], radius: float) -> list[np.ndarray]:
    """Per time step, a (M_s,) bool mask of the part's points that behave like the part.

    points_world: per step s the part's labelled points (M_s, 3) in the world [m].  clouds_world:
    per step the whole observed cloud (N_s, 3) [m], or its cKDTree when already built.
    Ts_world_part: per step the part pose (4, 4) or None where it is not tracked.  radius: the
    distance [m] within which a point lies on an observed surface (the ICP inlier distance).  See
    the module doc for the test."""
    T = len(points_world)
    if not (len(clouds_world) == len(Ts_world_part) == T):
        raise DataError(f"moving_point_masks: {T} point sets, {len(clouds_world)} clouds and "
                        f"{len(Ts_world_part)} poses; one of each per time step was expected")
    trees = thread_map(lambda c: c if isinstance(c, cKDTree) else cKDTree(c) if len(c) else None, clouds_world)

    def mask(s: int) -> np.ndarray:
        X = np.asarray(points_world[s], dtype=float).reshape(-1, 3)
        keep = np.ones(len(X), dtype=bool)
        if len(X) == 0 or Ts_world_part[s] is None:
            return keep
        others = [u for u in range(T) if u != s and Ts_world_part[u] is not None and trees[u] is not None]
        if len(others) > MAX_COMPARED_STEPS:
            others = [others[i] for i in np.linspace(0, len(others) - 1, MAX_COMPARED_STEPS).round().astype(int)]
        informative = np.zeros(len(X), dtype=int)
        occupied = np.zeros(len(X), dtype=int)
        T_s_inv = np.linalg.inv(Ts_world_part[s])
        for u in others:
            T_u_s = Ts_world_part[u] @ T_s_inv  # world at s -> world at u, rigidly with the part
            moved = X @ T_u_s[:3, :3].T + T_u_s[:3, 3]
            inf = np.linalg.norm(moved - X, axis=1) > 2 * radius
            if not inf.any():
                continue
            d = trees[u].query(X[inf], distance_upper_bound=radius)[0]
            informative[inf] += 1
            occupied[inf] += np.isfinite(d)
        return keep & ~((informative > 0) & (2 * occupied >= informative))

    return thread_map(mask, range(T))


def budget_subsample(points_per_step: list[np.ndarray], budget: int = MASS_POINT_BUDGET,
                     seed: int = 0) -> list[np.ndarray]:
    """The (M_s, 3) point sets with every set reduced to the same share of its points (seeded,
    without replacement) so that together they hold at most ``budget``; unchanged when they do."""
    total = sum(len(p) for p in points_per_step)
    if total <= budget:
        return points_per_step
    rng = np.random.default_rng(seed)
    share = budget / total
    return [p[np.sort(rng.choice(len(p), int(round(share * len(p))), replace=False))] for p in points_per_step]


def _trim(points: np.ndarray) -> np.ndarray:
    """The points inside the [TRIM_QUANTILE, 1 − TRIM_QUANTILE] quantiles along each principal axis."""
    if len(points) < 100:
        return points
    c = points - points.mean(axis=0)
    y = c @ np.linalg.svd(c, full_matrices=False)[2].T
    lo, hi = np.quantile(y, TRIM_QUANTILE, axis=0), np.quantile(y, 1 - TRIM_QUANTILE, axis=0)
    inside = np.all((y >= lo) & (y <= hi), axis=1)
    return points[inside] if inside.sum() >= 4 else points


def _sor(points: np.ndarray) -> np.ndarray:
    if len(points) <= SOR_NEIGHBOURS:
        return points
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    _, index = pc.remove_statistical_outlier(SOR_NEIGHBOURS, SOR_STD_RATIO)
    return points[np.asarray(index, dtype=int)] if len(index) >= 4 else points


def _slab(points: np.ndarray, density: float, thickness: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, com and inertia of the principal-axes box of ``points`` with its thinnest side at
    least ``thickness`` [m]."""
    com = points.mean(axis=0)
    _, _, Vt = np.linalg.svd(points - com, full_matrices=False)
    y = (points - com) @ Vt.T
    lo, hi = y.min(axis=0), y.max(axis=0)
    ext = np.maximum(hi - lo, thickness)
    centre = Vt.T @ ((lo + hi) / 2) + com
    m = float(density * np.prod(ext))
    a, b, c = ext
    I_box = m / 12 * np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    return m, centre, Vt.T @ I_box @ Vt


def part_mass_properties(points_link: np.ndarray, density: float, name: str, voxel: float,
                         keep: np.ndarray | None = None) -> MassProperties:
    """Mass properties of a part from its fused (N, 3) link-frame points [m] at ``density``
    [kg/m³]: the points ``keep`` (N,) selects (default all; see :func:`moving_point_masks`), trimmed
    (:data:`TRIM_QUANTILE`) and minus statistical outliers, as a convex hull (or, if that spans no volume, a box one ``voxel`` [m]
    thick).  Falls back to all points when fewer than 4 are kept."""
    pts = np.asarray(points_link, dtype=float).reshape(-1, 3)
    if len(pts) < 4:
        raise DataError(f"part {name!r} has {len(pts)} points; its mass properties need at least 4")
    sel = pts if keep is None or int(np.count_nonzero(keep)) < 4 else pts[np.asarray(keep, dtype=bool)]
    sel = _sor(_trim(sel))
    try:
        hull = trimesh.convex.convex_hull(sel)
        hull.density = float(density)
        thin = np.linalg.svd(sel - sel.mean(axis=0), compute_uv=False)[-1] / np.sqrt(len(sel))
        if not hull.is_volume or hull.volume <= 0 or thin < voxel / 4:
            raise ValueError("flat")
        I = np.asarray(hull.moment_inertia, dtype=float)
        return MassProperties(float(hull.mass), np.asarray(hull.center_mass, dtype=float), (I + I.T) / 2,
                              len(sel), len(pts), "hull")
    except Exception:  # qhull refuses flat sets; a near-flat hull has no meaningful volume
        m, com, I = _slab(sel, density, voxel)
        return MassProperties(m, com, (I + I.T) / 2, len(sel), len(pts), "slab")
