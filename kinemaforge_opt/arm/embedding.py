"""Embedding a calibration in model-based control code: a calibrated ``pin.Model`` plus
inverse- and forward-dynamics callables that include the joint friction.

    from kinemaforge_opt.arm.embedding import embed
    dyn = embed(calibrate(nominal, recording, method="inverse_dynamics"))
    tau = dyn.inverse_dynamics(q, v, a)            # (n,) arrays [rad, rad/s, rad/s²] -> [N·m]
    a = dyn.forward_dynamics(q, v, tau)

Both callables use the joint law of :meth:`kinemaforge_opt.model.JointDynamics.passive_force`
(viscous, Coulomb with the smooth sign tanh(v / V_SMOOTH), Stribeck, spring, bias, drag) — the
law the inverse-dynamics calibration fits — and the armature held by the ``pin.Model``:

    tau = RNEA(q, v, a) − passive(q, v),      a = ABA(q, v, tau + passive(q, v)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..calibration import Calibration
from ..model import ArticulatedModel
from ..model.pinocchio import build_pin_model
from .control import ForwardDynamics, InverseDynamics


@dataclass(frozen=True, eq=False)
class EmbeddedDynamics:
    """A calibrated model ready for a controller: ``pin_model`` (inertias and armature; q/v in
    ``joint_names`` order), ``inverse_dynamics(q, v, a) -> tau`` and
    ``forward_dynamics(q, v, tau) -> a`` for one sample, (n,) arrays, joint friction included."""

    model: ArticulatedModel
    pin_model: pin.Model
    joint_names: tuple[str, ...]
    inverse_dynamics: InverseDynamics
    forward_dynamics: ForwardDynamics


def passive_torque(model: ArticulatedModel):
    """(q, v) (n,) -> generalised passive force of the joints (n,) [N·m or N] (acts on the joints;
    the motors must supply its negative)."""
    dyn = [j.dynamics for j in model.movable_joints]
    return lambda q, v: np.array([d.passive_force(qi, vi) for d, qi, vi in zip(dyn, q, v)], dtype=float)


def embed(source: Calibration | ArticulatedModel) -> EmbeddedDynamics:
    """Calibrated Pinocchio model and ID/FD callables of a :class:`Calibration` (its ``model``)
    or of an :class:`ArticulatedModel`."""
    model = source.model if isinstance(source, Calibration) else source
    pm = build_pin_model(model)
    id_data, fd_data = pm.createData(), pm.createData()
    passive = passive_torque(model)

    def inverse_dynamics(q, v, a):
        return pin.rnea(pm, id_data, q, v, a) - passive(q, v)

    def forward_dynamics(q, v, tau):
        return pin.aba(pm, fd_data, q, v, np.asarray(tau, dtype=float) + passive(q, v))

    return EmbeddedDynamics(model, pm, model.joint_names, inverse_dynamics, forward_dynamics)
