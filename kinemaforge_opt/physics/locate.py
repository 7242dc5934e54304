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
from scipy.signal import savgol_coeffs, savgol_filter

from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..model.pinocchio import inverse_dynamics
from ..nlp.joint_space import GAP_INTERVALS, stretches

THRESHOLD_SIGMA = 3.0  # a window is flagged when its running RMS exceeds this many noise sigmas
# Savitzky–Golay window of the derivatives [s] ...
DERIVATIVE_WINDOW_S = 0.15
# ... at most this over the motion's angular frequency ω (:func:`motion_window`): a cubic
# fit's acceleration of a sinusoid is low by ≈ 0.08 (ω h)² for a half-window h, so ω h ≤ 0.5 keeps
# that bias under 2 % (a pendulum swinging at 2.5 Hz under a 0.15-s window: 9 %, larger than the
# damping force the pre-screen looks for).
DERIVATIVE_HALF_WINDOW_RAD = 0.5


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


def block_means(a: np.ndarray | None, k: int, t: np.ndarray | None = None) -> np.ndarray | None:
    """Means of (T, ...) ``a`` over consecutive blocks of ``k`` samples (a last incomplete block
    is dropped); None stays None.  With the sample times ``t`` (T,), no block straddles a gap in
    the recording: each stretch between gaps (:func:`~kinemaforge_opt.nlp.joint_space.stretches`)
    is averaged on its own (a mean across a gap is a sample of nothing recorded), and a gap stays
    a gap at the blocks' rate: the first blocks after one are dropped until the hole is longer
    than GAP_INTERVALS block intervals (a 0.12-s hole left out around a drawer's impact on its
    stop is 7 intervals at 60 Hz but 3.6 of the 30-Hz search grid's, whose fit then carried the
    dynamics through the impact)."""
    if a is None or k <= 1:
        return a
    if t is not None:
        least_hole = GAP_INTERVALS * k * float(np.median(np.diff(t))) * 1.01  # margin: blocks' median interval
        parts, last = [], None
        for i, j in stretches(t):
            times = block_means(t[i:j], k)
            skip = 0 if last is None else int(np.sum(times - last <= least_hole))
            parts.append(block_means(a[i:j], k)[skip:])
            last = times[-1] if times.size > skip else last
        return np.concatenate(parts) if parts else a[:0]
    T = (len(a) // k) * k
    return a[:T].reshape(T // k, k, *a.shape[1:]).mean(axis=1)


def running_rms(x: np.ndarray, w: int) -> np.ndarray:
    """(T,) the RMS of ``x`` (T,) over a centred window of ``w`` samples (zeros beyond the ends)."""
    return np.sqrt(np.convolve(x**2, np.ones(w) / w, mode="same"))


def _window_samples(dt: float, window_s: float | None) -> int:
    """The odd Savitzky–Golay window [samples] of ``window_s`` (default DERIVATIVE_WINDOW_S) at
    sample period ``dt`` [s], at least 7."""
    return max(7, int(round((window_s or DERIVATIVE_WINDOW_S) / dt)) | 1)


def velocity_noise(sigma_q: np.ndarray, dt: float, window_s: float | None = None, block: int = 1) -> np.ndarray:
    """(n,) standard deviation [rad/s or m/s] of :func:`smooth_derivatives`' velocity under white
    position noise ``sigma_q`` (n,) sampled every ``dt`` [s], inside a stretch: the derivative
    filter's gain (the norm of its coefficients), for means over blocks of ``block`` samples (the
    search grid, :func:`block_means`) the norm of the block-averaged filter."""
    c = savgol_coeffs(_window_samples(dt, window_s), 3, deriv=1, delta=dt)
    c = np.convolve(c, np.ones(block) / block)
    return np.asarray(sigma_q, dtype=float) * float(np.linalg.norm(c))


def smooth_derivatives(rec: Recording, window_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Savitzky–Golay (cubic) q, v, a (each (T, n)) from the recorded q; window ``window_s``
    (default DERIVATIVE_WINDOW_S), at least 7 samples.  Each stretch between gaps in the recording
    (:func:`~kinemaforge_opt.nlp.joint_space.recording_gaps`) on its own: a window across a gap
    reads its jump as motion."""
    dt = rec.dt
    w = _window_samples(dt, window_s)
    q, v, a = np.array(rec.q, dtype=float), np.zeros_like(rec.q), np.zeros_like(rec.q)
    for i, j in stretches(rec.t):
        ww = min(w, (j - i) - 1 + (j - i) % 2)  # the longest odd window the stretch holds
        if ww < 5:  # too short for a cubic: kept as recorded, at rest
            continue
        q[i:j] = savgol_filter(rec.q[i:j], ww, 3, axis=0)
        v[i:j] = savgol_filter(rec.q[i:j], ww, 3, deriv=1, delta=dt, axis=0)
        a[i:j] = savgol_filter(rec.q[i:j], ww, 3, deriv=2, delta=dt, axis=0)
    return q, v, a


def motion_window(rec: Recording) -> float:
    """Savitzky–Golay window [s] for ``rec``'s derivatives: DERIVATIVE_WINDOW_S, shortened so that
    its half-window is at most DERIVATIVE_HALF_WINDOW_RAD over the fastest joint's angular
    frequency RMS(v) / RMS(q − mean q) (a swing's ω; a slow push with a large offset reads low,
    which keeps the default).  Velocities, not accelerations: a second derivative's noise would
    read as a fast motion."""
    q, v, _ = smooth_derivatives(rec)
    spread = np.sqrt(np.mean((q - q.mean(axis=0)) ** 2, axis=0))
    speed = np.sqrt(np.mean(v**2, axis=0))
    omega = float(np.max(np.where(spread > 0, speed / np.maximum(spread, 1e-300), 0.0)))
    return min(DERIVATIVE_WINDOW_S, 2.0 * DERIVATIVE_HALF_WINDOW_RAD / omega) if omega > 0 else DERIVATIVE_WINDOW_S


def inverse_dynamics_residual(model: ArticulatedModel, rec: Recording, window_s: float | None = None,
                              block: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(residual force (T, n) [N·m or N], q, v, a) of ``model`` along ``rec``, derivatives under a
    ``window_s`` window (:func:`smooth_derivatives`); with ``block`` > 1, each as its means over
    blocks of that many samples (on a search grid made of such means).  Where a joint is held on
    its stop (``rec.held``) its residual is 0: the stop's force, which the model declares."""
    q, v, a = smooth_derivatives(rec, window_s)
    tau = rec.tau if rec.tau is not None else np.zeros_like(q)
    r = inverse_dynamics(model, q, v, a) - tau - model.passive_forces(q, v)
    if rec.held is not None:
        r[rec.held] = 0.0
    return tuple(block_means(x, block, rec.t) for x in (r, q, v, a))


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
        windows = _windows(rec.t, running_rms(err[:, k], w) > THRESHOLD_SIGMA, min_gap_s=0.5)
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
