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
from ..stops import stop_impacts


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


STOP_TOLERANCE = 0.01
"""A joint counts as on a position stop within this fraction of its range (upper − lower) of
either limit (or beyond it).  Dimensionless, the same for every joint; 0 would miss a stop that a
spline through coarse samples approaches without reaching."""


def at_stop(model: ArticulatedModel, q: np.ndarray, tolerance: float = STOP_TOLERANCE) -> np.ndarray:
    """(T, n) True where a movable joint of ``model`` with finite position limits is within
    ``tolerance`` × its range of a limit, or past it, at the states ``q`` (T, n) [rad or m]."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    out = np.zeros(q.shape, dtype=bool)
    for k, j in enumerate(model.movable_joints):
        lim = j.limits
        if lim is None or not (np.isfinite(lim.lower) and np.isfinite(lim.upper)):
            continue
        margin = tolerance * (lim.upper - lim.lower)
        out[:, k] = (q[:, k] <= lim.lower + margin) | (q[:, k] >= lim.upper - margin)
    return out


def _joint_inertias(model: ArticulatedModel, q: np.ndarray) -> np.ndarray:
    """(T, n) M_jj(q) [kg·m² or kg]: each joint's own diagonal entry of the mass matrix at the
    states ``q`` (T, n); ½ M_jj v_j² is the kinetic energy of motion along that joint alone (what
    an impact on its stop can take out, at most, when the others do not move)."""
    pm = build_pin_model(model)
    data = pm.createData()
    return np.array([np.diag(pin.crba(pm, data, qi)) for qi in q]).reshape(q.shape)


def free_segments(model: ArticulatedModel, q: np.ndarray, v: np.ndarray | None = None,
                  tolerance: float = STOP_TOLERANCE, t: np.ndarray | None = None,
                  sample_t: np.ndarray | None = None) -> list[tuple[int, int]]:
    """Maximal runs [a, b] (sample indices, b > a) of the samples ``q``, ``v`` (T, n) in which no
    interval may hold a stop's impact: an interval is out when, at either of its ends, a joint is
    on a stop (:func:`at_stop`) while moving *into* it (towards the limit it is at) with more than
    ``tolerance`` × the motion's kinetic-energy span (max − min over the samples of
    Σ_j ½ M_jj v_j², :func:`_joint_inertias`), or strictly past a limit (a compliant stop pressed
    in stores energy and gives it back as the joint springs out).  A stop's force does work only
    while the joint moves into it or, pressed in, back out: a joint that rests on its stop (a
    closed door while the other one swings) or leaves it (a door pushed open from shut) takes
    none.  Cutting a push's start out of the books left them to begin mid-push, where a spline
    through camera-rate samples is least accurate (protocol_cabinet_1@s1's reconstruction:
    residual 0.150 with the departure cut, 0.015 with it kept).  Without ``v``, finite
    differences of q.

    t (T,) [s] and sample_t (S,) [s]: when q, v interpolate coarser measured samples at the times
    ``sample_t``, every measured interval that holds an interval out, and its two neighbours,
    are out too: the impact happened somewhere between two samples, and the interpolant's error
    spreads to the next knots (a cubic spline's by a factor ≈ 0.27 per knot).  A joint on a stop
    then also counts as moving along it at its :func:`arrival_speed`: the spline turns smoothly
    where the joint was stopped short, so its own speed at the stop is about nil.  And a joint
    past a limit counts only if it arrived there with that much energy, or if a measured sample
    of its interval is past the limit by more than ``tolerance`` × the range: the spline through
    the samples of a joint resting on its stop (or leaving it) rings a hair past the limit next to
    samples where something moves (two parts pushed one after the other at ~3 Hz: the resting
    one's ringing cut the first push out of the books, the true model read 0.09 to 0.16; Table 1's
    two-part runs, true model 0.037 → 0.005), while measured samples far past it are motion the
    model cannot make (protocol_moving_cabinet's second door, tracked 0.21 rad past its closed
    limit for 2.3 s: 0.84 with those spans in the books, 0.16 without).  A measured interval that
    holds a stop impact of the samples themselves (:func:`~kinemaforge_opt.stops.stop_impacts`) is
    out too, with its neighbours, whatever the model's limits: by the limits alone, a
    reconstruction of protocol_refrigerator_1@s1 kept a door's impact in its books (one segment
    over both doors' pushes where the true model's books have two)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    stop = at_stop(model, q, tolerance)
    past = at_stop(model, q, -1e-6)  # beyond a limit (by more than numerical jitter)
    if stop.any():
        v = np.gradient(q, axis=0) if v is None else np.atleast_2d(np.asarray(v, dtype=float))
        half_m = 0.5 * _joint_inertias(model, q)  # kinetic energy per (speed along the joint)²
        floor = tolerance * (float(np.ptp((half_m * v**2).sum(axis=1))) if len(q) > 1 else 0.0)
        into = _speed_into_limit(model, q, v)
        if sample_t is not None and t is not None and len(sample_t) > 1:
            arrived = arrival_speed(model, q, t, sample_t)
            into = np.maximum(into, arrived)
            # a spline through a joint resting on its stop, or leaving it, rings a hair past the
            # limit: past it counts where the joint arrived with energy, or where a measured sample
            # is past it by more than the tolerance (the measured motion leaves the model's range)
            past &= (half_m * arrived**2 > floor) | _measured_past(model, q, t, sample_t, tolerance)
        stop &= half_m * into**2 > floor
    hit = (stop | past).any(axis=1)
    free = ~(hit[1:] | hit[:-1])  # interval i: samples i -> i + 1
    if sample_t is not None and t is not None and len(sample_t) > 1:
        k = _interval_of(t[:-1], sample_t)  # the measured interval holding each interval of q
        # an impact the measured samples show is out, wherever the model puts its limits
        for e in stop_impacts(sample_t, _at_samples(q, t, sample_t)):
            free &= k != e.i - 1
        # q, v interpolate coarser measured samples: an impact flagged in one measured interval
        # happened somewhere in it, and the interpolant's error spreads to its neighbours
        bad = np.zeros(len(sample_t) + 1, dtype=bool)
        for j in np.unique(k[~free]):
            bad[max(j - 1, 0): j + 2] = True
        free &= ~bad[k]
    out, i = [], 0
    while i < free.size:
        if free[i]:
            k = i
            while k < free.size and free[k]:
                k += 1
            out.append((i, k))
            i = k
        else:
            i += 1
    return out


def _at_samples(q: np.ndarray, t: np.ndarray, sample_t: np.ndarray) -> np.ndarray:
    """(S, n) the motion q (T, n) at times t (T,) [s] interpolated at the measured times ``sample_t`` (S,)."""
    return np.array([np.interp(sample_t, t, column) for column in q.T]).T.reshape(len(sample_t), q.shape[1])


def _interval_of(t: np.ndarray, sample_t: np.ndarray) -> np.ndarray:
    """(T,) index of the measured interval [sample_t[k], sample_t[k + 1]) holding each time of t (T,)."""
    return np.clip(np.searchsorted(sample_t, t, side="right") - 1, 0, len(sample_t) - 2)


def _measured_past(model: ArticulatedModel, q: np.ndarray, t: np.ndarray, sample_t: np.ndarray,
                   tolerance: float) -> np.ndarray:
    """(T, n) True at each sample of q (T, n) at times t (T,) [s] whose measured interval (between
    the measured times ``sample_t`` (S,)) has an end past a limit by more than ``tolerance`` × the
    joint's range: a measured excursion, not the interpolant's."""
    past = at_stop(model, _at_samples(q, t, sample_t), -tolerance)
    k = _interval_of(t, sample_t)
    return past[k] | past[k + 1]


def _towards_nearer_limit(model: ArticulatedModel, q: np.ndarray) -> np.ndarray:
    """(T, n) +1 where a joint at ``q`` (T, n) is nearer its upper limit, −1 nearer its lower one,
    0 for a joint without finite limits: a velocity times it is positive towards the nearer stop."""
    out = np.zeros_like(q)
    for j, joint in enumerate(model.movable_joints):
        lim = joint.limits
        if lim is not None and np.isfinite(lim.lower) and np.isfinite(lim.upper):
            out[:, j] = np.where(q[:, j] > 0.5 * (lim.lower + lim.upper), 1.0, -1.0)
    return out


def _speed_into_limit(model: ArticulatedModel, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(T, n) [rad/s or m/s] the part of each joint's velocity ``v`` (T, n) that points towards the
    nearer of its limits at ``q`` (T, n), zero where it points away (or the joint has no finite
    limits)."""
    return np.maximum(_towards_nearer_limit(model, q) * v, 0.0)


def arrival_speed(model: ArticulatedModel, q: np.ndarray, t: np.ndarray, sample_t: np.ndarray) -> np.ndarray:
    """(T, n) [rad/s or m/s] at each sample of q (T, n) at times t (T,) [s], which interpolate
    measured samples at ``sample_t`` (S,) [s]: per joint with finite limits, the fastest mean speed
    towards the nearer limit over the measured interval holding the sample and the one before
    (zero when both move away from it).  A door that hits its stop between two camera frames and
    rebounds is at the stop in the spline through them with a spline speed near zero at its
    turn; its mean speed into the stop over the arriving interval is what the impact took
    (protocol_refrigerator_0@s1's door, 1.8 rad/s into its stop: the books held the impact and its
    energy residual read 0.16 where the true model on the same motion reads 0.03)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    sample_t = np.asarray(sample_t, dtype=float)
    k = _interval_of(t, sample_t)
    qs = _at_samples(q, t, sample_t)
    speed = np.diff(qs, axis=0) / np.diff(sample_t)[:, None]  # (S-1, n) mean speed of each measured interval
    towards = _towards_nearer_limit(model, q)
    return np.maximum(np.maximum(towards * speed[k], towards * speed[np.maximum(k - 1, 0)]), 0.0)


def energy_residual(model: ArticulatedModel, recording: Recording, stop_tolerance: float = STOP_TOLERANCE,
                    sample_t: np.ndarray | None = None) -> float:
    """Dimensionless energy-balance residual of ``recording`` under ``model``.

    With E the mechanical energy above, P_app = τ·v the applied power and
    P_dis = −Σ_j (b_j v_j² + f_j |v_j|) + Σ_j F_j(q_j, v_j) v_j the power of viscous damping,
    Coulomb friction and the joint's other non-spring forces F_j (Stribeck friction, bias, quadratic
    drag, a found limit contact: :mod:`kinemaforge_opt.physics.effects`), over
    the stop-free segments s = [a_s, b_s] of the recording (:func:`free_segments`),

        r = Σ_s |ΔE_s − W_app,s − W_dis,s| / S,
        ΔE_s = E(t_b) − E(t_a),  W_·,s = ∫_s P_· dt  (trapezoid rule),
        S = max(Σ_s |ΔE_s|, Σ_s ∫_s |P_app| dt, Σ_s ∫_s |P_dis| dt, max_s (max_s E_kin − min_s E_kin)).

    Why segments: a position stop of the model (its joint limits; Drake enforces them) does work
    the books above do not hold — a door that hits its stop loses most of its kinetic energy
    there.  Counting that loss made the residual of the *true* model on MuJoCo's own 120 Hz record
    0.10 (a door or drawer that hits its stop once) to 1.0 (a laptop lid falling onto its stop);
    over the stop-free segments it is below 1e-4 and 0.005.  The last term of S normalises a
    conservative motion (ΔE = W = 0) by the kinetic energy it exchanges.  r = 0 for a perfectly
    consistent model and data; r is 0 if nothing moves (S = 0); NaN when no interval is free of
    the stops (nothing to check).  ``sample_t``: the measured sample times the recording
    interpolates, if it does (:func:`free_segments`).  Velocities come from the recording, or from finite
    differences of q when it has none; τ is taken as zero when the recording has no ``tau``
    columns.  Joints of the model missing from the recording raise :class:`DataError`.
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
    p_dis = -(v**2 @ b + np.abs(v) @ f) + _other_passive_power(dyn, rec.q, v)
    segments = free_segments(model, rec.q, v, stop_tolerance, rec.t, sample_t)
    if not segments:
        return float("nan")
    num = dE_abs = W_app_abs = W_dis_abs = ek_span = 0.0
    for a, z in segments:
        s = slice(a, z + 1)
        dE = float(E[z] - E[a])
        num += abs(dE - _integral(rec.t[s], p_app[s]) - _integral(rec.t[s], p_dis[s]))
        dE_abs += abs(dE)
        W_app_abs += _integral(rec.t[s], np.abs(p_app[s]))
        W_dis_abs += _integral(rec.t[s], np.abs(p_dis[s]))
        ek_span = max(ek_span, float(np.ptp(E_kin[s])))
    scale = max(dE_abs, W_app_abs, W_dis_abs, ek_span)
    if scale <= 0.0:
        return 0.0
    return num / scale


def _other_passive_power(dynamics, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(T,) Σ_j F_j(q_j, v_j) v_j [W] of the joint forces other than damping, Coulomb friction and
    springs (which the energy balance books on its own) that each joint's ``dynamics`` hold."""
    booked = frozenset({"viscous_damping", "coulomb_friction", "spring"})
    power = np.zeros(len(q))
    for k, d in enumerate(dynamics):
        power += d.passive_force(q[:, k], v[:, k], without=booked) * v[:, k]
    return power


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
