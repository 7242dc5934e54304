"""Drake verification: simulate a model, replay a recording, measure drift and energy balance.

The only package that imports pydrake.  Public API::

    simulate(model, q0, v0, duration_s, tau=None, dt_out=0.01, discrete=True) -> Trajectory
    drift(model, recording, horizons_s=(1, 5, 10, 20, 50)) -> DriftReport
    energy_residual(model, recording) -> float
    mechanical_energy(model, q, v) -> (T,) energy [J]
    build_plant(model, discrete=True) -> DrakePlant
"""

from .drift import DEFAULT_HORIZONS_S, DriftReport, drift, link_points
from .energy import energy_residual, mechanical_energy
from .plant import DISCRETE_TIME_STEP_S, DrakePlant, build_plant
from .simulate import V_EPS, Trajectory, simulate, simulate_at

__all__ = [
    "DEFAULT_HORIZONS_S",
    "DISCRETE_TIME_STEP_S",
    "V_EPS",
    "DrakePlant",
    "DriftReport",
    "Trajectory",
    "build_plant",
    "drift",
    "energy_residual",
    "link_points",
    "mechanical_energy",
    "simulate",
    "simulate_at",
]
