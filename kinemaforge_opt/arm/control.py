"""Model-based control on the MuJoCo "real" arm: inverse/forward-dynamics callables from an
ArticulatedModel and a computed-torque tracking run that reports the tracking error.

Callables take one sample: ``tau = id(q, v, a)`` and ``a = fd(q, v, tau)`` with (n,) arrays in
the model's joint order [rad, rad/s, rad/s², N·m].
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import DataError, require_shape
from ..model import ArticulatedModel
from ..model.pinocchio import build_pin_model
from .mujoco_real import Controller, RealArm, SensorNoise, run_controller

InverseDynamics = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
ForwardDynamics = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _joint_force_terms(model: ArticulatedModel):
    d = [j.dynamics for j in model.movable_joints]
    arr = lambda f: np.array([getattr(x, f) for x in d])  # noqa: E731
    return arr("damping"), arr("coulomb"), arr("spring_stiffness"), arr("spring_rest")


def _passive_torque(model: ArticulatedModel):
    """(q, v) -> torque the joints' damping, Coulomb friction and springs oppose [N·m] (n,)."""
    b, f, k, rest = _joint_force_terms(model)
    return lambda q, v: b * v + f * np.sign(v) + k * (q - rest)


def inverse_dynamics(model: ArticulatedModel) -> InverseDynamics:
    """tau = RNEA(q, v, a) (armature included) + damping·v + coulomb·sign(v) + k (q - rest)."""
    pm = build_pin_model(model)
    data = pm.createData()
    passive = _passive_torque(model)
    return lambda q, v, a: pin.rnea(pm, data, q, v, a) + passive(q, v)


def forward_dynamics(model: ArticulatedModel) -> ForwardDynamics:
    """a = ABA(q, v, tau - damping·v - coulomb·sign(v) - k (q - rest)) (armature included)."""
    pm = build_pin_model(model)
    data = pm.createData()
    passive = _passive_torque(model)
    return lambda q, v, tau: pin.aba(pm, data, q, v, tau - passive(q, v))


def computed_torque(
    id_fn: InverseDynamics, q_d: np.ndarray, v_d: np.ndarray, a_d: np.ndarray, kp: np.ndarray, kd: np.ndarray
) -> Controller:
    """tau = id(q, v, a_d + kp (q_d - q) + kd (v_d - v)) at sample k; desired (T, n), gains (n,) [1/s², 1/s]."""
    kp, kd = np.asarray(kp, dtype=float), np.asarray(kd, dtype=float)
    return lambda t, q, v, k: id_fn(q, v, a_d[k] + kp * (q_d[k] - q) + kd * (v_d[k] - v))


@dataclass(frozen=True, eq=False)
class TrackingResult:
    """Tracking run: t (T,) [s], q_des and q (true, T × n) [rad]; tau applied (T, n) [N·m]."""

    t: np.ndarray
    q_des: np.ndarray
    q: np.ndarray
    tau: np.ndarray

    @property
    def error(self) -> np.ndarray:
        """q - q_des (T, n) [rad]."""
        return self.q - self.q_des

    @property
    def rms(self) -> np.ndarray:
        """Per-joint RMS tracking error (n,) [rad]."""
        return np.sqrt(np.mean(self.error**2, axis=0))

    @property
    def max_abs(self) -> np.ndarray:
        """Per-joint maximum |error| (n,) [rad]."""
        return np.max(np.abs(self.error), axis=0)


def track(
    arm: RealArm,
    t: np.ndarray,
    q_d: np.ndarray,
    v_d: np.ndarray,
    a_d: np.ndarray,
    id_fn: InverseDynamics,
    kp: float | np.ndarray = 100.0,
    kd: float | np.ndarray = 20.0,
    noise: SensorNoise | None = None,
    seed: int = 0,
) -> TrackingResult:
    """Computed-torque tracking of (q_d, v_d, a_d) (T, n) at times t (T,) [s] on ``arm``, starting
    on the trajectory.  kp [1/s²], kd [1/s]: outer-loop gains (scalars or (n,))."""
    n = len(arm.joint_names)
    for name, x in (("q_d", q_d), ("v_d", v_d), ("a_d", a_d)):
        require_shape(name, x, (np.size(t), n), "tracking reference")
    kp, kd = np.broadcast_to(kp, (n,)), np.broadcast_to(kd, (n,))
    if np.any(kp <= 0) or np.any(kd <= 0):
        raise DataError("computed-torque gains kp and kd must be positive")
    _, true = run_controller(arm, t, q_d[0], v_d[0], computed_torque(id_fn, q_d, v_d, a_d, kp, kd), noise, seed)
    return TrackingResult(true.t, np.asarray(q_d), true.q, true.tau)
