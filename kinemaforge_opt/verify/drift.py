"""Drift: replay a recording in Drake and measure how far the model wanders from it.

The replay starts from the recording's first state (q, and v or finite differences of q) under
its recorded tau (:mod:`.simulate`).  At each horizon h (seconds after the first sample) the
simulated and reference link positions are compared in Cartesian space:

    drift_m(h) = max over moving links ℓ and points p ∈ {origin of ℓ, COM of ℓ} of
                 |T_world_ℓ(q_sim(t0+h)) p − T_world_ℓ(q_ref(t0+h)) p|      [m]

(forward kinematics by Pinocchio).  The reference q_ref(t) is the recording linearly
interpolated in time; **beyond the recording's end it is the recording's last q held constant**
(the object is assumed to come to rest where the recording leaves it) while the replay keeps the
last recorded tau applied.  A horizon past the end therefore measures whether the model settles
where the real object did.  ``joint_rms(h)`` is the RMS of q_sim − q_ref over all joints and
samples in [t0, t0+h] (rad and m mixed when joint types are mixed).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import DataError
from ..io.recording import Recording
from ..model import ArticulatedModel
from ..model.pinocchio import build_pin_model
from .energy import model_ordered, recorded_velocity
from .simulate import V_EPS, Trajectory, simulate_at

DEFAULT_HORIZONS_S = (1.0, 5.0, 10.0, 20.0, 50.0)


@dataclass(frozen=True, eq=False)
class DriftReport:
    """Drift of a replay against its recording.

    horizons_s: (H,) horizons [s] after the recording's first sample.
    drift_m: (H,) link-position error at each horizon [m] (module docs).
    max_drift_m: (H,) largest link-position error over [t0, t0+h] [m].
    joint_rms: (H,) joint-space RMS error over [t0, t0+h] [rad or m].
    beyond_recording: (H,) True where t0+h is after the last recorded sample (reference = rest).
    simulated: the replay, times relative to t0.  reference_q: (T, n) q_ref at ``simulated.t``.
    """

    horizons_s: np.ndarray
    drift_m: np.ndarray
    max_drift_m: np.ndarray
    joint_rms: np.ndarray
    beyond_recording: np.ndarray
    simulated: Trajectory
    reference_q: np.ndarray


def drift(
    model: ArticulatedModel,
    recording: Recording,
    horizons_s=DEFAULT_HORIZONS_S,
    discrete: bool = True,
    v_eps: float = V_EPS,
    forcing: Recording | None = None,
    v0: np.ndarray | None = None,
) -> DriftReport:
    """Replay ``recording`` with ``model`` up to the longest horizon and measure the drift.

    Output samples are the recording's own times, plus each horizon, plus a grid at the
    recording's median period beyond its end.  forcing: optional recording whose ``tau`` is
    applied instead of ``recording``'s (e.g. the applied force at a finer rate than the measured
    q); it must start at the recording's first time.  v0: (n,) initial velocity [rad/s or m/s]
    (default: the recording's v, or finite differences of q; see :func:`fit_initial_velocity`
    for coarse recordings).  Raises :class:`DataError` naming the
    joints when the recording's joints and the model's differ, or for non-positive horizons."""
    rec = model_ordered(model, recording)
    if forcing is not None:
        forcing = model_ordered(model, forcing)
        if forcing.tau is None:
            raise DataError("the forcing recording has no tau:<joint> columns")
        if abs(forcing.t[0] - rec.t[0]) > 1e-9:
            raise DataError(f"the forcing starts at t = {forcing.t[0]:.6g} s but the recording at "
                            f"t = {rec.t[0]:.6g} s; they must start together")
    else:
        forcing = rec if rec.tau is not None else None
    h = np.asarray(horizons_s, dtype=float).reshape(-1)
    if h.size == 0 or np.any(h <= 0) or not np.all(np.isfinite(h)):
        raise DataError(f"horizons_s must be positive finite seconds, got {list(horizons_s)}")
    t_rec = rec.t - rec.t[0]
    t_max = float(h.max())
    grid_beyond = np.arange(t_rec[-1], t_max, rec.dt)
    t_out = np.unique(np.concatenate([t_rec[t_rec <= t_max], h, grid_beyond, [t_max]]))
    v0 = recorded_velocity(rec)[0] if v0 is None else np.asarray(v0, dtype=float).reshape(model.nq)
    sim = simulate_at(model, rec.q[0], v0, t_out, forcing, discrete, v_eps)
    q_ref = np.column_stack([np.interp(t_out, t_rec, rec.q[:, j]) for j in range(model.nq)])

    err_m = _link_point_error(model, sim.q, q_ref)
    dq2 = np.sum((sim.q - q_ref) ** 2, axis=1)
    idx = np.searchsorted(t_out, h)
    drift_m = err_m[idx]
    max_drift = np.array([err_m[: i + 1].max() for i in idx])
    rms = np.array([np.sqrt(dq2[: i + 1].mean() / model.nq) for i in idx])
    return DriftReport(h, drift_m, max_drift, rms, h > t_rec[-1], sim, q_ref)


def per_horizon(horizons_s, values, cast=float) -> dict:
    """{horizon key ("1", "50"): cast(value)}, the verification documents' form of one value per
    horizon (``values`` in the order of ``horizons_s`` [s])."""
    return {f"{h:g}": cast(v) for h, v in zip(np.asarray(horizons_s, dtype=float).reshape(-1), values)}


MASS_SHARE = 0.01
"""How much :func:`drift_range` scales each moving link's mass and inertia by, up and down: a
reconstruction's masses come from its meshes and a density, or from forces at a camera's rate,
and are not known closer than this."""


def drift_range(
    model: ArticulatedModel,
    recording: Recording,
    horizons_s=DEFAULT_HORIZONS_S,
    discrete: bool = True,
    forcing: Recording | None = None,
    v0: np.ndarray | None = None,
    share: float = MASS_SHARE,
) -> np.ndarray:
    """(H, 2) the least and the largest :func:`drift` [m] at each horizon over the replays with one
    moving link's mass and rotational inertia scaled by 1 − ``share`` or 1 + ``share`` (its centre
    of mass kept), every other argument as :func:`drift` takes it.  A narrow range says the drift
    is the model's; a wide one that the motion is a knife edge, where a hair more or less mass
    decides the outcome, and the drift measures that hair, not the fit (protocol_laptop_1's lid,
    pushed just over its balance point: 1-s drift 0.051 m, 0.09-0.16 m with its mass ±1 %; at 50 s
    0.003-0.21 m).  Two replays per moving link."""
    runs = []
    for link in sorted({j.child for j in model.movable_joints}):
        inertial = model.link(link).inertial
        if inertial is None or inertial.mass <= 0:
            continue
        for factor in (1.0 - share, 1.0 + share):
            scaled = dataclasses.replace(inertial, mass=inertial.mass * factor, inertia=inertial.inertia * factor)
            runs.append(drift(model.with_link(link, inertial=scaled), recording, horizons_s, discrete,
                              forcing=forcing, v0=v0).drift_m)
    if not runs:
        h = np.asarray(horizons_s, dtype=float).reshape(-1)
        return np.full((h.size, 2), np.nan)
    runs = np.array(runs)
    return np.column_stack([runs.min(axis=0), runs.max(axis=0)])


def range_record(horizons_s, spread: np.ndarray) -> dict[str, list[float]]:
    """:func:`drift_range`'s (H, 2) result as the documents hold it: {horizon key: [least, largest]}."""
    return per_horizon(horizons_s, spread, lambda pair: [float(pair[0]), float(pair[1])])


INITIAL_WINDOW_S = 0.25
"""Span of the recording's start that :func:`fit_initial_velocity` matches [s]."""


def fit_initial_velocity(
    model: ArticulatedModel,
    recording: Recording,
    forcing: Recording | None = None,
    window_s: float = INITIAL_WINDOW_S,
    discrete: bool = True,
    iterations: int = 4,
) -> np.ndarray:
    """(n,) the initial velocity whose Drake replay best matches the recorded q over the first
    ``window_s`` seconds (at least 3 samples), by Gauss-Newton on finite-difference sensitivities
    (one replay per joint and iteration), started from the best of 1, ½ and 0 × the
    finite-difference estimate and kept
    within twice the largest finite-difference speed of each joint, and away from a stop the
    joint starts on.

    Why: at a visual rate (~10 Hz) the first finite difference of q is a poor velocity (a door
    pushed from rest shows ~0.5 rad/s), and the replay's drift would mostly measure that."""
    rec = model_ordered(model, recording)
    forcing = forcing if forcing is not None else (rec if rec.tau is not None else None)
    t_rec = rec.t - rec.t[0]
    k = max(3, int(np.searchsorted(t_rec, window_s, side="right")))
    t_fit, q_fit = t_rec[:k], rec.q[:k]
    v = recorded_velocity(rec)[0].copy()
    scale = np.maximum(np.abs(np.diff(rec.q[:k], axis=0)).max(axis=0) / max(t_fit[-1], 1e-9), 1e-3)
    # the answer stays within the speeds the recording shows (a joint pinned on a stop is
    # insensitive to v0, and an unbounded step would run off there)
    bound = 2.0 * np.abs(recorded_velocity(rec)).max(axis=0) + scale
    lower, upper = -bound, bound.copy()
    # a joint that starts on a stop (within 1 % of its range) cannot be moving into it: such a v0
    # only buys a bounce off the stop, which the fit would use to soak up model error
    for k, j in enumerate(model.movable_joints):
        if j.limits is not None and j.type != "continuous" and j.limits.upper > j.limits.lower:
            tol = 0.01 * (j.limits.upper - j.limits.lower)
            if rec.q[0, k] <= j.limits.lower + tol:
                lower[k] = 0.0
            if rec.q[0, k] >= j.limits.upper - tol:
                upper[k] = 0.0

    def residual(v0):
        return (simulate_at(model, rec.q[0], v0, t_fit, forcing, discrete).q - q_fit)[1:].ravel()

    # Gauss-Newton starts from the best of rest, half and all of the finite-difference speed: a
    # stop makes the residual non-smooth, and a start past it can sit in a false minimum
    # (protocol_drawer_1@s1, a drawer pulled from rest: started at its finite difference,
    # 0.17 m/s, the replayed drawer hit its open stop inside the window and the first step went
    # uphill; from rest the fit reaches 0.042 m/s and the 1-s drift falls from 0.069 to 0.004 m)
    starts = [np.clip(v * share, lower, upper) for share in (1.0, 0.5, 0.0)]
    v, r = min(((s, residual(s)) for s in starts), key=lambda sr: float(sr[1] @ sr[1]))
    for _ in range(iterations):
        J = np.empty((r.size, model.nq))
        for j in range(model.nq):
            dv = np.zeros(model.nq)
            dv[j] = 1e-3 * scale[j]
            J[:, j] = (residual(v + dv) - r) / dv[j]
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        v_new = np.clip(v + step, lower, upper)
        step = v_new - v
        r_new = residual(v_new)
        if r_new @ r_new >= r @ r:
            break
        v, r = v_new, r_new
        if np.all(np.abs(step) < 1e-4 * scale):
            break
    return v


def link_points(model: ArticulatedModel, q: np.ndarray) -> np.ndarray:
    """(T, P, 3) world positions [m] of the origin and COM of every moving link for q (T, n)."""
    pm = build_pin_model(model)
    data = pm.createData()
    moving = [j.child for j in model.joints if _moves(model, j.child)]
    frames = [(pm.getFrameId(name), _com(model, name)) for name in moving]
    out = np.empty((len(q), 2 * len(frames), 3))
    for i, qi in enumerate(np.asarray(q, dtype=float)):
        pin.framesForwardKinematics(pm, data, qi)
        for k, (fid, com) in enumerate(frames):
            T = data.oMf[fid]
            out[i, 2 * k] = T.translation
            out[i, 2 * k + 1] = T.act(com)
    return out


def _link_point_error(model: ArticulatedModel, q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """(T,) max over moving-link points of the distance between their positions under q_a and q_b."""
    d = np.linalg.norm(link_points(model, q_a) - link_points(model, q_b), axis=2)
    return d.max(axis=1)


def _moves(model: ArticulatedModel, link: str) -> bool:
    """True if a movable joint lies on the path from the root to ``link``."""
    by_child = {j.child: j for j in model.joints}
    while link in by_child:
        j = by_child[link]
        if j.is_movable:
            return True
        link = j.parent
    return False


def _com(model: ArticulatedModel, link: str) -> np.ndarray:
    inertial = model.link(link).inertial
    return np.zeros(3) if inertial is None else np.asarray(inertial.com, dtype=float)
