"""The visual term of the screw-axis solver: observed points against each part's surface model
moved by forward kinematics — a differentiable stand-in for rendering the model's depth.

Surface model of a part: (K, 3) points and unit normals on the part at the *zero
configuration* (q = 0), world frame.  At time step t the part's link has moved by

    T_world0_t(q_t, θ) = T_world_link(q_t, θ) · T_world_link(0, θ)⁻¹        (4, 4)

(both from the bridge's ``link_poses``, so the choice of link frame cancels and the surface does
not move when the NLP moves a joint's origin at q = 0).  An observed point y (world, time t)
corresponding to the surface point x with normal n gives the point-to-plane residual

    r = (R n) · (R x + p − y) = n · (x + Rᵀ (p − y)),        T_world0_t = [R p; 0 1],

and the term is Σ ρ_δ(r) with ρ_δ the pseudo-Huber loss δ² (√(1 + (r/δ)²) − 1) (quadratic below δ,
linear above, smooth everywhere).

Inside one solve the robust loss is replaced by its iteratively-reweighted quadratic (IRLS):
weights w = ρ'(r)/r = 1/√(1 + (r/δ)²) taken at the motion the correspondences were found under,
so Σ w r²/2.  The residual is linear in z = [vec(Rᵀ); Rᵀp; 1] (13,): r = aᵀz with
a = [−vec(n yᵀ); n; n·x], hence Σ w r² = zᵀ H z with the (13, 13) moment matrix H = Σ w a aᵀ,
precomputed per part and time step — the NLP's cost per step no longer grows with the number
of points.  Refreshing correspondences between coarse-to-fine stages refreshes the weights.

Correspondences (which surface point each observed point is compared with) are found by a
nearest-neighbour search in the zero configuration and held fixed during one solve; the
coarse-to-fine loop refreshes them between solves, as ICP does.  Every function here accepts
numpy arrays; :func:`point_to_plane` and :func:`pseudo_huber` accept casadi symbols too.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from ..errors import DataError


@dataclass(frozen=True, eq=False)
class SurfaceModel:
    """A part's surface at the zero configuration: points (K, 3) [m] and unit normals (K, 3),
    world frame.  oriented: the normals point out of the part, towards the cameras that saw the
    points (else their sign is arbitrary and no far-side test applies)."""

    name: str
    points: np.ndarray
    normals: np.ndarray
    oriented: bool = False

    @functools.cached_property
    def tree(self) -> cKDTree:
        """Nearest-neighbour index of ``points`` (built once)."""
        return cKDTree(self.points)


def surface_model(points_world0: np.ndarray, spacing: float, name: str, max_points: int = 4000,
                  sightlines: np.ndarray | None = None) -> SurfaceModel:
    """Surface model of a part from its fused points at the zero configuration (N, 3) [m]:
    voxel-downsampled to ``spacing`` [m] (coarser if more than ``max_points`` remain), normals
    from local plane fits (open3d, 20 neighbours within 4 spacings), oriented towards the
    points' ``sightlines`` (N, 3) (unit vectors towards the cameras that saw them) when given.
    Raises DataError naming the part if fewer than 10 points remain."""
    pts = np.asarray(points_world0, dtype=float)
    if len(pts) < 10:
        raise DataError(f"part {name!r}: {len(pts)} points; a surface model needs at least 10")
    # the perception's voxel grid (cells at multiples of the edge, points in input order), not
    # open3d's (anchored at the cloud's per-axis minimum, in hash order): the same scene in a
    # world with permuted axes then gets the same surface model, turned
    from ..perception.clouds import downsample

    cols = pts if sightlines is None else np.hstack([pts, np.asarray(sightlines, dtype=float)])
    voxel = spacing
    down_cols = downsample(cols, voxel)
    while len(down_cols) > max_points:
        voxel *= 1.3
        down_cols = downsample(cols, voxel)
    if len(down_cols) < 10:
        raise DataError(f"part {name!r}: {len(down_cols)} points after downsampling to {voxel:.3g} m; need at least 10")
    down = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(down_cols[:, :3]))
    if sightlines is not None:
        # open3d orients the normals it estimates along the ones a cloud already has: the
        # sightlines, averaged over each voxel, ride along as normals
        down.normals = o3d.utility.Vector3dVector(down_cols[:, 3:])
    down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * voxel, max_nn=20))
    normals = np.asarray(down.normals, dtype=float)
    return SurfaceModel(name, np.asarray(down.points, dtype=float), normals / np.linalg.norm(normals, axis=1, keepdims=True),
                        oriented=sightlines is not None)


def pseudo_huber(r, delta: float):
    """δ² (√(1 + (r/δ)²) − 1): ≈ r²/2 for |r| ≪ δ, ≈ δ|r| for |r| ≫ δ (numpy or casadi)."""
    if isinstance(r, (ca.SX, ca.MX, ca.DM)):
        return delta**2 * (ca.sqrt(1 + (r / delta) ** 2) - 1)
    return delta**2 * (np.sqrt(1 + (np.asarray(r) / delta) ** 2) - 1)


def point_to_plane(T_world0_t, x0, n0, y):
    """Residuals (N,) [m] of observed points ``y`` (3, N) against surface points ``x0`` (3, N) with
    normals ``n0`` (3, N), both at the zero configuration, after the part moved by ``T_world0_t``
    (4, 4).  Column-major point blocks so that casadi symbols and numpy arrays both work."""
    R, p = T_world0_t[:3, :3], T_world0_t[:3, 3]
    if isinstance(T_world0_t, (ca.SX, ca.MX)):
        back = ca.mtimes(R.T, ca.repmat(p, 1, y.shape[1]) - y)
        return ca.sum1(n0 * (x0 + back)).T
    back = np.asarray(R).T @ (np.asarray(p)[:, None] - np.asarray(y))
    return np.sum(np.asarray(n0) * (np.asarray(x0) + back), axis=0)


@dataclass(frozen=True, eq=False)
class Correspondences:
    """For one part and one time step: observed points (3, N) [m], their surface points and
    normals (3, N) at the zero configuration, gate weights (N,) (0 = rejected or padding), IRLS
    weights (N,), the moment matrix H (13, 13) of the gated, IRLS-weighted pairs, the
    point-to-plane residuals (N,) [m] under the motion the pairs were made at, and which pairs
    are with the far side of the surface (N,) bool (see :func:`correspond`).  thickness: the
    slab thickness [m] the far-side pairs were made with (None: no far side modelled);
    H_thickness (14, 14): the moment matrix of the rows [a, f] with f = −1 on the modelled
    far-side pairs, so that the IRLS cost at thickness ``thickness + Δ`` is [z; Δ]ᵀ H_thickness [z; Δ]
    (a far-side residual is r = aᵀz − Δ: its target plane moves Δ further into the part)."""

    observed: np.ndarray
    targets: np.ndarray
    normals: np.ndarray
    weights: np.ndarray
    irls: np.ndarray
    H: np.ndarray
    residuals: np.ndarray
    far_side: np.ndarray
    thickness: float | None = None
    H_thickness: np.ndarray | None = None


def linear_rows(observed: np.ndarray, targets: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, 13) rows a with r = a·z, z = [vec(Rᵀ) (column-major); Rᵀp; 1] (see module doc)."""
    y, x, n = observed.T, targets.T, normals.T
    # n·Rᵀ y = Σ_jk n_j (Rᵀ)_jk y_k ; vec column-major: index j + 3k
    outer = (n[:, :, None] * y[:, None, :]).reshape(len(y), 9, order="F")
    return np.hstack([-outer, n, np.sum(n * x, axis=1, keepdims=True)])


def z_vector(T_world0_t):
    """z = [vec(Rᵀ); Rᵀp; 1] (13,) of a (4, 4) motion (numpy or casadi)."""
    R, p = T_world0_t[:3, :3], T_world0_t[:3, 3]
    if isinstance(T_world0_t, (ca.SX, ca.MX)):
        return ca.vertcat(ca.vec(R.T), ca.mtimes(R.T, p), 1)
    R, p = np.asarray(R), np.asarray(p)
    return np.concatenate([R.T.reshape(-1, order="F"), R.T @ p, [1.0]])


def fixed_subsample(points: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Row indices of a fixed, seeded subsample of at most ``n`` of ``points`` (N, 3)."""
    if len(points) <= n:
        return np.arange(len(points))
    return np.sort(np.random.default_rng(seed).choice(len(points), n, replace=False))


def correspond(observed_world: np.ndarray, T_world0_t: np.ndarray, surface: SurfaceModel, gate: float,
               size: int, delta: float, plane_gate: float = np.inf,
               sightlines: np.ndarray | None = None, thickness: float | None = None) -> Correspondences:
    """Nearest surface point of each observed point (M, 3) moved back to the zero configuration by
    ``T_world0_t``⁻¹ (4, 4); pairs farther than ``gate`` [m], or off the point's tangent plane by
    more than ``plane_gate`` [m], get weight 0.  Padded with zero weights to ``size`` columns.
    IRLS weights of the pseudo-Huber loss of width ``delta`` [m] at ``T_world0_t``.

    The far side: a seen surface faces the camera, so an observed point whose nearest surface
    point, moved, faces away from the cameras that saw it (``sightlines`` (M, 3), unit vectors
    towards them; needs an oriented surface) lies on a side of the part the model lacks — an
    opened door's inner face, a lid's underside.  Modelled as a slab, that side is the tangent
    plane moved ``thickness`` [m] into the part; with ``thickness`` None such pairs get weight 0.
    Paired with the front face instead, they pulled protocol_refrigerator_0's hinge 2.2 cm
    towards the cameras; left out, an opened laptop lid, seen only from below, kept 11 of 4000
    pairs."""
    m = len(observed_world)
    if m > size:
        raise ValueError(f"{m} observed points exceed the block size {size}")
    R, p = T_world0_t[:3, :3], T_world0_t[:3, 3]
    back = (observed_world - p) @ R  # R^T (y - p), row-wise
    d, idx = surface.tree.query(back) if m else (np.zeros(0), np.zeros(0, dtype=int))
    targets = surface.points[idx]
    keep = np.ones(m, dtype=bool)
    far = np.zeros(size, dtype=bool)
    far_test = sightlines is not None and surface.oriented
    modelled = far_test and thickness is not None  # the far side is a slab, else left out
    if far_test and m:
        # n·(Rᵀ s) = (R n)·s < 0: the moved surface point faces away from the camera
        far[:m] = np.sum(surface.normals[idx] * (sightlines @ R), axis=1) < 0
        if not modelled:
            keep = ~far[:m]
        else:  # the far side: the surface moved ``thickness`` into the part
            targets = targets - thickness * far[:m, None] * surface.normals[idx]
            d = np.where(far[:m], np.linalg.norm(back - targets, axis=1), d)
    obs = np.zeros((3, size))
    tgt = np.zeros((3, size))
    nrm = np.zeros((3, size))
    w = np.zeros(size)
    obs[:, :m] = observed_world.T
    tgt[:, :m] = targets.T
    nrm[:, :m] = surface.normals[idx].T
    if m < size:  # padding: unit normals keep the residual finite
        nrm[0, m:] = 1.0
    A = linear_rows(obs, tgt, nrm)
    r = A @ z_vector(T_world0_t)
    keep &= (d <= gate) & (np.abs(r[:m]) <= plane_gate)
    w[:m] = keep.astype(float)
    irls = w / np.sqrt(1.0 + (r / delta) ** 2)
    if not modelled:
        return Correspondences(obs, tgt, nrm, w, irls, (A * irls[:, None]).T @ A, r, far)
    Af = np.hstack([A, -far[:, None].astype(float)])
    Hf = (Af * irls[:, None]).T @ Af
    return Correspondences(obs, tgt, nrm, w, irls, Hf[:13, :13], r, far, float(thickness), Hf)


def robust_value(c: Correspondences, T_world0_t: np.ndarray, delta: float, thickness: float | None = None) -> float:
    """Σ gate-weight · ρ_δ(r) / δ² of one correspondence block under the motion ``T_world0_t``,
    its far-side pairs (if modelled) at the slab ``thickness`` [m] (None: the one they were made
    with)."""
    r = point_to_plane(T_world0_t, c.targets, c.normals, c.observed)
    if c.thickness is not None and thickness is not None:
        r = r - (thickness - c.thickness) * c.far_side
    return float(np.sum(c.weights * pseudo_huber(r, delta)) / delta**2)
