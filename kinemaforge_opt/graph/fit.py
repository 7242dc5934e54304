"""Fit each candidate joint relation — rigid, prismatic, revolute, helical — to a relative motion.

Each fit is a closed-form initialiser (chordal mean, principal line, screw / Plücker axis from
the rotation null space or — whichever starts lower — plane + circle fit of the positions, the
only one for position-only tracks) followed by a robust refinement (scipy ``least_squares``,
soft-L1 loss on residuals normalised by the estimated noise σ, so the loss switches to linear
beyond ~1σ).  Latent joint values (one per sample) are refined jointly with a sparse Jacobian.
A full-pose pair whose orientations contradict its positions (no screw fits both; see
:func:`fit_all`) is fitted on its positions, its orientations counted modulo a box's half-turn
symmetry (a registration flip).

Scoring (Sturm et al., JAIR 2011): BIC = χ² + k ln N with χ² the robust sum of normalised
squared residuals, k the model's parameters *including* its N latent joint values (so pure
noise around a static pose is rigid, not a prismatic joint of one noisy coordinate per sample).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix
from scipy.spatial.transform import Rotation

from ..spatial import normalize, tangent_basis
from .motion import RelativeMotion

JOINT_TYPES = ("rigid", "prismatic", "revolute", "helical")
# A residual RMS this many times another's is a clear misfit (the usual 3σ level).
SIGNIFICANCE = 3.0
# Refinement budget: well-posed fits converge in 5–40 evaluations; a helix on a short arc is
# nearly degenerate (pitch trades against axis tilt) and is stopped here rather than polished.
MAX_NFEV = 60
# Problems with at most this many unknowns get a dense Jacobian and an exact trust-region step
# (faster than sparse LSMR up to here; beyond, the dense SVD grows as N³).
DENSE_MAX_PARAMS = 150


@dataclass(frozen=True, eq=False)
class JointHypothesis:
    """One fitted relation between a parent and a child.

    type: 'rigid' | 'prismatic' | 'revolute' | 'helical'.
    axis_world (3,), origin_world (3,): the joint line in the world at the first common sample
    [unit, m] (None for rigid).  For revolute/helical the origin is the point of the axis closest
    to the child's first position (the circle centre for position-only tracks); for prismatic it
    is the child's position at q = 0.  axis_parent, origin_parent: the same line in the parent frame.
    pitch: helical pitch [m/rad] (0 otherwise).  radius: distance of the child origin from the
    axis [m] (revolute/helical), else None.
    q: (N,) joint values per common sample [rad or m], 0 at the first sample (zeros for rigid).
    residual_rms: RMS position residual [m].  residual_autocorr: lag-1 autocorrelation of the
    residual vectors (near 1 = systematic model error, near 0 = white noise).
    noise_sigma: the pair's estimated white position noise per coordinate [m].
    chi2: robust χ² of the normalised residuals.  n_params: global parameters; n_latent: latent
    joint values (N for moving joints, 0 for rigid).  bic: χ² + (n_params + n_latent) ln N here;
    the graph rescores it for correlated residuals (see ``graph.score``).
    confidence: ρ ∈ [0, 1], set by the graph (probability of this type for the pair times the
    fit's consistency with the noise level); 1.0 until scored.
    rotation_rms: RMS rotation residual [rad] — modulo a registration flip for a full-pose pair
    fitted on its positions (see :func:`fit_all`) — and rotation_sigma: the pair's estimated
    rotation noise per coordinate [rad] (both 0 for position-only tracks).
    times: (N,) the common samples' times [s]; position_residuals: (N, 3) the position residual
    per sample in the parent frame [m] (compares two fits of one child sample by sample).
    """

    type: str
    axis_world: np.ndarray | None
    origin_world: np.ndarray | None
    axis_parent: np.ndarray | None
    origin_parent: np.ndarray | None
    pitch: float
    radius: float | None
    q: np.ndarray
    residual_rms: float
    residual_autocorr: float
    noise_sigma: float
    chi2: float
    n_params: int
    n_latent: int
    n_samples: int
    bic: float
    confidence: float = 1.0
    rotation_rms: float = 0.0
    rotation_sigma: float = 0.0
    times: np.ndarray | None = None
    position_residuals: np.ndarray | None = None


def _unit_rows(A: np.ndarray) -> np.ndarray:
    """The rows of ``A`` (k, 3) scaled to unit length (a stack of axes, one per parameter vector)."""
    return A / np.linalg.norm(A, axis=1, keepdims=True)


def _rot(axis_angles: np.ndarray) -> np.ndarray:
    """(N, 3) rotation vectors -> (N, 3, 3) matrices (Rodrigues, vectorised; the fits call this
    thousands of times, where scipy's Rotation spends most of its time validating)."""
    w = np.asarray(axis_angles, dtype=float)
    th2 = np.einsum("ni,ni->n", w, w)
    th = np.sqrt(th2)
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th2 / 6.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(ths)) / np.where(small, 1.0, th2))
    K = np.zeros(w.shape[:1] + (3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)


def _log(Rs: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices -> (N, 3) rotation vectors (vectorised; scipy for the rare
    angles within 1e-3 rad of π, where the skew part vanishes)."""
    cos = np.clip((np.einsum("nii->n", Rs) - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(cos)
    v = np.stack([Rs[:, 2, 1] - Rs[:, 1, 2], Rs[:, 0, 2] - Rs[:, 2, 0], Rs[:, 1, 0] - Rs[:, 0, 1]], axis=1)
    small = th < 1e-4
    f = np.where(small, 0.5 + th**2 / 12.0, th / (2.0 * np.sin(np.where(small, 1.0, th))))
    out = v * f[:, None]
    near_pi = th > np.pi - 1e-3
    if near_pi.any():
        out[near_pi] = Rotation.from_matrix(Rs[near_pi]).as_rotvec()
    return out


def _robust_chi2(r: np.ndarray) -> float:
    """Sum of the soft-L1 loss 2(sqrt(1 + r²) - 1) over normalised residuals (≈ r² near 0)."""
    return float(np.sum(2.0 * (np.sqrt(1.0 + r**2) - 1.0)))


def _solve(fun, x0: np.ndarray, n_global: int, n_latent: int, rows_per_sample: int):
    """Robust least squares where the global parameters touch every residual and latent value i
    only its own ``rows_per_sample`` residuals.  The Jacobian is taken by forward differences in
    n_global + 1 evaluations (all latent values are perturbed at once: their rows are disjoint)
    and handed over dense for small problems, as CSR (LSMR trust region) for large ones.
    ``fun`` maps parameters (n,) to residuals (m,) and a stack (k, n) to (k, m): those n_global + 1
    evaluations and the unperturbed one are one call (numpy's per-call overhead, not arithmetic,
    is what a 30-sample fit spends its time on)."""
    if not n_latent:
        res = least_squares(fun, x0, loss="soft_l1", f_scale=1.0, method="trf", x_scale="jac", max_nfev=MAX_NFEV)
        return res.x, res.fun
    n = n_global + n_latent
    m = n_latent * rows_per_sample
    sample = np.arange(m) // rows_per_sample
    dense = n <= DENSE_MAX_PARAMS
    if not dense:
        cols = np.concatenate([np.tile(np.arange(n_global), (m, 1)), n_global + sample[:, None]], axis=1)
        indptr = np.arange(m + 1) * (n_global + 1)
    eps = np.sqrt(np.finfo(float).eps)

    def jac(x):
        h = eps * np.maximum(1.0, np.abs(x))
        # rows: x, x + h_i e_i per global parameter, x + every latent step at once
        X = np.tile(x, (n_global + 2, 1))
        X[1 + np.arange(n_global), np.arange(n_global)] += h[:n_global]
        X[-1, n_global:] += h[n_global:]
        F = fun(X)
        Jg = (F[1:-1] - F[0]).T / h[:n_global]
        Jl = (F[-1] - F[0]) / h[n_global:][sample]
        if dense:
            J = np.zeros((m, n))
            J[:, :n_global] = Jg
            J[np.arange(m), n_global + sample] = Jl
            return J
        return csr_matrix((np.concatenate([Jg, Jl[:, None]], axis=1).ravel(), cols.ravel(), indptr), shape=(m, n))

    res = least_squares(fun, x0, jac=jac, loss="soft_l1", f_scale=1.0, method="trf", x_scale="jac",
                        max_nfev=MAX_NFEV, tr_solver="exact" if dense else "lsmr")
    return res.x, res.fun


def _finish(kind, motion, axis_p, origin_p, pitch, radius, q, r_norm, pos_res, n_params) -> JointHypothesis:
    n = motion.n
    chi2 = _robust_chi2(r_norm)
    n_latent = 0 if kind == "rigid" else n
    bic = chi2 + (n_params + n_latent) * np.log(n)
    e = pos_res.reshape(n, 3)
    autocorr = float(np.sum(e[1:] * e[:-1]) / max(np.sum(e * e), 1e-300))
    R0, p0 = motion.T_world_parent0[:3, :3], motion.T_world_parent0[:3, 3]
    axis_w = None if axis_p is None else R0 @ axis_p
    origin_w = None if origin_p is None else R0 @ origin_p + p0
    rms = float(np.sqrt(np.mean(np.sum(pos_res.reshape(n, 3) ** 2, axis=1))))
    return JointHypothesis(
        kind, axis_w, origin_w, axis_p, origin_p, float(pitch), radius, np.asarray(q, float), rms,
        autocorr, motion.sigma_position, chi2, int(n_params), n_latent, n, float(bic),
        times=motion.times, position_residuals=e,
    )


def _orient(axis: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flip the axis so the joint value increases from the first to the last sample; q(0) = 0."""
    q = q - q[0]
    if q[-1] < 0:
        return -axis, -q
    return axis, q


# --------------------------------------------------------------------------- full pose


def _rot_residual(R_model: np.ndarray, Rs: np.ndarray) -> np.ndarray:
    return _log(np.einsum("nji,njk->nik", R_model, Rs))


def _chordal_mean(Rs: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(Rs.sum(axis=0))
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


def _pose_residuals(m: RelativeMotion, R: np.ndarray, p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Noise-normalised residuals of the model poses R (k, n, 3, 3), p (k, n, 3) of k parameter
    vectors against ``m``'s poses: (k, 6n), per sample (position, rotation vector); (6n,) when
    ``x``, the parameters asked for, is one vector."""
    k, n = p.shape[:2]
    R = np.broadcast_to(R, (k, n, 3, 3)).reshape(-1, 3, 3)
    rot = _rot_residual(R, np.tile(m.Rs, (k, 1, 1))).reshape(k, n, 3)
    r = np.concatenate([(m.positions - p) / m.sigma_position, rot / m.sigma_rotation], axis=2).reshape(k, -1)
    return r if np.ndim(x) == 2 else r[0]


def _fit_pose(kind: str, m: RelativeMotion) -> JointHypothesis:
    Rs, ps, sp, sr, n = m.Rs, m.positions, m.sigma_position, m.sigma_rotation, m.n
    if kind == "rigid":
        R0 = _chordal_mean(Rs)

        def fun(x):
            X = np.atleast_2d(x)
            R = (_rot(X[:, :3]) @ R0)[:, None]
            return _pose_residuals(m, R, np.repeat(X[:, None, 3:6], n, axis=1), x)

        x0, n_glob, k = np.r_[np.zeros(3), np.median(ps, axis=0)], 6, 6
    elif kind == "prismatic":
        R0 = _chordal_mean(Rs)
        c = ps.mean(axis=0)
        a0 = np.linalg.svd(ps - c)[2][0]
        B = tangent_basis(a0)
        d0 = (ps - c) @ a0

        def fun(x):
            X = np.atleast_2d(x)
            R = (_rot(X[:, :3]) @ R0)[:, None]
            a = _unit_rows(a0 + X[:, 3:5] @ B.T)
            return _pose_residuals(m, R, (c + X[:, 5:7] @ B.T)[:, None] + X[:, 7:, None] * a[:, None], x)

        x0, n_glob, k = np.r_[np.zeros(7), d0], 7, 7
    else:
        return _fit_pose_screw(kind, m)

    x, r = _solve(fun, x0, n_glob, x0.size - n_glob, 6)
    r = r.reshape(n, 6)
    pos_res = r[:, :3] * sp
    rot = dict(rotation_rms=float(np.sqrt(np.mean(np.sum((r[:, 3:] * sr) ** 2, axis=1)))), rotation_sigma=float(sr))
    if kind == "rigid":
        return dataclasses.replace(_finish(kind, m, None, None, 0.0, None, np.zeros(n), r.ravel(), pos_res, k), **rot)
    if kind == "prismatic":
        a = normalize(a0 + B @ x[3:5])
        axis, q = _orient(a, x[7:])
        origin = c + B @ x[5:7] + x[7] * a
        return dataclasses.replace(_finish(kind, m, axis, origin, 0.0, None, q, r.ravel(), pos_res, k), **rot)


def _rotation_start(m: RelativeMotion, ref: int, helical: bool):
    """Screw start from the rotations: axis = null space of R_t R_ref^T − I, angles = the
    rotation vectors' components along it, centre (and pitch) by least squares on the positions."""
    Rs, ps = m.Rs, m.positions
    dR = np.einsum("nij,kj->nik", Rs, Rs[ref])  # R_t R_ref^T
    dp = ps - np.einsum("nij,j->ni", dR, ps[ref])
    a0 = np.linalg.svd((dR - np.eye(3)).reshape(-1, 3))[2][-1]
    phi = _rot_residual(np.tile(np.eye(3), (m.n, 1, 1)), dR) @ a0
    h0 = float(np.dot(dp @ a0, phi) / max(np.dot(phi, phi), 1e-300)) if helical else 0.0
    c0 = np.linalg.lstsq((np.eye(3) - dR).reshape(-1, 3), (dp - h0 * phi[:, None] * a0).reshape(-1), rcond=None)[0]
    return a0, c0, phi, h0


def _position_start(m: RelativeMotion, ref: int, helical: bool):
    """Screw start from the positions alone (plane + circle, see :func:`_circle`): needed when the
    track's orientations are unreliable (a flat door registered flipped by π on some frames), where
    the rotation start's angles are wrong although the positions trace a clean arc."""
    ps = m.positions
    a0, centre, _, _, th = _circle(ps)
    th = th - th[ref]
    h0 = float(np.dot((ps - ps[ref]) @ a0, th) / max(np.dot(th, th), 1e-300)) if helical else 0.0
    return a0, centre, th, h0


def _fit_pose_screw(kind: str, m: RelativeMotion) -> JointHypothesis:
    """Revolute / helical fit of a full-pose motion, refined from the better (lower robust cost)
    of a rotation-based and a position-based start."""
    Rs, ps, sp, sr, n = m.Rs, m.positions, m.sigma_position, m.sigma_rotation, m.n
    ref = n // 2
    nh = 1 if kind == "helical" else 0
    n_glob, k = 10 + nh, 9 + nh  # one gauge freedom (angle offset vs reference orientation)
    R_ref, p_ref = Rs[ref], ps[ref]
    starts = []
    for start in (_rotation_start, _position_start):
        a0, c0, phi, h0 = start(m, ref, bool(nh))
        B = tangent_basis(a0)

        def fun(x, a0=a0, c0=c0, B=B):
            """Residuals (m,) of x (nx,), or (k, m) of a stack x (k, nx)."""
            X = np.atleast_2d(x)
            k = X.shape[0]
            a = _unit_rows(a0 + X[:, :2] @ B.T)
            cc = c0 + X[:, 2:4] @ B.T
            Rr = _rot(X[:, 4:7]) @ R_ref
            pr = p_ref + X[:, 7:10]
            h = X[:, 10] if nh else np.zeros(k)
            th = X[:, 10 + nh:]
            Ra = _rot((th[:, :, None] * a[:, None, :]).reshape(-1, 3)).reshape(k, n, 3, 3)
            p = cc[:, None] + np.einsum("knij,kj->kni", Ra, pr - cc) + (h[:, None] * th)[:, :, None] * a[:, None, :]
            return _pose_residuals(m, Ra @ Rr[:, None], p, x)

        x0 = np.r_[np.zeros(10), [h0] * nh, phi]
        starts.append((_robust_chi2(fun(x0)), fun, x0, a0, c0, B))
    _, fun, x0, a0, c0, B = min(starts, key=lambda s: s[0])
    x, r = _solve(fun, x0, n_glob, n, 6)
    r = r.reshape(n, 6)
    a, cc = normalize(a0 + B @ x[:2]), c0 + B @ x[2:4]
    pos_res = r[:, :3] * sp
    rot = dict(rotation_rms=float(np.sqrt(np.mean(np.sum((r[:, 3:] * sr) ** 2, axis=1)))), rotation_sigma=float(sr))
    h = x[10] if nh else 0.0
    axis, q = _orient(a, x[n_glob:])
    origin = cc + a * np.dot(ps[0] - cc, a)
    radius = float(np.linalg.norm((ps[0] - cc) - a * np.dot(ps[0] - cc, a)))
    # Flipping the axis negates the angle too, so the pitch h is unchanged.
    return dataclasses.replace(_finish(kind, m, axis, origin, h, radius, q, r.ravel(), pos_res, k), **rot)


# --------------------------------------------------------------------------- position only


def _circle(ps: np.ndarray):
    """Plane + algebraic circle fit of (N, 3) points -> (axis (3,) = plane normal, centre (3,),
    radius [m], U0 (3, 2) in-plane basis, angles (N,) about +axis, unwrapped) with (u, v, axis)
    right-handed."""
    mean = ps.mean(axis=0)
    U0 = np.linalg.svd(ps - mean)[2][:2].T
    a0 = np.cross(U0[:, 0], U0[:, 1])
    uv = (ps - mean) @ U0
    sol = np.linalg.lstsq(np.c_[2 * uv, np.ones(len(ps))], np.sum(uv**2, axis=1), rcond=None)[0]
    r0 = float(np.sqrt(max(sol[2] + sol[:2] @ sol[:2], 0.0)))
    th0 = np.unwrap(np.arctan2(uv[:, 1] - sol[1], uv[:, 0] - sol[0]))
    return a0, mean + U0 @ sol[:2], r0, U0, th0


def _fit_points(kind: str, m: RelativeMotion) -> JointHypothesis:
    ps, sp, n = m.positions, m.sigma_position, m.n
    mean = ps.mean(axis=0)
    _, _, Vt = np.linalg.svd(ps - mean)
    # each model maps a stack of parameter vectors X (k, nx) to positions (k, n, 3)
    if kind == "rigid":
        model = lambda X: np.repeat(X[:, None], n, axis=1)  # noqa: E731
        x0, n_glob, k = np.median(ps, axis=0), 3, 3
    elif kind == "prismatic":
        a0 = Vt[0]
        B = tangent_basis(a0)

        def model(X):
            a = _unit_rows(a0 + X[:, :2] @ B.T)
            return (mean + X[:, 2:4] @ B.T)[:, None] + X[:, 4:, None] * a[:, None]

        x0, n_glob, k = np.r_[np.zeros(4), (ps - mean) @ a0], 4, 4
    else:  # revolute / helical: plane (normal = axis) + algebraic circle fit in that plane
        a0, centre0, r0, U0, th0 = _circle(ps)
        nh = 1 if kind == "helical" else 0
        B = tangent_basis(a0)

        def frame(X):
            a = _unit_rows(a0 + X[:, 3:5] @ B.T)
            u = _unit_rows(U0[:, 0] - a * (a @ U0[:, 0])[:, None])
            return a, u, np.cross(a, u)

        def model(X):
            a, u, v = frame(X)
            th = X[:, 6 + nh:, None]
            h = X[:, 6, None, None] if nh else 0.0
            return (X[:, None, :3] + X[:, 5, None, None] * (np.cos(th) * u[:, None] + np.sin(th) * v[:, None])
                    + h * th * a[:, None])

        x0 = np.r_[centre0, 0.0, 0.0, r0, [0.0] * nh, th0]  # helix starts as the circle
        n_glob = 6 + nh
        k = 6 + nh

    def fun(x):
        r = ((ps - model(np.atleast_2d(x))) / sp).reshape(-1, 3 * n)
        return r if np.ndim(x) == 2 else r[0]

    x, _ = _solve(fun, x0, n_glob, x0.size - n_glob, 3)
    r = fun(x)
    pos_res = r * sp
    if kind == "rigid":
        return _finish(kind, m, None, None, 0.0, None, np.zeros(n), r, pos_res, k)
    if kind == "prismatic":
        a = normalize(a0 + B @ x[:2])
        axis, q = _orient(a, x[4:])
        origin = mean + B @ x[2:4] + x[4] * a
        return _finish(kind, m, axis, origin, 0.0, None, q, r, pos_res, k)
    a = frame(x[None])[0][0]
    th = x[n_glob:]
    # The circle's angle runs about +a; flipping the axis negates the angle and keeps the pitch.
    axis, q = _orient(a, th)
    h = x[6] if kind == "helical" else 0.0
    centre = x[:3] + (h * th[0] * a if kind == "helical" else 0.0)
    return _finish(kind, m, axis, centre, h, float(abs(x[5])), q, r, pos_res, k)


def fit_relation(kind: str, motion: RelativeMotion) -> JointHypothesis:
    """Fit one relation type (see JOINT_TYPES) to ``motion``; returns the unscored hypothesis."""
    if kind not in JOINT_TYPES:
        raise ValueError(f"unknown relation type {kind!r}; expected one of {JOINT_TYPES}")
    return (_fit_pose if motion.Rs is not None else _fit_points)(kind, motion)


def fit_all(motion: RelativeMotion) -> dict[str, JointHypothesis]:
    """Every relation type fitted to ``motion``, keyed by type.

    Full-pose motions whose orientations contradict their positions are fitted on the positions,
    the orientations counting modulo a registration flip (see :func:`_flip_scored`): when the
    better of the revolute and helical fits that must explain both clearly misfits what the
    hinge through the positions explains (see :func:`rotations_contradict`)."""
    hyps = {kind: fit_relation(kind, motion) for kind in JOINT_TYPES}
    if motion.Rs is None:
        return hyps
    screw = min(hyps["revolute"], hyps["helical"], key=lambda h: h.residual_rms)
    if (screw.residual_rms <= SIGNIFICANCE * np.sqrt(3.0) * motion.sigma_position
            and screw.rotation_rms <= SIGNIFICANCE * np.sqrt(3.0) * motion.sigma_rotation):
        return hyps  # poses fitted to the noise level: no contradiction possible
    points = dataclasses.replace(motion, Rs=None, sigma_rotation=0.0)
    revolute = _flip_scored(_fit_points("revolute", points), motion)
    if not rotations_contradict(screw, revolute):
        return hyps
    return {kind: revolute if kind == "revolute" else _flip_scored(_fit_points(kind, points), motion)
            for kind in JOINT_TYPES}


def rotations_contradict(full: JointHypothesis, points: JointHypothesis) -> bool:
    """True when the full-pose screw fit ``full`` misfits by more than SIGNIFICANCE times the
    position-only hinge fit ``points`` (scored by :func:`_flip_scored`) the positions or the
    orientations — these modulo a registration flip for ``points`` (RMS floored at √3·σ).

    A registration of a part with a symmetric shape (a flat door, a drawer front) may come out
    turned by the symmetry (π about the panel's normal) on some frames: the orientation jumps,
    the position — the centroid of the registered points, which the symmetry maps onto itself —
    does not.  A hinge that explains such orientations misses the positions (a π swing); one
    that explains the positions misses the orientations; the position-only fit, up to the flip,
    does neither."""
    floor = np.sqrt(3.0) * full.noise_sigma
    floor_r = np.sqrt(3.0) * full.rotation_sigma
    return (max(full.residual_rms, floor) > SIGNIFICANCE * max(points.residual_rms, floor)
            or max(full.rotation_rms, floor_r) > SIGNIFICANCE * max(points.rotation_rms, floor_r))


def _half_turn_axis(A: np.ndarray) -> np.ndarray:
    """(K, 3) axes of the half-turns nearest (K, 3, 3) rotations (a half-turn about n is
    2nnᵀ − I: the top eigenvector of the symmetric part)."""
    return np.linalg.eigh((A + np.swapaxes(A, 1, 2)) / 2.0)[1][:, :, -1]


def _top_axis(n: np.ndarray) -> np.ndarray:
    """The unit axis (3,) closest to (K, 3) sign-free unit axes (top eigenvector of Σ nnᵀ)."""
    return np.linalg.eigh(n.T @ n)[1][:, -1]


def flip_angles(Rs: np.ndarray) -> np.ndarray:
    """(N,) angles [rad] of (N, 3, 3) rotations from a central one, R_ref, modulo the symmetry
    of a box: the half-turns about three perpendicular body axes b1, b2, b3 (which registration
    cannot tell apart on a panel or a drawer front).  Sample t counts the least angle of
    gᵀ R_refᵀ R_t over g ∈ {I, half-turns about b1, b2, b3}.

    R_ref is the sample with the least median angle to the others, each angle δ taken as
    min(δ, π − δ).  b1 is the axis nearest the half-turn axes of the samples more than π/2 from
    R_ref (none: no flip), b2 that of the rest of them (axes more than 45° from b1) projected
    off b1, b3 = b1 × b2.  Fixed axes, not any half-turn: a half-turn composed with a turn about
    a perpendicular axis is again a half-turn."""
    cos = (np.einsum("rji,tji->rt", Rs, Rs) - 1.0) / 2.0  # cos of the angle of R_rᵀ R_t
    d = np.arccos(np.clip(cos, -1.0, 1.0))
    ref = int(np.argmin(np.median(np.minimum(d, np.pi - d), axis=1)))
    A = np.einsum("ji,njk->nik", Rs[ref], Rs)
    far = d[ref] > np.pi / 2
    if not far.any():
        return d[ref]
    n = _half_turn_axis(A[far])
    b1 = _top_axis(n)
    rest = n[np.abs(n @ b1) < np.cos(np.pi / 4)]
    b2 = _top_axis(rest - np.outer(rest @ b1, b1)) if len(rest) else tangent_basis(b1)[:, 0]
    b2 = normalize(b2 - b1 * (b2 @ b1))
    out = d[ref]
    for b in (b1, b2, np.cross(b1, b2)):
        g = 2.0 * np.outer(b, b) - np.eye(3)
        out = np.minimum(out, np.arccos(np.clip((np.einsum("ij,nij->n", g, A) - 1.0) / 2.0, -1.0, 1.0)))
    return out


def _flip_scored(h: JointHypothesis, motion: RelativeMotion) -> JointHypothesis:
    """A position-only fit ``h`` of full-pose ``motion`` with the orientations scored modulo a
    registration flip: what the relation leaves of them — Rot(axis, q_t)ᵀ R_t for a hinge or
    screw, R_t for rigid and prismatic — must stay put up to a flip (:func:`flip_angles`).
    Their χ² (each angle spread over its three coordinates) joins the positions', so the
    information criterion weighs both.

    A flat door registered flipped by π on some frames still turns with its hinge between flips.
    A drawer fragment does not turn: its centroid may trace a slight arc (or jump when the
    registration slips to another face), and a hinge through those positions claims a rotation
    the orientations do not show."""
    Rs = motion.Rs
    if h.type in ("revolute", "helical"):
        Rs = np.einsum("nji,njk->nik", _rot(h.q[:, None] * h.axis_parent[None, :]), Rs)
    d, sr = flip_angles(Rs), motion.sigma_rotation
    chi2 = h.chi2 + 3.0 * _robust_chi2(d / (np.sqrt(3.0) * sr))
    return dataclasses.replace(h, chi2=chi2, bic=chi2 + (h.n_params + h.n_latent) * np.log(h.n_samples),
                               rotation_rms=float(np.sqrt(np.mean(d**2))), rotation_sigma=float(sr))
