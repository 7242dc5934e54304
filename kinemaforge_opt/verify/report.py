"""The verification of one model (and optionally one recording) as a JSON-ready dict + a plot.

With a recording: replay it (drift per horizon) and compute its energy residual.
Without one: a conservative check.  Damping and Coulomb friction are removed, the model starts
at mid-range (the middle of finite limits, else the spring rest position, else 0) with a
velocity of :data:`FREE_V0` per joint and is simulated on the continuous plant (limit contact
would dissipate energy); its energy must stay constant, so the report gives the largest energy
deviation and the energy residual of the simulated motion (both ~0 for a sound model).
"""

from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path

import numpy as np

from ..io.recording import Recording
from ..model import ArticulatedModel
from .drift import DEFAULT_HORIZONS_S, drift, drift_range, per_horizon, range_record
from .energy import energy_residual, model_ordered
from .plot import plot_trajectories
from .simulate import simulate

FREE_V0 = {"revolute": 1.0, "continuous": 1.0, "helical": 1.0, "prismatic": 0.1}
"""Initial velocity of the conservative check per joint type [rad/s or m/s]."""


def energy_text(residual: float | None, fmt: str = ".3g") -> str:
    """An energy residual as printed: ``fmt`` digits, or why there is none (None or NaN: no stretch
    of the motion is free of the joints' stops, so nothing could be booked)."""
    if residual is None or not np.isfinite(residual):
        return "n/a (no stretch of the motion free of the joints' stops to book)"
    return format(residual, fmt)


def range_text(ranges: dict, horizon: str) -> str:
    """ " (least–largest)" of ``ranges`` (a document's ``drift_range_m``) at ``horizon``, or "" when it
    has none there."""
    return f" ({ranges[horizon][0]:.3g}–{ranges[horizon][1]:.3g})" if horizon in ranges else ""


def verify_recording(
    model: ArticulatedModel,
    recording: Recording,
    plot_path: str | os.PathLike,
    horizons_s=DEFAULT_HORIZONS_S,
    discrete: bool = True,
    with_range: bool = False,
) -> dict:
    """Drift per horizon (keys are the horizons in s, as in ``reconstruction.json``), energy
    residual and timings; writes the recorded-vs-simulated plot to ``plot_path``.  with_range:
    also ``drift_range_m``, the drift's least and largest value per horizon with each moving
    link's mass and inertia scaled by 1 ± MASS_SHARE (:func:`.drift.drift_range`)."""
    start = time.perf_counter()
    rec = model_ordered(model, recording)
    report = drift(model, rec, horizons_s, discrete=discrete)
    residual = energy_residual(model, rec)
    plot_trajectories(plot_path, report.simulated, rec.t - rec.t[0], rec.q,
                      title=f"{model.name}: recorded vs Drake replay")
    extra = {}
    if with_range:
        spread = drift_range(model, rec, horizons_s, discrete=discrete)
        extra["drift_range_m"] = range_record(report.horizons_s, spread)
    return {
        "mode": "replay",
        "plant": "discrete_1ms" if discrete else "continuous",
        "recording_duration_s": float(rec.t[-1] - rec.t[0]),
        "drift_m": per_horizon(report.horizons_s, report.drift_m),
        "max_drift_m": per_horizon(report.horizons_s, report.max_drift_m),
        "joint_rms": per_horizon(report.horizons_s, report.joint_rms),
        "beyond_recording": per_horizon(report.horizons_s, report.beyond_recording, bool),
        "energy_residual": None if np.isnan(residual) else float(residual),
        "plot": Path(plot_path).name,
        **extra,
        "timing_s": {"replay": report.simulated.wall_time_s, "total": time.perf_counter() - start},
    }


def mid_range(model: ArticulatedModel) -> np.ndarray:
    """(n,) the middle of each joint's finite limits, else its spring rest position, else 0."""
    q = []
    for j in model.movable_joints:
        lim = j.limits
        if lim is not None and np.isfinite(lim.lower) and np.isfinite(lim.upper):
            q.append(0.5 * (lim.lower + lim.upper))
        else:
            q.append(j.dynamics.spring_rest)
    return np.array(q)


def verify_free(model: ArticulatedModel, plot_path: str | os.PathLike, duration_s: float = 10.0) -> dict:
    """The conservative check (module docs); writes the free-response plot to ``plot_path``."""
    start = time.perf_counter()
    conservative = model
    for j in model.movable_joints:
        d = dataclasses.replace(j.dynamics, damping=0.0, coulomb=0.0)
        conservative = conservative.with_joint(j.name, dynamics=d)
    q0 = mid_range(model)
    v0 = np.array([FREE_V0[j.type] for j in model.movable_joints])
    traj = simulate(conservative, q0, v0, duration_s, dt_out=0.01, discrete=False)
    sim_rec = Recording(traj.t, traj.joint_names, traj.q, traj.v)
    plot_trajectories(plot_path, traj, title=f"{model.name}: conservative free response (no damping, no friction)")
    return {
        "mode": "free_response",
        "plant": "continuous",
        "q0": q0.tolist(),
        "v0": v0.tolist(),
        "duration_s": float(duration_s),
        "energy_drift_J": float(np.max(np.abs(traj.energy - traj.energy[0]))),
        "energy_residual": float(energy_residual(conservative, sim_rec)),
        "drift_m": {},
        "plot": Path(plot_path).name,
        "timing_s": {"simulate": traj.wall_time_s, "total": time.perf_counter() - start},
    }
