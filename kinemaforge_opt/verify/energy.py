"""Mechanical energy and the energy-balance residual of a recording under a model.

Energy is evaluated with Pinocchio (kinematics and gravity) plus the model's joint springs and
armature, so the same definition serves recorded states and Drake-simulated states:

    E(q, v) = ½ vᵀ M(q) v                          (M from Pinocchio's CRBA, armature included
                                                      like Drake's reflected inertia; pin 4.1's
                                                      computeKineticEnergy counts the armature of
                                                      some joint types only, so it is not used)
            − Σ_links m g·p_com                       (gravity potential, zero at p = 0)
            + ½ Σ_j k_j (q_j − rest_j)²              (joint springs)

The zero of the potential is arbitrary; only differences of E are meaningful.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..errors import DataError
from ..io.recording import Recording
from ..model import ArticulatedModel
from ..model.pinocchio import build_pin_model


def mechanical_energy(model: ArticulatedModel, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Kinetic + potential energy [J] of the states ``q``, ``v`` (T, n) -> (T,)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    v = np.atleast_2d(np.asarray(v, dtype=float))
    pm = build_pin_model(model)
    data = pm.createData()
    dyn = [j.dynamics for j in model.movable_joints]
    k = np.array([d.spring_stiffness for d in dyn])
    rest = np.array([d.spring_rest for d in dyn])
    E = np.empty(len(q))
    for i, (qi, vi) in enumerate(zip(q, v)):
        M = pin.crba(pm, data, qi)
        M = np.triu(M) + np.triu(M, 1).T
        E[i] = 0.5 * vi @ M @ vi + pin.computePotentialEnergy(pm, data, qi)
    return E + 0.5 * ((q - rest) ** 2 @ k)


def recorded_velocity(recording: Recording) -> np.ndarray:
    """(T, n) the recording's velocities, or central finite differences of q when it has none."""
    if recording.v is not None:
        return recording.v
    return np.gradient(recording.q, recording.t, axis=0)


def _integral(t: np.ndarray, power: np.ndarray) -> float:
    """Trapezoidal ∫ power dt [J] of a (T,) power signal."""
    return float(np.sum(0.5 * (power[1:] + power[:-1]) * np.diff(t)))


def energy_residual(model: ArticulatedModel, recording: Recording) -> float:
    """Dimensionless energy-balance residual of ``recording`` under ``model``.

    With E the mechanical energy above, P_app = τ·v the applied power and
    P_dis = −Σ_j (b_j v_j² + f_j |v_j|) the power of viscous damping and Coulomb friction,

        r = |ΔE − W_app − W_dis| / S,
        ΔE = E(t_end) − E(t_0),  W_app = ∫ P_app dt,  W_dis = ∫ P_dis dt  (trapezoid rule),
        S = max(|ΔE|, ∫|P_app| dt, ∫|P_dis| dt, max_t E_kin(t) − min_t E_kin(t)).

    The last term of S normalises a conservative motion (ΔE = W = 0) by the kinetic energy it
    exchanges.  r = 0 for a perfectly consistent model and data; r is 0 if nothing moves (S = 0).
    Velocities come from the recording, or from finite differences of q when it has none;
    τ is taken as zero when the recording has no ``tau`` columns.  Joints of the model missing
    from the recording raise :class:`DataError`.
    """
    rec = model_ordered(model, recording)
    v = recorded_velocity(rec)
    E = mechanical_energy(model, rec.q, v)
    E_kin = E - mechanical_energy(model, rec.q, np.zeros_like(v))
    tau = np.zeros_like(v) if rec.tau is None else rec.tau
    dyn = [j.dynamics for j in model.movable_joints]
    b = np.array([d.damping for d in dyn])
    f = np.array([d.coulomb for d in dyn])
    p_app = np.sum(tau * v, axis=1)
    p_dis = -(v**2 @ b + np.abs(v) @ f)
    dE = float(E[-1] - E[0])
    W_app, W_dis = _integral(rec.t, p_app), _integral(rec.t, p_dis)
    scale = max(abs(dE), _integral(rec.t, np.abs(p_app)), _integral(rec.t, np.abs(p_dis)), float(np.ptp(E_kin)))
    if scale <= 0.0:
        return 0.0
    return abs(dE - W_app - W_dis) / scale


def model_ordered(model: ArticulatedModel, recording: Recording) -> Recording:
    """The recording ordered as the model's q.  Raises :class:`DataError` naming the joints when
    the recording has a joint the model lacks or lacks one the model has."""
    extra = [n for n in recording.joint_names if n not in model.joint_names]
    if extra:
        raise DataError(
            f"recorded joint(s) {', '.join(map(repr, extra))} are not movable joints of model "
            f"{model.name!r}; its joints: {', '.join(map(repr, model.joint_names))}"
        )
    missing = [n for n in model.joint_names if n not in recording.joint_names]
    if missing:
        raise DataError(
            f"the recording has no q columns for joint(s) {', '.join(map(repr, missing))} of model "
            f"{model.name!r}; recorded joints: {', '.join(map(repr, recording.joint_names))}"
        )
    return recording.select(model.joint_names)
