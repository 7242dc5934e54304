"""Stops read off a joint's measured trajectory: where it hit one, where its range ends.

A reconstruction knows a joint only from q at the camera's frames (2-10 a second).  These
functions say, from those frames alone, where a joint arrived at an end of its observed range and
was stopped there (:func:`stop_impacts`, :func:`stop_spans`) and where the range a model of it
should declare ends (:func:`stop_limits`): at a stop it rests on, past its first or last seen frame
when it moved out of sight (:func:`unseen_reach`), or where it turned between two frames
(:func:`apex_reach`).  The screw-axis NLP leaves the dynamics at a stop out of its fit, the
written URDF takes the limits, and the verifier breaks its interpolant and its energy books at the
impacts.  times (T,) [s]; q (T, n) [rad or m], time-major.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Stop impacts (:func:`stop_spans`).  A joint arriving at an end of its observed range hits a stop
# when it arrived faster than STOP_MIN_SPEED × its peak speed, leaves the end (if at all) slower
# than STOP_REST × that speed (a smooth turn at the top of a swing leaves as fast as it came, a
# lid that fell onto its stop rests there) and its speed dropped at that frame or the one before
# by more than STOP_DROP × the typical drop of the frames before.  Under a constant deceleration a
# (friction bringing a door to rest) no frame-mean speed drops by more than a·Δt, the drop of every
# frame before, so 2 leaves room for noise and for friction that grows as the speed falls.  The
# two frames: an impact inside the last frame step lowers that step's mean speed too.
STOP_DROP = 2.0
STOP_MIN_SPEED = 0.1
STOP_REST = 0.5
# A joint first seen moving off an end of its range came from farther when its second frame step
# is at most this share of its first: clearly slowing.  A steady motion's frame-step speeds differ
# by far less (protocol_cabinet_multi_0's drawer, pulled out when first seen: 0.2838, 0.2832 m/s);
# a door first seen after its push had lost 28 % (protocol_microwave_1@s1) and 45 % (the tiny
# test door) by its second step.
UNSEEN_SLOWING = 0.9
# Share of a joint's observed range within which it is at an end of that range.
STOP_BAND = 0.02


@dataclass(frozen=True)
class StopImpact:
    """A joint's impact on a stop (:func:`stop_impacts`): joint index k, the frame i that caught
    the arrival at the end ``end`` [rad or m] of its observed range, the last frame b of its stay
    there, and ``rest``: where it rests against the stop to the last frame when that lies off the
    end's band (the extreme of those frames on the stop's side), else ``end``."""

    k: int
    i: int
    b: int
    end: float
    rest: float


def _time_major(times: np.ndarray, q) -> np.ndarray:
    """q as a (T, n) float array for the T frames ``times`` (a (n, T) array is transposed)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    return q.T if q.shape[0] != times.size else q


def stop_impacts(times: np.ndarray, q: np.ndarray) -> list[StopImpact]:
    """The stop impacts of the joints moving as q (T, n) [rad or m] at the observed frames
    ``times`` (T,) [s]: a joint, after leaving its start, arrives at frame i within STOP_BAND of
    its observed range of an end of that range, and the arrival is an impact (see
    :data:`STOP_DROP`).  Its stay at that end holds the frames within the band of the end; a joint
    that from the frame after the arrival on stays within the band of that frame to the last one,
    off the end's band, rests against the stop to the end too (``rest``): a compliant stop is
    pressed in at the impact, so the frame that catches it can lie past where the joint then rests
    (protocol_laptop_0@s1's lid: 0.034 rad at the impact, then at rest at 0.001 rad; the stop's
    holding force, which the NLP does not model, was fitted as the lid's weight traded for Coulomb
    friction).  A door or drawer that rebounds and moves off keeps the end's band alone (with the
    frame after the arrival taken as where it rests, protocol_refrigerator_0's rebounding door was
    left out two frames longer and its full fit stopped at 200 iterations).  Every joint and every
    arrival is examined."""
    q = _time_major(times, q)
    T = times.size
    if T < 5:
        return []
    s = np.abs(np.diff(q, axis=0) / np.diff(times)[:, None])  # (T-1, n) speed over step j -> j + 1
    drop = np.maximum(s[:-1] - s[1:], 0.0)  # (T-2, n): drop[i-1], the speed lost at frame i
    out = []
    for k in range(q.shape[1]):
        lo, hi = q[:, k].min(), q[:, k].max()
        tol = STOP_BAND * (hi - lo)
        if tol <= 0:
            continue
        left = np.maximum.accumulate(np.abs(q[:, k] - q[0, k])) > tol
        i = 2
        while i < T - 1:
            end = hi if q[i, k] >= hi - tol else lo if q[i, k] <= lo + tol else None
            if end is None or not left[i]:
                i += 1
                continue
            b = i  # the stay at that end
            while b + 1 < T and abs(q[b + 1, k] - end) <= tol:
                b += 1
            rest = end
            after = q[i + 1:, k]
            if b + 1 < T and abs(after[0] - end) > tol and np.all(np.abs(after - after[0]) <= tol):
                # at rest off the end's band from the frame after the impact to the last one: where
                # the compliant stop holds it
                b, rest = T - 1, float(after.max() if end == hi else after.min())
            if _impact(s[:, k], drop[:, k], _arrival(q[:, k], i, b, 1.0 if end == hi else -1.0), leaves=b + 1 < T):
                out.append(StopImpact(k, i, b, float(end), rest))
            i = b + 1
    return out


def stop_spans(times: np.ndarray, q: np.ndarray) -> list[tuple[int, int]]:
    """Frame spans (a, b) in which a stop may act: per :func:`stop_impacts`, a = the frame before
    the one that caught the impact, b = the first frame after the stay at the stop (the stop may
    push it off again; the last frame if it stays).  times (T,) [s], q (T, n) [rad or m]."""
    return sorted((e.i - 1, min(e.b + 1, times.size - 1)) for e in stop_impacts(times, q))


def stop_limits(times: np.ndarray, q: np.ndarray, seen: np.ndarray | None = None) -> np.ndarray:
    """(n, 2) lower and upper limits [rad or m] of the joints moving as q (T, n) at the frames
    ``times`` (T,) [s]: the observed range, but an end where a joint hit a stop and then rested
    against it off the impact frame's band (:func:`stop_impacts`) is where it rests (the
    impact frame caught the compliant stop pressed in; a simulator's stop at that depth would hold
    the joint there: protocol_laptop_1@s1's lid, resting at 0.001 rad under a limit at 0.077 rad,
    replayed 9 mm off after 50 s, 0.2 mm with the limit where it rests).

    ``seen`` (T, n) bool: where each joint's child part is observed (default: where q is finite).  Only
    the frames from a joint's first to its last seen one count.  An end the joint takes at its
    first seen frame while moving off it, with frames before that unseen (or at its last seen
    frame, arriving, with frames after unseen), is no observed stop when the joint was slowing
    down as it left it (speeding up as it arrived): it moves out by the way that frame step's
    speed covers in the unseen time (:func:`unseen_reach`; an estimate, not a bound: the tiny
    test door, first seen 0.67 s into its push, gets −0.63 rad for a true −0.93).
    protocol_microwave_1@s1's door, first seen 0.475 s into a push at 1.8 rad/s: with its limit
    at that first pose the energy books read the push as a stop, energy residual 0.54; with any
    limit past it, 0.11.  An end the joint turned at between frames, moving on both sides and no
    stop impact, is where it turned (:func:`apex_reach`)."""
    q = _time_major(times, q)
    seen = np.isfinite(q) if seen is None else np.asarray(seen, dtype=bool).reshape(q.shape)
    limits = np.full((q.shape[1], 2), np.nan)
    for k in range(q.shape[1]):
        rows = np.flatnonzero(seen[:, k])
        rows = np.arange(rows[0], rows[-1] + 1) if rows.size else np.arange(times.size)  # never seen: every frame
        rows = rows[np.isfinite(q[rows, k])]
        if rows.size == 0:
            continue
        tk, qk = times[rows], q[rows, k]
        limits[k] = qk.min(), qk.max()
        impacts = stop_impacts(tk, qk[:, None])
        for e in impacts:
            limits[k, int(e.end == limits[k, 1])] = e.rest
        reach = unseen_reach(tk, qk, times[0], times[-1], limits[k])
        for side in {0, 1} - {int(e.end == qk.max()) for e in impacts}:
            reach[side] += apex_reach(tk, qk, side)
        limits[k] += reach
    return limits


def apex_reach(times: np.ndarray, q: np.ndarray, side: int) -> float:
    """How far [rad or m] (−: lower, +: upper) the ``side`` (0 lower, 1 upper) end of the observed
    range of a joint seen moving as q (S,) at ``times`` (S,) [s] moves out when the joint turned
    there between frames: the end's frame i is inside the series, the joint arrived there and left
    it moving (each faster than STOP_MIN_SPEED × its fastest frame step, over the two steps on
    either side), and it was no stop impact (the caller leaves those ends alone).  The turn then lies
    between frames i − 1 and i + 1, and the vertex of the parabola through the three frames (the
    standard sub-sample peak estimate) says where.  Zero elsewhere.

    protocol_laptop_0's lid, lifted and let fall at 6.3 frames a second, turned at 1.389 rad
    (MuJoCo's 120-Hz record) between frames at 1.336 and 1.376 rad; the vertex says 1.395.  With its
    limit at the frame, the replay of the lid under the recorded hand stopped there: 1-s drift
    0.028 m, 0.018 m with the limit 0.02 rad out.  A joint resting at the end before or after (a
    door pushed to its stop, or leaving one) has a frame step near zero on that side and keeps the
    frame."""
    S = q.size
    i = int(np.argmax(q) if side else np.argmin(q))
    if S < 3 or not 0 < i < S - 1:
        return 0.0
    speed = np.abs(np.diff(q) / np.diff(times))
    floor = STOP_MIN_SPEED * speed.max()
    if speed[max(i - 2, 0):i].max() <= floor or speed[i:i + 2].max() <= floor:
        return 0.0
    a, b, _ = np.polyfit(times[i - 1:i + 2] - times[i], q[i - 1:i + 2], 2)
    vertex = -b / (2 * a) if a != 0 else 0.0
    return float(np.polyval((a, b, 0.0), vertex)) if (a < 0) == bool(side) else 0.0


def unseen_reach(times: np.ndarray, q: np.ndarray, start: float, end: float, limits: np.ndarray) -> np.ndarray:
    """(2,) how far [rad or m] the lower and upper limits ``limits`` (2,) of a joint seen moving as
    q (S,) at ``times`` (S,) [s] move out (−, +) for the unseen time from ``start`` [s] to its first
    seen frame and from its last to ``end`` [s]: when it is at an end of ``limits`` at its first
    seen frame and was slowing down as it left it (its second frame step at most UNSEEN_SLOWING ×
    its first, and the first faster than STOP_MIN_SPEED × its fastest step: it came from
    farther), by that first step's speed × the unseen time; the same, reversed in time, for an
    end it arrived at speeding up at its last seen frame.  Zero elsewhere.  A joint that leaves
    its first seen pose speeding up or steadily may have started there: protocol_cabinet_multi_0's
    drawer, first seen 3.2 s in as it is pulled out at a steady 0.28 m/s, had its closed end put
    0.9 m into the carcass by a first version of this rule that moved every end left in motion
    (by the fastest speed × the unseen time), and the replay's 1-s drift went 0.19 → 0.36 m."""
    reach = np.zeros(2)
    if q.size < 3:
        return reach
    speed = np.diff(q) / np.diff(times)
    fastest = float(np.abs(speed).max())
    # (the frame, its step's speed into the unseen time, the next step's, how long it is unseen)
    for i, v, v_next, hidden in ((0, -speed[0], -speed[1], times[0] - start), (-1, speed[-1], speed[-2], end - times[-1])):
        if hidden <= 0 or abs(v) <= STOP_MIN_SPEED * fastest or v * v_next <= 0 or abs(v_next) > UNSEEN_SLOWING * abs(v):
            continue
        side = int(v > 0)
        if q[i] == limits[side]:
            reach[side] = v * hidden
    return reach


def _arrival(q: np.ndarray, i: int, b: int, toward: float) -> int:
    """The frame at which a joint moving as q (T,) arrived at an end of its range (``toward``: +1
    the upper, −1 the lower) whose band it entered at frame i and stayed in to frame b: i, or,
    when it kept moving towards the end
    from frame to frame inside the band and left the band after b, the frame where it stopped
    doing so.  A smooth turn whose top two frames both fall in the band (a lid lifted at 6.3
    frames a second, 1.353 and 1.368 rad under a top of 1.379) arrives at the second and leaves it
    as fast as it came; read from the first, its slow step to the second looked like a stop's."""
    if b + 1 >= q.size:
        return i
    while i < b and toward * (q[i + 1] - q[i]) > 0:
        i += 1
    return i


def _impact(s: np.ndarray, drop: np.ndarray, i: int, leaves: bool) -> bool:
    """Whether a joint's arrival at an end of its range at frame i (≥ 2) is a stop impact, from its
    frame-step speeds s (T-1,) and speed drops (T-2,) (:data:`STOP_DROP`).  ``leaves``: the joint
    leaves that end again later.  A joint that arrives fast, leaves slower than STOP_REST × that
    speed and does leave was sent back by a stop (gravity and springs send it back as fast as it
    came) or by a hand (its span only leaves data out), so the drop need not show: a hand that
    braked it before the end hides it (protocol_drawer_1@s1's drawer, braked to 0.11 m/s,
    rebounds at 0.015 m/s)."""
    arrive = s[i - 2:i].max()
    if not (arrive > STOP_MIN_SPEED * s.max() and s[i:i + 2].max() < STOP_REST * arrive):
        return False
    prior = min(float(np.median(drop[max(i - 4 - d, 0):i - 1 - d])) for d in (0, 1) if i - 1 - d > 0)
    return bool(leaves or drop[i - 2:i].max() > STOP_DROP * prior)
