"""Locate a mismatch: which joint, which time windows, which region of state carry residual above
the noise level.

Two residuals of a nominal fit are used (both from the recording alone):
- the output error e = q_fit - q_rec of the collocation fit, against the encoder noise sigma_q;
- the inverse-dynamics residual force r = M(q) a + h(q, v) - tau_applied - tau_passive, with v and a
  from a Savitzky–Golay fit to q, whose noise level is taken from its own high-frequency part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..model.pinocchio import inverse_dynamics

THRESHOLD_SIGMA = 3.0  # a window is flagged when its running RMS exceeds this many noise sigmas


@dataclass(frozen=True)
class JointMismatch:
    """Where joint ``joint`` disagrees with the model.

    windows_s: [(t_start, t_end)] with output error above THRESHOLD_SIGMA × noise [s].
    share_of_residual: this joint's share of the total normalised squared output error.
    regions: state regions (name -> mean |residual force| / noise there), e.g. "v>0", "v<0",
    "low speed", "q low third", "q high third", "near limit".
    """

    joint: str
    windows_s: tuple[tuple[float, float], ...]
    share_of_residual: float
    rms_over_noise: float
    regions: dict[str, float]


def smooth_derivatives(rec: Recording, window_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Savitzky–Golay (cubic) q, v, a (each (T, n)) from the recorded q; window ≈ 0.15 s, at least
    7 samples."""
    dt = rec.dt
    w = max(7, int(round((window_s or 0.15) / dt)) | 1)
    w = min(w, rec.t.size - 1 + rec.t.size % 2)  # the longest odd window the recording holds
    q = savgol_filter(rec.q, w, 3, axis=0)
    v = savgol_filter(rec.q, w, 3, deriv=1, delta=dt, axis=0)
    a = savgol_filter(rec.q, w, 3, deriv=2, delta=dt, axis=0)
    return q, v, a


def inverse_dynamics_residual(model: ArticulatedModel, rec: Recording) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(residual force (T, n) [N·m or N], q, v, a) of ``model`` along ``rec``."""
    q, v, a = smooth_derivatives(rec)
    tau = rec.tau if rec.tau is not None else np.zeros_like(q)
    passive = np.stack([j.dynamics.passive_force(q[:, k], v[:, k]) for k, j in enumerate(model.movable_joints)], axis=1)
    return inverse_dynamics(model, q, v, a) - tau - passive, q, v, a


def _windows(t: np.ndarray, flagged: np.ndarray, min_gap_s: float) -> tuple[tuple[float, float], ...]:
    out = []
    idx = np.flatnonzero(flagged)
    if idx.size == 0:
        return ()
    start = prev = idx[0]
    for i in idx[1:]:
        if t[i] - t[prev] > min_gap_s:
            out.append((float(t[start]), float(t[prev])))
            start = i
        prev = i
    out.append((float(t[start]), float(t[prev])))
    return tuple(out)


def locate(model: ArticulatedModel, rec: Recording, q_fit: np.ndarray, sigma_q: np.ndarray) -> tuple[JointMismatch, ...]:
    """Per-joint mismatch of a nominal fit ``q_fit`` (T, n) to ``rec`` (noise ``sigma_q`` (n,))."""
    err = (q_fit - rec.q) / sigma_q
    total = float(np.sum(err**2))
    w = max(3, int(round(0.25 / rec.dt)))
    kernel = np.ones(w) / w
    force, q, v, _ = inverse_dynamics_residual(model, rec)
    out = []
    for k, j in enumerate(model.joint_names):
        running = np.sqrt(np.convolve(err[:, k] ** 2, kernel, mode="same"))
        windows = _windows(rec.t, running > THRESHOLD_SIGMA, min_gap_s=0.5)
        # Noise of the residual force: its high-frequency part (difference from a smoothed copy).
        r = force[:, k]
        smooth = np.convolve(r, kernel, mode="same")
        noise = max(1.4826 * np.median(np.abs(r - smooth)), 1e-12)
        speed = np.abs(v[:, k])
        low = speed < 0.1 * max(np.sqrt(np.mean(v[:, k] ** 2)), 1e-12)
        lo3, hi3 = np.quantile(q[:, k], [1 / 3, 2 / 3])
        masks = {"v>0": (v[:, k] > 0) & ~low, "v<0": (v[:, k] < 0) & ~low, "low speed": low,
                 "q low third": q[:, k] <= lo3, "q high third": q[:, k] >= hi3}
        lim = model.joint(j).limits
        if lim is not None and np.isfinite(lim.lower) and np.isfinite(lim.upper):
            margin = 0.05 * (lim.upper - lim.lower)
            masks["near limit"] = (q[:, k] < lim.lower + margin) | (q[:, k] > lim.upper - margin)
        regions = {name: float(np.mean(smooth[m]) / noise) for name, m in masks.items() if m.sum() >= 5}
        out.append(
            JointMismatch(
                joint=j, windows_s=windows,
                share_of_residual=float(np.sum(err[:, k] ** 2) / total) if total > 0 else 0.0,
                rms_over_noise=float(np.sqrt(np.mean(err[:, k] ** 2))),
                regions=regions,
            )
        )
    return tuple(out)
