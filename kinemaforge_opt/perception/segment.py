"""Over-segmentation of moving points into candidate rigid parts, and the environment planes.

Proposals: the moving points of one time step are clustered by Euclidean connectivity (open3d
DBSCAN, ε = CLUSTER_VOXELS voxels: points on one surface are about a voxel apart, separate
parts are separated by a gap or by a static region).  More proposals than true parts is fine:
the constraint graph merges proposals that move rigidly together.

Environment: among the static points, large planes that have (nearly) the whole scene on one
side — the floor under an object, the wall behind it — are background, not part of the base
link (their convex hull would be a slab of floor).  RANSAC with open3d ``segment_plane``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

CLUSTER_VOXELS = 2.0
# Smallest cluster kept as a proposal: a rigid SE(3) fit needs a few dozen points to be
# overdetermined against depth noise (6 unknowns, 1 constraint per point-to-plane pair).
MIN_PROPOSAL_POINTS = 20
# A plane is a candidate environment surface if it holds at least this share of the static
# points, and is background if at most OUTSIDE_SHARE of all other points lie behind it.
PLANE_MIN_SHARE = 0.05
OUTSIDE_SHARE = 0.01
MAX_PLANES = 4
RANSAC_ITERATIONS = 1000
# RANSAC and the one-side test use a random subset of at most this many points (a plane holding
# 5 % of them still has 250 inliers).
RANSAC_MAX_POINTS = 5000


def clusters(points: np.ndarray, voxel: float, min_points: int = MIN_PROPOSAL_POINTS) -> list[np.ndarray]:
    """Indices of each DBSCAN cluster of (N, 3) points [m] with at least ``min_points``
    members, largest first."""
    if len(points) < max(min_points, 1):
        return []
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    labels = np.asarray(pcd.cluster_dbscan(eps=CLUSTER_VOXELS * voxel, min_points=4))
    out = [np.flatnonzero(labels == k) for k in range(labels.max() + 1)]
    return sorted((c for c in out if len(c) >= min_points), key=len, reverse=True)


@dataclass(frozen=True)
class Plane:
    """n·p + d = 0 with unit normal n (3,) pointing to the scene side; d [m]."""

    normal: np.ndarray
    offset: float

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed distances [m] of (N, 3) points (positive on the scene side)."""
        return points @ self.normal + self.offset


def environment_planes(static_points: np.ndarray, all_points: np.ndarray, threshold: float,
                       seed: int = 0) -> list[Plane]:
    """Background planes among (N, 3) static points [m] (module doc); ``all_points`` (M, 3) is
    the whole scene used for the one-side test; ``threshold`` [m] the inlier distance."""
    o3d.utility.random.seed(seed)
    rng = np.random.default_rng(seed)
    if len(static_points) > RANSAC_MAX_POINTS:
        static_points = static_points[rng.choice(len(static_points), RANSAC_MAX_POINTS, replace=False)]
    if len(all_points) > RANSAC_MAX_POINTS:
        all_points = all_points[rng.choice(len(all_points), RANSAC_MAX_POINTS, replace=False)]
    pool = static_points
    planes = []
    for _ in range(MAX_PLANES):
        if len(pool) < max(3, PLANE_MIN_SHARE * len(static_points)):
            break
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pool))
        (a, b, c, d), inliers = pcd.segment_plane(threshold, 3, RANSAC_ITERATIONS)
        if len(inliers) < PLANE_MIN_SHARE * len(static_points):
            break
        n = np.array([a, b, c])
        plane = Plane(n / np.linalg.norm(n), d / np.linalg.norm(n))
        dist = plane.distance(all_points)
        off = np.abs(dist) > threshold
        if np.mean(dist[off] < 0) > 0.5:
            plane = Plane(-plane.normal, -plane.offset)
            dist = -dist
        if off.any() and np.mean(dist[off] < 0) <= OUTSIDE_SHARE:
            planes.append(plane)
        pool = np.delete(pool, inliers, axis=0)
    return planes
