"""Exciting trajectories: a finite Fourier series per joint, inside position, velocity and
acceleration limits, optimised for the condition number of the identification regressor
(:func:`kinemaforge_opt.arm.idim.identification_regressor` restricted to its base columns).

q_i(t) = q0_i + sum_l [ a_il sin(l w t) - b_il cos(l w t) ] / (l w),  w = 2 pi f0,  l = 1..L,
so q, v and acc are linear in each joint's coefficients x_i = [q0_i, a_i1..a_iL, b_i1..b_iL]:
the limits are linear constraints (SLSQP) and the trajectory is periodic with period 1/f0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize

from ..errors import DataError, ModelError
from ..io.recording import Recording
from ..model import ArticulatedModel
from ..model.pinocchio import build_pin_model
from .control import inverse_dynamics
from .idim import base_columns, identification_regressor

#: Franka Panda joint acceleration limits [rad/s²] (datasheet), a sensible default for arms.
PANDA_ACC_LIMITS = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])


def design_matrices(t: np.ndarray, base_frequency: float, harmonics: int):
    """(Q, V, A), each (T, 1 + 2L): q = Q @ x_i, v = V @ x_i, acc = A @ x_i for one joint."""
    t = np.asarray(t, dtype=float)
    w = 2 * np.pi * base_frequency * np.arange(1, harmonics + 1)
    s, c = np.sin(np.outer(t, w)), np.cos(np.outer(t, w))
    one, zero = np.ones((t.size, 1)), np.zeros((t.size, 1))
    return np.hstack([one, s / w, -c / w]), np.hstack([zero, c, s]), np.hstack([zero, -s * w, c * w])


@dataclass(frozen=True, eq=False)
class FourierTrajectory:
    """Finite Fourier series per joint.  base_frequency f0 [Hz]; coefficients (n, 1 + 2L):
    per joint [q0 [rad], a_1..a_L, b_1..b_L [rad/s]]."""

    base_frequency: float
    coefficients: np.ndarray

    @property
    def harmonics(self) -> int:
        return (self.coefficients.shape[1] - 1) // 2

    @property
    def period(self) -> float:
        """[s]"""
        return 1.0 / self.base_frequency

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, v, acc) at times t (T,) [s], each (T, n) [rad, rad/s, rad/s²]."""
        Q, V, A = design_matrices(t, self.base_frequency, self.harmonics)
        X = self.coefficients.T
        return Q @ X, V @ X, A @ X


@dataclass(frozen=True)
class Limits:
    """Per-joint bounds, (n,) each: q_lower, q_upper [rad], v_max [rad/s], a_max [rad/s²]."""

    q_lower: np.ndarray
    q_upper: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray

    def within(self, q_lower: np.ndarray, q_upper: np.ndarray, margin: float = 0.1) -> "Limits":
        """These limits narrowed to also keep ``margin`` [rad] inside another range (n,) each,
        e.g. a real arm's joint ranges."""
        lo = np.maximum(self.q_lower, np.asarray(q_lower) + margin)
        hi = np.minimum(self.q_upper, np.asarray(q_upper) - margin)
        if np.any(lo >= hi):
            raise ModelError(f"joint ranges do not overlap for joints {np.flatnonzero(lo >= hi).tolist()}")
        return Limits(lo, hi, self.v_max, self.a_max)


def model_limits(
    model: ArticulatedModel,
    a_max: np.ndarray | float = PANDA_ACC_LIMITS,
    position_margin: float = 0.1,
    velocity_fraction: float = 0.5,
) -> Limits:
    """Limits from the model's URDF limits: positions shrunk by ``position_margin`` [rad] at each
    end, velocities scaled by ``velocity_fraction``; ``a_max`` [rad/s²] (n,) or scalar.
    Raises :class:`ModelError` naming a joint without finite position or velocity limits."""
    lo, hi, vm = [], [], []
    for j in model.movable_joints:
        lim = j.limits
        if lim is None or not np.all(np.isfinite([lim.lower, lim.upper, lim.velocity])):
            raise ModelError(f"joint {j.name!r} needs finite position and velocity limits for excitation design")
        if lim.upper - lim.lower <= 2 * position_margin:
            raise ModelError(f"joint {j.name!r}: range {lim.lower}..{lim.upper} is narrower than twice the margin")
        lo.append(lim.lower + position_margin)
        hi.append(lim.upper - position_margin)
        vm.append(lim.velocity * velocity_fraction)
    n = model.nq
    return Limits(np.array(lo), np.array(hi), np.array(vm), np.broadcast_to(np.asarray(a_max, float), (n,)).copy())


def limit_violation(traj: FourierTrajectory, limits: Limits, samples: int = 2000) -> float:
    """Largest violation of any limit over one period (dense grid); <= 0 means within limits."""
    q, v, a = traj.evaluate(np.linspace(0, traj.period, samples, endpoint=False))
    return float(max(np.max(q - limits.q_upper), np.max(limits.q_lower - q),
                     np.max(np.abs(v) - limits.v_max), np.max(np.abs(a) - limits.a_max)))


def _fit_into_limits(X: np.ndarray, f0: float, limits: Limits, shrink: float = 0.98) -> np.ndarray:
    """Scale each joint's oscillation (and re-centre it) so the trajectory fits the limits."""
    t = np.linspace(0, 1 / f0, 2000, endpoint=False)
    Q, V, A = design_matrices(t, f0, (X.shape[1] - 1) // 2)
    X = X.copy()
    for i in range(X.shape[0]):
        X[i, 0] = 0.0
        osc = Q @ X[i]
        span = (limits.q_upper[i] - limits.q_lower[i]) / max(np.ptp(osc), 1e-12)
        s = shrink * min(span, limits.v_max[i] / np.max(np.abs(V @ X[i])), limits.a_max[i] / np.max(np.abs(A @ X[i])))
        X[i, 1:] *= s
        osc = s * osc
        X[i, 0] = 0.5 * (limits.q_upper[i] + limits.q_lower[i]) - 0.5 * (osc.max() + osc.min())
    return X


def random_fourier(
    n: int, limits: Limits, base_frequency: float = 0.1, harmonics: int = 5, seed: int = 0
) -> FourierTrajectory:
    """A random Fourier trajectory (Gaussian coefficients) scaled into ``limits``."""
    rng = np.random.default_rng(seed)
    X = np.hstack([np.zeros((n, 1)), rng.standard_normal((n, 2 * harmonics))])
    return FourierTrajectory(base_frequency, _fit_into_limits(X, base_frequency, limits))


class _Conditioning:
    """log10 condition number of the base-column regressor on a time grid (base columns fixed
    from the initial trajectory plus random states, so the objective is comparable throughout)."""

    def __init__(self, model: ArticulatedModel, t: np.ndarray, f0: float, L: int, base: np.ndarray):
        self.pm = build_pin_model(model)
        self.n, self.t, self.f0, self.L = model.nq, t, f0, L
        self.base = base

    def traj(self, x: np.ndarray) -> FourierTrajectory:
        return FourierTrajectory(self.f0, x.reshape(self.n, 1 + 2 * self.L))

    def regressor(self, x: np.ndarray) -> np.ndarray:
        q, v, a = self.traj(x).evaluate(self.t)
        return identification_regressor(self.pm, q, v, a)

    def __call__(self, x: np.ndarray) -> float:
        return float(np.log10(np.linalg.cond(self.regressor(x)[:, self.base])))


def regressor_condition(model: ArticulatedModel, traj: FourierTrajectory, samples: int = 200) -> float:
    """Condition number of the base-column identification regressor over one period."""
    t = np.linspace(0, traj.period, samples, endpoint=False)
    pm = build_pin_model(model)
    W = identification_regressor(pm, *traj.evaluate(t))
    return float(np.linalg.cond(W[:, base_columns(W)]))


@dataclass(frozen=True, eq=False)
class ExcitationResult:
    """Designed trajectory, its condition number and the random start's, and solver status."""

    trajectory: FourierTrajectory
    condition: float
    initial_condition: float
    iterations: int
    message: str


def design_excitation(
    model: ArticulatedModel,
    limits: Limits | None = None,
    base_frequency: float = 0.1,
    harmonics: int = 5,
    samples: int = 100,
    max_iterations: int = 60,
    seed: int = 0,
) -> ExcitationResult:
    """Fourier excitation for ``model`` minimising cond(W_base) subject to ``limits``
    (default :func:`model_limits`) at ``samples`` grid points per period; SLSQP from a random
    feasible start.  A final rescale guarantees the limits on a dense grid."""
    if not 0 < base_frequency:
        raise DataError(f"base_frequency must be positive, got {base_frequency}")
    limits = limits or model_limits(model)
    n, L = model.nq, harmonics
    t = np.linspace(0, 1 / base_frequency, samples, endpoint=False)
    x0 = random_fourier(n, limits, base_frequency, L, seed).coefficients.ravel()
    pm = build_pin_model(model)
    rng = np.random.default_rng(seed)
    q_r = rng.uniform(limits.q_lower, limits.q_upper, (samples, n))
    W_rand = identification_regressor(pm, q_r, rng.uniform(-1, 1, (samples, n)) * limits.v_max,
                                      rng.uniform(-1, 1, (samples, n)) * limits.a_max)
    cost = _Conditioning(model, t, base_frequency, L, base_columns(W_rand))
    G, h = _linear_limits(t, base_frequency, L, n, limits)
    res = scipy.optimize.minimize(
        cost, x0, method="SLSQP",
        constraints=[{"type": "ineq", "fun": lambda x: h - G @ x, "jac": lambda x: -G}],
        options={"maxiter": max_iterations, "eps": 1e-6},
    )
    X = res.x.reshape(n, 1 + 2 * L)
    traj = FourierTrajectory(base_frequency, X)
    if limit_violation(traj, limits) > 0:
        traj = FourierTrajectory(base_frequency, _fit_into_limits(X, base_frequency, limits))
    return ExcitationResult(traj, regressor_condition(model, traj, samples), regressor_condition(
        model, cost.traj(x0), samples), int(res.nit), str(res.message))


def _linear_limits(t, f0, L, n, limits: Limits, margin: float = 0.98):
    """G x <= h for the limits at grid times t (x = all joints' coefficients, joint-major)."""
    Q, V, A = design_matrices(t, f0, L)
    rows, rhs = [], []
    for i in range(n):
        def block(M):
            out = np.zeros((M.shape[0], n * (1 + 2 * L)))
            out[:, i * (1 + 2 * L) : (i + 1) * (1 + 2 * L)] = M
            return out
        ones = np.ones(t.size)
        rows += [block(Q), block(-Q), block(V), block(-V), block(A), block(-A)]
        rhs += [ones * limits.q_upper[i], -ones * limits.q_lower[i], ones * margin * limits.v_max[i],
                ones * margin * limits.v_max[i], ones * margin * limits.a_max[i], ones * margin * limits.a_max[i]]
    return np.vstack(rows), np.concatenate(rhs)


def excitation_plan(model: ArticulatedModel, traj: FourierTrajectory, duration: float, rate_hz: float = 1000.0) -> Recording:
    """The trajectory sampled at ``rate_hz`` for ``duration`` [s] as a recording.csv-shaped plan:
    q, v and the nominal torque tau = ID_model(q, v, acc) (with the model's joint friction)."""
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    q, v, a = traj.evaluate(t)
    id_fn = inverse_dynamics(model)
    tau = np.array([id_fn(q[k], v[k], a[k]) for k in range(t.size)])
    return Recording(t, model.joint_names, q, v, tau)
