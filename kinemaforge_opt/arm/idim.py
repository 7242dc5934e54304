"""Classical IDIM-LS: inverse-dynamics identification model solved by linear least squares.

tau = W(q, v, a) theta, with W = [Pinocchio joint-torque regressor (10 per body, inertia about
the joint frame, Pinocchio order m, mc, I) | armature a_i | viscous v_i | Coulomb sign(v_i) |
offset 1] per joint.  Only the base columns (an independent subset found by QR with column
pivoting) are estimated; the others stay at zero.  Accelerations come from zero-phase low-pass
filtered velocities; torques get the same filter (parallel filtering).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg
import scipy.signal

from ..errors import DataError
from ..io.recording import Recording
from ..model import ArticulatedModel
from ..model.pinocchio import DYNAMIC_PARAMETER_NAMES, build_pin_model

_JOINT_TERMS = ("armature", "viscous", "coulomb", "offset")


def parameter_names(joint_names) -> list[str]:
    """Names of the columns of :func:`identification_regressor` (body i rides on joint i)."""
    names = [f"{j}.{p}" for j in joint_names for p in DYNAMIC_PARAMETER_NAMES]
    return names + [f"{j}.{term}" for term in _JOINT_TERMS for j in joint_names]


def identification_regressor(pin_model: pin.Model, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Stacked regressor W, shape (T*n, 14 n), rows sample-major (t0: joints 0..n-1, t1: …).

    q, v, a: (T, n) [rad, rad/s, rad/s²].  Columns as :func:`parameter_names`."""
    q, v, a = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, v, a))
    T, n = q.shape
    data = pin_model.createData()
    W = np.zeros((T, n, 14 * n))
    eye = np.eye(n)
    for k in range(T):
        W[k, :, : 10 * n] = pin.computeJointTorqueRegressor(pin_model, data, q[k], v[k], a[k])
    W[:, :, 10 * n : 11 * n] = eye * a[:, None, :]
    W[:, :, 11 * n : 12 * n] = eye * v[:, None, :]
    W[:, :, 12 * n : 13 * n] = eye * np.sign(v)[:, None, :]
    W[:, :, 13 * n :] = eye
    return W.reshape(T * n, 14 * n)


def base_columns(W: np.ndarray, rtol: float = 1e-6) -> np.ndarray:
    """Sorted indices of an independent subset of W's columns spanning its column space
    (QR with column pivoting; |R_kk| > rtol·|R_00|)."""
    _, R, piv = scipy.linalg.qr(W, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > rtol * d[0]))
    return np.sort(piv[:rank])


def filtered_states(rec: Recording, cutoff_hz: float = 8.0) -> tuple[np.ndarray, ...]:
    """(q, v, a, tau), each (T, n), from a recording with v and tau: zero-phase 4th-order
    Butterworth at ``cutoff_hz`` [Hz] on q, v and tau; a = d/dt of filtered v [rad/s²]."""
    if rec.v is None or rec.tau is None:
        raise DataError("IDIM-LS needs a recording with v and tau columns")
    fs = 1.0 / rec.dt
    if not cutoff_hz < fs / 2:
        raise DataError(f"cutoff {cutoff_hz} Hz must be below the Nyquist frequency {fs / 2} Hz")
    sos = scipy.signal.butter(4, cutoff_hz, fs=fs, output="sos")
    f = lambda x: scipy.signal.sosfiltfilt(sos, x, axis=0)  # noqa: E731
    v = f(rec.v)
    return f(rec.q), v, np.gradient(v, rec.t, axis=0), f(rec.tau)


@dataclass(frozen=True, eq=False)
class IdimResult:
    """An IDIM-LS estimate.

    theta: (14 n,) parameters named by ``names`` (non-base ones are 0); base: indices estimated.
    viscous, coulomb, offset, armature: (n,) per joint [N·m·s/rad, N·m, N·m, kg·m²] (armature
    and inertia columns are only meaningful as base combinations).
    fit_rms: (n,) RMS of the filtered-torque residual on the fitting rows [N·m]."""

    pin_model: pin.Model
    joint_names: tuple[str, ...]
    names: tuple[str, ...]
    theta: np.ndarray
    base: np.ndarray
    fit_rms: np.ndarray

    def _block(self, term: str) -> np.ndarray:
        n = len(self.joint_names)
        k = 10 + _JOINT_TERMS.index(term)
        return self.theta[k * n : (k + 1) * n]

    @property
    def viscous(self) -> np.ndarray:
        return self._block("viscous")

    @property
    def coulomb(self) -> np.ndarray:
        return self._block("coulomb")

    @property
    def offset(self) -> np.ndarray:
        return self._block("offset")

    @property
    def armature(self) -> np.ndarray:
        return self._block("armature")

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Predicted joint torques (T, n) [N·m] for q, v, a (T, n)."""
        W = identification_regressor(self.pin_model, q, v, a)
        return (W @ self.theta).reshape(np.shape(q))

    def inverse_dynamics(self):
        """The estimate as a callable tau = id(q (n,), v (n,), a (n,)) [N·m]."""
        return lambda q, v, a: self.predict(q[None], v[None], a[None])[0]


def fit_idim_ls(
    model: ArticulatedModel,
    rec: Recording,
    cutoff_hz: float = 8.0,
    decimate: int = 10,
    trim_s: float = 0.1,
    v_min: float = 0.1,
) -> IdimResult:
    """IDIM-LS on ``rec`` (q, v, tau of ``model``'s movable joints) using ``model``'s kinematics.

    cutoff_hz: low-pass for q, v, tau [Hz]; decimate: keep every k-th sample after filtering;
    trim_s: seconds dropped at each end (filter transients); v_min [rad/s]: rows of a joint whose
    |v| is below it are left out of the fit (friction there is neither sign(v) nor well filtered)."""
    rec = rec.select(model.joint_names)
    pm = build_pin_model(model)
    q, v, a, tau = filtered_states(rec, cutoff_hz)
    keep = np.flatnonzero((rec.t >= rec.t[0] + trim_s) & (rec.t <= rec.t[-1] - trim_s))[::decimate]
    if keep.size < 2:
        raise DataError(f"recording of {rec.t[-1] - rec.t[0]:.3g} s is too short for IDIM-LS")
    W = identification_regressor(pm, q[keep], v[keep], a[keep])
    y = tau[keep].ravel()
    rows = np.abs(v[keep]).ravel() >= v_min
    base = base_columns(W[rows])
    beta, *_ = np.linalg.lstsq(W[rows][:, base], y[rows], rcond=None)
    theta = np.zeros(W.shape[1])
    theta[base] = beta
    resid = np.where(rows, y - W @ theta, 0.0).reshape(keep.size, -1)
    return IdimResult(pm, model.joint_names, tuple(parameter_names(model.joint_names)), theta, base,
                      np.sqrt(np.sum(resid**2, axis=0) / np.maximum(rows.reshape(keep.size, -1).sum(0), 1)))


def torque_rms(tau_pred: np.ndarray, tau_meas: np.ndarray) -> np.ndarray:
    """Per-joint RMS of tau_pred - tau_meas, both (T, n) [N·m] -> (n,)."""
    return np.sqrt(np.mean((np.asarray(tau_pred) - np.asarray(tau_meas)) ** 2, axis=0))


def held_out_rms(predict, rec: Recording, cutoff_hz: float = 8.0, trim_s: float = 0.1,
                 filtered_torque: bool = False) -> np.ndarray:
    """Per-joint RMS [N·m] (n,) of ``predict(q, v, a)`` ((T, n) arrays -> (T, n) torques) against
    the measured torque of ``rec``, states from :func:`filtered_states`, ``trim_s`` [s] dropped
    at each end.  filtered_torque: compare with the equally filtered torque instead of the raw one
    (removes sensor noise and the controller's high-frequency torque that filtered accelerations
    cannot follow)."""
    q, v, a, tau_f = filtered_states(rec, cutoff_hz)
    m = (rec.t >= rec.t[0] + trim_s) & (rec.t <= rec.t[-1] - trim_s)
    return torque_rms(predict(q[m], v[m], a[m]), (tau_f if filtered_torque else rec.tau)[m])


def batched(id_fn):
    """A single-sample callable tau = id(q, v, a) ((n,) arrays) as a (T, n) -> (T, n) one."""
    return lambda q, v, a: np.array([id_fn(q[k], v[k], a[k]) for k in range(len(q))])
