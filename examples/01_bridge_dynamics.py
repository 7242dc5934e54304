"""01 — Pinocchio's algorithms as CasADi functions of the model's free parameters.

Builds the laptop's dynamics with the hinge axis and the lid's inertia free, evaluates ABA, the
energies and the lid pose, and takes an exact derivative of the acceleration with respect to the
lid's inertial parameters — the building block of every NLP in kinemaforge_opt.

    .venv/bin/python examples/01_bridge_dynamics.py
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np

from kinemaforge_opt import read_urdf
from kinemaforge_opt.symbolic import build_dynamics

MODEL = Path(__file__).resolve().parents[1] / "models" / "laptop" / "laptop.urdf"


def main() -> None:
    model = read_urdf(MODEL)
    dyn = build_dynamics(model, free=["hinge.axis", "lid.inertia"])
    q, v, tau = np.array([1.0]), np.array([0.5]), np.array([0.0])
    print(f"theta = {[p.name for p in dyn.parameters]} ({dyn.theta0.size} values)")
    print(f"ABA: a = {float(dyn.aba(q, v, tau, dyn.theta0)):.4f} rad/s² (lid falling under gravity)")
    print(f"kinetic {float(dyn.kinetic_energy(q, v, dyn.theta0)):.5f} J, potential {float(dyn.potential_energy(q, dyn.theta0)):.5f} J")
    T_world_lid = dyn.poses(q)[dyn.link_names.index("lid")]
    print(f"T_world_lid translation {np.round(T_world_lid[:3, 3], 4)} m")
    theta = ca.SX.sym("theta", dyn.theta0.size)
    da_dtheta = ca.Function("da_dtheta", [theta], [ca.jacobian(dyn.aba(q, v, tau, theta), theta)])
    J = da_dtheta(dyn.theta0).full()[0]
    lid = dyn.parameter("lid.inertia").slice
    print(f"d a / d [m, m·c_x] of the lid = {np.round(J[lid][:2], 3)} (exact, by CasADi)")


if __name__ == "__main__":
    main()
