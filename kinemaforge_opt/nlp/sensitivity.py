"""Uncertainty and identifiability of a solved joint-space fit.

The collocation defects D(X, z) = 0 define the trajectory X as a function of the initial state
x0 and the scaled parameters z.  By the implicit-function theorem,
dX_rest/ds = -(dD/dX_rest)^-1 dD/ds with s = (x0, z); the output residuals r(X) then give the
Gauss–Newton information F = Jᵀ J (J = dr/ds) and the covariance s² F⁻¹, s² = RSS / (N - dof).
Unit-axis parameters are reduced to their two tangent directions first (the length of an axis
vector is not a parameter).  Directions of F with eigenvalue below ``rel_tol`` × the largest
(after normalising each coordinate) are reported as combinations the data cannot determine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..spatial import normalize, tangent_basis
from .joint_space import JointSpaceFit


@dataclass(frozen=True)
class Sensitivity:
    """cov_z: covariance of the scaled parameters z (in the full z coordinates; axis blocks
    carry their tangent-plane covariance).  unidentifiable: list of {coordinate label: weight}
    combinations the data cannot determine.  null_z: (nz, k) those directions in z coordinates
    (unit columns; the initial-state part of each direction dropped).  dof: residuals minus
    parameters."""

    cov_z: np.ndarray
    labels: tuple[str, ...]
    unidentifiable: tuple[dict[str, float], ...]
    residual_variance: float
    dof: int
    null_z: np.ndarray


def lag1_autocorrelation(residuals: np.ndarray) -> float:
    """Pooled lag-1 autocorrelation of residual series (rows = series, time along axis 1),
    clipped to [0, 0.99]."""
    r = np.atleast_2d(residuals)
    r = r - r.mean(axis=1, keepdims=True)
    num = float(np.sum(r[:, 1:] * r[:, :-1]))
    den = float(np.sum(r * r))
    return float(np.clip(num / den if den > 0 else 0.0, 0.0, 0.99))


def ar1_inflation(residuals: np.ndarray) -> float:
    """Variance inflation (1 + rho)/(1 - rho) of the mean of AR(1)-correlated residuals."""
    rho = lag1_autocorrelation(residuals)
    return (1 + rho) / (1 - rho)


def fit_sensitivity(fit: JointSpaceFit, X: np.ndarray, z: np.ndarray, rel_tol: float = 1e-9) -> Sensitivity:
    """Covariance and unidentifiable directions at the solution (X (2n, T), z (nz,))."""
    import casadi as ca

    nx, T = X.shape
    Xs = ca.MX.sym("X", nx, T)
    zs = ca.MX.sym("z", z.size)
    D = fit.defects(Xs, zs)
    jac = ca.Function("defect_jacobians", [Xs, zs], [ca.jacobian(D, Xs), ca.jacobian(D, zs)])
    JX, Jz = jac(X, z)
    JX, Jz = sp.csc_matrix(JX.sparse()), Jz.full()
    r = fit.residuals(X).full().ravel()
    Rj = ca.Function("residual_jacobian", [Xs], [ca.jacobian(fit.residuals(Xs), Xs)])(X)
    Rj = sp.csr_matrix(Rj.sparse())

    # s = (free states, z): the first state of every segment is free; the rest follow from the defects.
    free_idx = np.concatenate([np.arange(c * nx, (c + 1) * nx) for c in fit.segment_starts])
    rest_idx = np.setdiff1d(np.arange(nx * T), free_idx)
    A = JX[:, rest_idx]
    B = sp.hstack([JX[:, free_idx], sp.csc_matrix(Jz)]).toarray()
    n_free = free_idx.size
    dX = np.zeros((nx * T, n_free + z.size))
    dX[free_idx, np.arange(n_free)] = 1.0
    dX[rest_idx] = -spla.splu(A.tocsc()).solve(B)
    J = Rj @ dX

    # Reduce axis blocks to their tangent plane.
    labels = []
    nrow = n_free + z.size
    P = []
    for i in range(n_free):
        e = np.zeros(nrow)
        e[i] = 1
        P.append(e)
        labels.append(f"initial state[{i}]")
    offset = n_free
    for b in fit.blocks:
        if b.name.endswith(".axis"):
            Bt = tangent_basis(normalize(z[offset - n_free : offset - n_free + 3]))
            for k in range(2):
                e = np.zeros(nrow)
                e[offset : offset + 3] = Bt[:, k]
                P.append(e)
                labels.append(f"{b.name}[tilt {k}]")
        else:
            for k in range(b.size):
                e = np.zeros(nrow)
                e[offset + k] = 1
                P.append(e)
                labels.append(b.name if b.size == 1 else f"{b.name}[{k}]")
        offset += b.size
    P = np.stack(P, axis=1)  # (n_free + nz, reduced)
    Jr = J @ P
    F = Jr.T @ Jr
    dof = max(r.size - F.shape[0], 1)
    # Residual variance, inflated by the AR(1) variance factor (1 + rho)/(1 - rho) of the
    # residuals' lag-1 autocorrelation: model-form error makes residuals correlated in time, and
    # treating them as independent would understate the uncertainty.
    # r stacks vec(R) of (n, T_samples) residual blocks (q, then v), column-major: one series
    # per joint and block.
    n_samples = fit.recording.t.size
    series = r.reshape(-1, n_samples, fit.model.nq).transpose(0, 2, 1).reshape(-1, n_samples)
    s2 = float(r @ r) / dof * ar1_inflation(series)

    d = np.sqrt(np.maximum(np.diag(F), 1e-300))
    Fn = F / np.outer(d, d)
    w, V = np.linalg.eigh(Fn)
    keep = w > rel_tol * w.max()
    Fn_inv = (V[:, keep] / w[keep]) @ V[:, keep].T
    cov_r = s2 * Fn_inv / np.outer(d, d)
    # reduced parameter coordinates -> full z coordinates (axis blocks: tangent plane into 3-D)
    Pz = P[n_free:, n_free:] if P.shape[1] > n_free else np.zeros((z.size, 0))
    unidentifiable, null_z = [], []
    for k in np.where(~keep)[0]:
        # the direction in reduced coordinates (y = d·r), then in z
        zdir = Pz @ (V[n_free:, k] / d[n_free:])
        if np.linalg.norm(zdir) > 0:
            null_z.append(zdir / np.linalg.norm(zdir))
        vec = V[:, k]
        combo = {labels[i]: float(vec[i]) for i in np.argsort(-np.abs(vec)) if abs(vec[i]) > 0.2 and i >= n_free}
        if combo:
            unidentifiable.append(combo)
    cov_z = Pz @ cov_r[n_free:, n_free:] @ Pz.T
    null = np.stack(null_z, axis=1) if null_z else np.zeros((z.size, 0))
    return Sensitivity(cov_z, tuple(labels), tuple(unidentifiable), s2, dof, null)
