"""Held-out prediction for the baselines: the nominal model (optionally with its inertia scaled)
plus a fitted passive force law, simulated from the first state of a recording under its recorded
forcing — the same protocol as :func:`kinemaforge_opt.physics.diagnose.diagnose` uses."""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..calibration import apply_parameters
from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..physics.locate import smooth_derivatives

ForceLaw = Callable[[float, float], float]


def augmented(model: ArticulatedModel, inertia_ratio: dict[str, float]) -> ArticulatedModel:
    """``model`` with the child link of each joint in ``inertia_ratio`` scaled by its ratio."""
    values = {f"{model.joint(j).child}.inertia_ratio": np.array([r]) for j, r in inertia_ratio.items()}
    return apply_parameters(model, values)


def predict(model: ArticulatedModel, rec: Recording, extra: dict[str, ForceLaw] | None = None) -> np.ndarray:
    """q (T, n) of ``model`` + the per-joint ``extra`` force laws f(q, v), simulated over ``rec``
    from its smoothed first state with its recorded tau (Pinocchio ABA, LSODA)."""
    import pinocchio as pin
    from scipy.integrate import solve_ivp

    from ..model.pinocchio import build_pin_model

    pm = build_pin_model(model)
    pd = pm.createData()
    joints = model.movable_joints
    n = len(joints)
    laws = [(extra or {}).get(j.name) for j in joints]
    q0, v0, _ = smooth_derivatives(rec)
    tau = rec.tau if rec.tau is not None else np.zeros((rec.t.size, n))

    def rhs(t, x):
        q, v = x[:n], x[n:]
        u = np.array([np.interp(t, rec.t, tau[:, k]) for k in range(n)])
        u += [j.dynamics.passive_force(q[k], v[k]) + (f(q[k], v[k]) if f else 0.0)
              for k, (j, f) in enumerate(zip(joints, laws))]
        return np.concatenate([v, pin.aba(pm, pd, q, v, u)])

    sol = solve_ivp(rhs, (rec.t[0], rec.t[-1]), np.concatenate([q0[0], v0[0]]), t_eval=rec.t,
                    method="LSODA", rtol=1e-7, atol=1e-9)
    q = sol.y[:n].T
    if q.shape[0] < rec.t.size:  # integration stopped early: hold the last state
        q = np.vstack([q, np.repeat(q[-1:], rec.t.size - q.shape[0], axis=0)])
    return q
