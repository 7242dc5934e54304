"""What the nominal model's inverse-dynamics residual force says before any NLP is solved: a
stop's likely side and position, starting values of an effect's parameters (linear least
squares on its force per unit parameter), and the linear pre-screen that ranks hypotheses for
the selection (:mod:`.selection`).  A ranking and a start, never evidence: the NLP fits decide."""

from __future__ import annotations

import numpy as np

from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..model.pinocchio import forward_dynamics, inverse_dynamics, link_inverse_dynamics
from ..nlp.joint_space import measurement_sigma, stretches
from .effects import EFFECTS
from .locate import inverse_dynamics_residual
from .search import Trial


def limit_stop_guess(model: ArticulatedModel, rec: Recording) -> dict[str, tuple[float, float]]:
    """Per joint, the side (+1 above the motion, -1 below) and initial position of a hypothetical
    stop: the recorded extreme at which the nominal inverse-dynamics residual force pushes back
    with the larger impulse (a stop is where the motion turns with a force the model lacks; a
    mean over the extreme's samples let one noisy sample outweigh an impact).  Only samples after
    the motion first leaves an extreme's band count for it: a recording that starts at rest at
    one end of its motion has not met a stop there (a drawer driven shut from its start onto a
    stop: the start's residual, differentiation noise at the edge, chose the start's end).  So has
    a piece of the recording between gaps (:func:`~kinemaforge_opt.nlp.joint_space.stretches`)
    that starts there: one that begins as the part leaves the model's own stop still carries that
    stop's push in its first samples."""
    force, q, _, _ = inverse_dynamics_residual(model, rec)
    sigma = measurement_sigma(rec.q)
    out = {}
    for k, j in enumerate(model.joint_names):
        qk = rec.q[:, k]
        lo, hi = float(qk.min()), float(qk.max())
        band = 0.03 * max(hi - lo, 1e-12)
        away = max(2.0 * band, 5.0 * float(sigma[k]))  # left the band: beyond the noise's reach
        extremes = ((1.0, qk >= hi - band, qk < hi - away), (-1.0, qk <= lo + band, qk > lo + away))
        push = {}
        for side, near, far in extremes:
            arrived = np.zeros_like(near)
            for a, b in stretches(rec.t):
                left = np.flatnonzero(far[a:b])
                arrived[a:b] = near[a:b] & (np.arange(b - a) > left[0]) if left.size else near[a:b]
            push[side] = -side * float(np.sum(force[arrived, k])) if arrived.any() else -np.inf
        if not np.isfinite(max(push.values())):  # the motion never left either band
            push = {side: -side * float(np.sum(force[near, k])) for side, near, _ in extremes}
        out[j] = (1.0, hi) if push[1.0] >= push[-1.0] else (-1.0, lo)
    return out


# Where a stop's fit may start, in fractions of the recorded range inside the recorded extreme on
# its side (:func:`stop_ramp_fraction`); STOP_START is the default start, and where the
# pre-screen's stop column starts (from the ramp's best start instead, that column reordered the
# real Qube's screened rounds: fin2 + fin4 fitted together predicted fin9 0.024 -> 0.049 rad).
STOP_START_FRACTIONS = (0.01, 0.02, 0.05, 0.1, 0.2)
STOP_START = 0.05


def stop_ramp_fraction(q: np.ndarray, r: np.ndarray, side: float, extreme: float) -> float:
    """The fraction of the recorded range ``q`` (T,) inside ``extreme`` (on ``side``) at which a
    stop's one-sided ramp of force, pushing back with the best stiffness >= 0, explains most of
    the missing force ``r`` (T,) by least squares; one of :data:`STOP_START_FRACTIONS`.  The
    residual force comes from smoothed accelerations, which spread an impact over the window,
    so this is a start for the NLP, not an estimate."""
    span = max(float(np.ptp(q)), 1e-12)

    def left(f):
        push = -side * np.maximum(side * (q - (extreme - side * f * span)), 0.0)  # force per unit stiffness
        k = max(float(push @ r) / max(float(push @ push), 1e-300), 0.0)
        return float(np.sum((r - k * push) ** 2))

    return min(STOP_START_FRACTIONS, key=left)


def inertia_columns(model: ArticulatedModel, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                    tau: np.ndarray | None) -> np.ndarray:
    """(T, n) per joint, the pre-screen's column of an inertia error on it: the force its moved
    link's inertia takes along (q, v) (T, n), at the accelerations the model predicts under the
    recorded joint forces ``tau`` (T, n) and its own passive forces.  Without a recorded force
    (``tau`` None): the whole rigid-body force M a + h at the measured accelerations ``a``.

    Why predicted accelerations: the residual force M a + h - tau is made of the measured ones,
    so a column made of them carries the very differentiation noise the residual carries and
    "explains" it (errors in variables: on a 1-mm drawer recorded at 100 Hz, 87 % of a residual
    that was mostly noise, ranked above the stop that made the rest).  To first order in the
    error the true acceleration is the predicted one, so this column has the noise of q and v
    only.  Why not without a force: the column then holds only the passive forces' share, and a
    single link's inertia scale is not identifiable at all (:mod:`.diagnose`); on the real Qube's
    free swings it reordered the later rounds and lost the arm's Coulomb friction (held-out
    0.030 / 0.028 -> 0.041 / 0.037 rad)."""
    if tau is None:
        return inverse_dynamics(model, q, v, a)
    joints = model.movable_joints
    accelerations = forward_dynamics(model, q, v, tau + model.passive_forces(q, v))
    shares = link_inverse_dynamics(model, [j.child for j in joints], q, v, accelerations)
    return np.stack([shares[k][:, k] for k in range(len(joints))], axis=1)


def stribeck_speeds(v: np.ndarray, eps: float, slowest: float = 0.0, n: int = 12) -> np.ndarray:
    """Candidate Stribeck speeds [rad/s or m/s] for a joint moving at speeds ``v`` (T,): a
    geometric grid from twice the smooth-sign width ``eps`` and the ``slowest`` speed that counts
    as moving (:func:`moving_speed`; a Stribeck speed below either has no shape the regression
    sees: its column is ~0 on every moving sample) to half the peak speed (above it the excess
    never fades within the recording: Coulomb friction by another name; the NLP's bound)."""
    hi = 0.5 * float(np.max(np.abs(v)))
    lo = min(max(2.0 * eps, 1e-3, slowest), hi)
    return np.geomspace(lo, hi, n) if hi > lo else np.array([hi])


def _stribeck_column(v: np.ndarray, vs: float, eps: float) -> np.ndarray:
    return -np.exp(-((v / vs) ** 2)) * np.tanh(v / eps)


def _best_stribeck_speed(v: np.ndarray, r: np.ndarray, eps: float, base: list[np.ndarray], grid: np.ndarray) -> float:
    """The speed of ``grid`` whose Stribeck column, with the columns ``base``, leaves the least of
    ``r`` by linear least squares (v, r and the columns on the same samples)."""
    def left(vs):
        A = np.stack(base + [_stribeck_column(v, vs, eps)], axis=1)
        return float(np.sum((r - A @ np.linalg.lstsq(A, r, rcond=None)[0]) ** 2))

    return float(min(grid, key=left))


# A sample counts as moving for the pre-screen when its smoothed speed is above this share of the
# joint's RMS speed and this many of the speed's noise sigmas: below either, the direction of
# motion (dry friction's sign) is noise, and a friction column there "explains" nothing but costs
# its squares (a door with Coulomb friction 0.3 N·m recorded at 60 Hz with 2 mm of noise: 5 % of
# its RMS speed is 0.03 rad/s, its speed's noise 0.04 rad/s, and the Coulomb column, ±1 at rest,
# ranked below damping, drag, tilt, inertia and a spring).  The linear starts keep the share
# alone: from the faster samples only, a drawer's Coulomb friction started at 5.0 N for 3.0 N
# (its damping's force folded in) and its fit fell to 0, and a spring's start sent a Drake door's
# stop + spring pair to IPOPT's cap.
MOVING_SHARE = 0.05
MOVING_SIGMA = 3.0


def moving_speed(v_scale: float, v_noise: float) -> float:
    """The slowest speed [rad/s or m/s] that counts as moving: MOVING_SHARE × the joint's RMS
    speed ``v_scale``, at least MOVING_SIGMA × its noise ``v_noise``."""
    return max(MOVING_SHARE * v_scale, MOVING_SIGMA * v_noise)


def linear_init(model: ArticulatedModel, joint: str, effect: str, start: Trial, r_nom: np.ndarray,
                q: np.ndarray, v: np.ndarray, eps: np.ndarray, v_scale: np.ndarray) -> dict[str, np.ndarray]:
    """Starting values of a force effect's parameters from the inverse-dynamics residual: the
    nominal model's missing generalised force ``r_nom`` (T, n) at smoothed (q, v), less the
    effects already in ``start``, regressed (least squares, moving samples only: at standstill
    dry friction takes any value) on the effect's force per unit parameter.  Most effects are
    linear in their parameters; the Stribeck speed is the one of :func:`stribeck_speeds` that
    explains most, a spring's rest position comes from its two linear coefficients (else
    mid-motion)."""
    k = model.joint_index(joint)
    r = r_nom[:, k].copy()
    for e_type in dict.fromkeys(e for e in EFFECTS if EFFECTS[e].force is not None):
        ps = [f"{joint}.{p}" for p in EFFECTS[e_type].params]
        if all(p in start.free for p in ps):
            r = r - EFFECTS[e_type].force(q[:, k], v[:, k], *[start.values[p][0] for p in ps], eps=float(eps[k]))
    moving = np.abs(v[:, k]) > MOVING_SHARE * v_scale[k]
    if moving.sum() < 5:
        return {}
    qk, vk, rk = q[moving, k], v[moving, k], r[moving]
    vs = _best_stribeck_speed(vk, rk, float(eps[k]), [], stribeck_speeds(v[:, k], float(eps[k]))) \
        if effect == "stribeck_friction" else 0.2 * v_scale[k]
    cols = {
        "viscous_damping": [-vk], "coulomb_friction": [-np.tanh(vk / eps[k])], "quadratic_drag": [-vk * np.abs(vk)],
        "constant_bias": [np.ones_like(vk)], "spring": [-qk, np.ones_like(qk)],
        "stribeck_friction": [_stribeck_column(vk, vs, eps[k])],
    }.get(effect)
    out = {}
    if effect == "stribeck_friction":
        out[f"{joint}.v_stribeck"] = np.array([vs])
    if effect == "spring":
        out[f"{joint}.spring_rest"] = np.array([float(np.mean(q[:, k]))])
    if cols is None:
        return out
    coef = np.linalg.lstsq(np.stack(cols, axis=1), rk, rcond=None)[0]
    first = EFFECTS[effect].params[0]
    value = coef[0] if EFFECTS[effect].lower[0] == -np.inf else max(coef[0], 0.0)
    out[f"{joint}.{first}"] = np.array([value])
    if effect == "spring" and coef[0] > 0:  # rest from the two coefficients, within a span of the motion
        lo, hi = float(q[:, k].min()), float(q[:, k].max())
        out[f"{joint}.spring_rest"] = np.array([np.clip(coef[1] / coef[0], 2 * lo - hi, 2 * hi - lo)])
    return out


def _columns(model: ArticulatedModel, joint: str, effect: str, q: np.ndarray, v: np.ndarray, id_force: np.ndarray,
             eps: np.ndarray, v_scale: np.ndarray, stops: dict, vs: float | None = None) -> list[np.ndarray]:
    """Force columns (each (T,)) of ``effect`` on ``joint`` for the linear pre-screen: the effect's
    force per unit parameter (Stribeck at speed ``vs``, default a fifth of the RMS speed), the rigid-body force M a + h
    for an inertia ratio, gravity's sin q and cos q for a revolute axis tilt (a constant for a
    prismatic one), a one-sided ramp from STOP_START inside the stop guess for a limit contact."""
    k = model.joint_index(joint)
    qk, vk = q[:, k], v[:, k]
    vs = 0.2 * v_scale[k] if vs is None else vs
    side, stop = stops[joint]
    span = float(np.ptp(qk))
    if effect == "axis_tilt":
        return [np.ones_like(qk)] if model.joint(joint).type == "prismatic" else [np.sin(qk), np.cos(qk)]
    return {
        "viscous_damping": [-vk], "coulomb_friction": [-np.tanh(vk / eps[k])], "quadratic_drag": [-vk * np.abs(vk)],
        "constant_bias": [np.ones_like(vk)], "spring": [-qk, np.ones_like(qk)],
        "stribeck_friction": [_stribeck_column(vk, vs, eps[k])],
        "inertia_error": [id_force[:, k]],
        "limit_contact": [np.maximum(side * (qk - (stop - side * STOP_START * span)), 0.0)],
    }[effect]


def screen_scores(model: ArticulatedModel, pending: list[tuple[str, str]], selected: list[tuple[str, str]],
                  r_nom: np.ndarray, id_force: np.ndarray, q: np.ndarray, v: np.ndarray, eps: np.ndarray,
                  v_scale: np.ndarray, v_noise: np.ndarray, stops: dict) -> dict[tuple[str, str], float]:
    """Per hypothesis, the share of the nominal inverse-dynamics residual on its joint (moving
    samples, above :func:`moving_speed` for the RMS speeds ``v_scale`` and speed noise
    ``v_noise`` (n,)) that the already selected effects on that joint leave and the hypothesis
    removes too, by joint linear least squares on their force columns (:func:`_columns`; a Stribeck
    column at the speed of :func:`stribeck_speeds` that explains most); lower = explains
    more.  A cheap ranking, not evidence: the chosen hypotheses are then fitted by the NLP."""
    out = {}
    for joint, effect in pending:
        k = model.joint_index(joint)
        slowest = moving_speed(v_scale[k], v_noise[k])
        moving = np.abs(v[:, k]) > slowest
        rk, vk, ek = r_nom[moving, k], v[moving, k], float(eps[k])
        grid = stribeck_speeds(v[:, k], ek, slowest)  # a Stribeck column at the speed that explains most
        base = [c[moving] for j, e in selected if j == joint
                for c in _columns(model, j, e, q, v, id_force, eps, v_scale, stops,
                                  _best_stribeck_speed(vk, rk, ek, [], grid) if e == "stribeck_friction" else None)]

        def left(cols):
            if not cols:
                return float(np.sum(rk**2))
            A = np.stack(cols, axis=1)
            return float(np.sum((rk - A @ np.linalg.lstsq(A, rk, rcond=None)[0]) ** 2))

        vs = _best_stribeck_speed(vk, rk, ek, base, grid) if effect == "stribeck_friction" else None
        new = [c[moving] for c in _columns(model, joint, effect, q, v, id_force, eps, v_scale, stops, vs)]
        out[(joint, effect)] = left(base + new) / max(left(base), 1e-300)
    return out
