"""The joint-space fit: a recording's trajectory and the model's free parameters, by direct
collocation on the bridge's ABA.

Transcription: one collocation interval per recorded sample interval, compressed
Hermite–Simpson (4th order, A-stable, so stiff smooth-friction terms do not destabilise it):

    x_m = (x_k + x_k+1)/2 + h/8 (f_k - f_k+1),     x_k+1 - x_k = h/6 (f_k + 4 f_m + f_k+1),

with x = (q, v), f(x, u) = (v, ABA(q, v, u + tau_passive(q, v), theta)), and the applied force u
interpolated linearly between samples.  Named terms:

- cost ``output_q`` (and ``output_v`` when v is recorded): squared residuals / noise variance,
  averaged over samples;
- constraint ``dynamics``: the Hermite–Simpson defects;
- ``energy`` (``soft`` cost or ``hard`` constraint, or ``off``): per window, the change of
  rigid-body energy minus the work of applied and passive forces (Simpson quadrature on the same
  collocation points), relative to the energy scale of the recording; the books are kept by the
  variable and constraint ``energy_books`` (their running sum along the grid);
- constraint ``unit_axis:<joint>`` for every freed axis.

The interval functions are ``casadi.Function.map``-ped over the intervals, so the NLP graph stays
small and JIT compilation is an option (FACTS.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from ..errors import DataError, KinemaforgeError, UnknownNameError
from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..model.pinocchio import build_pin_model, forward_dynamics
from ..physics.effects import EFFECTS, FORCE_EFFECTS, dynamics_effects
from ..symbolic import Dynamics, available_parameters, build_dynamics
from .parameters import (
    FORCE_PARAMS,
    DataScales,
    ParameterBlock,
    force_parameter_names,
    make_block,
    nominal_force_parameters,
)
from .problem import Problem

# Which force-parameter groups make up each force effect.
_EFFECT_PARAMS = {t: EFFECTS[t].params for t in FORCE_EFFECTS}


MIN_SAMPLES = 10  # below this, noise levels (third differences) and any parameter are undetermined


def match_recording(model: ArticulatedModel, recording: Recording) -> Recording:
    """``recording`` restricted and ordered to the model's joints.  Raises :class:`DataError` /
    :class:`UnknownNameError` naming the joints when the two disagree, or when nothing moves."""
    extra = [j for j in recording.joint_names if j not in model.joint_names]
    if extra:
        raise UnknownNameError("joint (recorded)", extra[0], model.joint_names)
    missing = [j for j in model.joint_names if j not in recording.joint_names]
    if missing:
        raise DataError(f"recording has no q column for joint(s) {missing} of model {model.name!r}")
    rec = recording.select(model.joint_names)
    if rec.t.size < MIN_SAMPLES:
        raise DataError(f"recording has {rec.t.size} samples: too few to identify anything (at least {MIN_SAMPLES})")
    if np.all(np.ptp(rec.q, axis=0) < 1e-9):
        raise DataError("recording shows no motion: every joint stays at its initial position")
    check_units(model, rec)
    return unwrapped_angles(model, rec)


def unwrapped_angles(model: ArticulatedModel, rec: Recording) -> Recording:
    """``rec`` (ordered as the model's joints) with each continuous joint's q unwrapped where it
    jumps by more than π between samples: encoders and logs often report an angle in (−π, π],
    and a pendulum spinning over the top then jumps by 2π where the model's angle goes on (fitted
    as it was, every wrap is a misfit no effect explains).  Raises :class:`DataError` naming the
    joint for such a jump on a revolute joint with finite limits, whose angle cannot wrap."""
    q = rec.q
    for k, j in enumerate(model.movable_joints):
        if j.type not in ("revolute", "continuous"):
            continue
        jumps = np.flatnonzero(np.abs(np.diff(q[:, k])) > np.pi)
        if not jumps.size:
            continue
        lim = j.limits
        if j.type == "revolute" and lim is not None and np.isfinite(lim.lower) and np.isfinite(lim.upper):
            i = int(jumps[0])
            raise DataError(
                f"recording q:{j.name} jumps by {q[i + 1, k] - q[i, k]:+.3g} rad between t = {rec.t[i]:.6g} and "
                f"{rec.t[i + 1]:.6g} s, more than π in one sample, on a joint limited to [{lim.lower:.4g}, "
                f"{lim.upper:.4g}] rad: a wrapped angle, or samples out of order?")
        if q is rec.q:
            q = rec.q.copy()
        q[:, k] = np.unwrap(q[:, k])
    return rec if q is rec.q else replace(rec, q=q)


SPIKE_SIGMA = 10.0  # a single sample this many noise sigmas off the line through its neighbours...
SPIKE_ECHO = 0.2    # ...whose neighbours are off theirs by half that, the other way, within this share


GAP_INTERVALS = 5.0  # a sample interval this many times the median one is a gap in the recording
JOIN_GAP_S = 1.0  # the least pause [s] between recordings joined end to end (join_recordings)


def recording_gaps(t: np.ndarray) -> np.ndarray:
    """Indices i (sample intervals t[i] → t[i+1]) longer than GAP_INTERVALS median intervals: a log
    that paused or lost data.  What moved the part meanwhile is unknown (the recorded force is only
    interpolated across), so fits and predictions do not carry the dynamics across a gap."""
    dt = np.diff(np.asarray(t, dtype=float))
    return np.flatnonzero(dt > GAP_INTERVALS * np.median(dt)) if dt.size else np.zeros(0, dtype=int)


def stretches(t: np.ndarray) -> list[tuple[int, int]]:
    """The [start, end) sample ranges of the stretches of a recording between its gaps
    (:func:`recording_gaps`), in order."""
    bounds = [0, *(recording_gaps(t) + 1), len(t)]
    return list(zip(bounds[:-1], bounds[1:]))


def without_spikes(rec: Recording) -> tuple[Recording, dict[str, list[float]]]:
    """(``rec`` without its isolated spikes, {joint: times [s] left out}).  A tracker's glitch
    moves one sample far off the motion: it stands SPIKE_SIGMA measurement sigmas or more off the
    line through its two neighbours, and each neighbour stands half as far off the line through
    its own neighbours the other way (the echo of the one displaced sample; SPIKE_ECHO of the
    jump plus two sigmas).  A real reversal, even an instant rebound off a stop, leaves its
    neighbours on their lines, so it is kept.  An output-error fit pulled by a glitch of 50
    sigmas reported drag and friction for a door's damping."""
    n = rec.t.size
    if n < 5:
        return rec, {}
    t, q = rec.t, rec.q
    w = (t[1:-1] - t[:-2]) / (t[2:] - t[:-2])  # sample i's place between its neighbours
    dev = q[1:-1] - ((1 - w)[:, None] * q[:-2] + w[:, None] * q[2:])  # (T-2, n), sample i+1 off its line
    sig = measurement_sigma(q) * np.sqrt(1.0 + w[:, None] ** 2 + (1 - w[:, None]) ** 2)
    big = np.abs(dev) >= SPIKE_SIGMA * sig
    echo = np.zeros_like(big)
    tol = SPIKE_ECHO * np.abs(dev[1:-1]) + 2.0 * sig[1:-1]
    echo[1:-1] = (np.abs(dev[:-2] + dev[1:-1] / 2) <= tol) & (np.abs(dev[2:] + dev[1:-1] / 2) <= tol)
    spike = np.zeros((n, q.shape[1]), dtype=bool)
    spike[1:-1] = big & echo
    if not spike.any():
        return rec, {}
    left_out = {name: [float(x) for x in t[spike[:, k]]] for k, name in enumerate(rec.joint_names) if spike[:, k].any()}
    return rec.rows(~spike.any(axis=1)), left_out


def spike_words(left_out: dict[str, list[float]]) -> str:
    """The sentence that says which samples :func:`without_spikes` left out."""
    where = "; ".join(f"q:{j} at t = " + ", ".join(f"{x:.4g}" for x in ts[:5]) + (" …" if len(ts) > 5 else "")
                      for j, ts in left_out.items())
    return (f"left out {sum(map(len, left_out.values()))} isolated sample(s) ({where} s): each a single jump of "
            f"{SPIKE_SIGMA:g}+ noise sigmas off its neighbours' line that both neighbours contradict (a tracking glitch)")


def _rest_acceleration(model: ArticulatedModel, rec: Recording, samples: int) -> np.ndarray:
    """(samples, n) accelerations [rad/s² or m/s²] of the nominal model held at rest at each of
    the first ``samples`` recorded positions under the recorded force and its passive forces
    (gravity, springs, bias; friction vanishes at rest)."""
    q, v = rec.q[:samples], np.zeros_like(rec.q[:samples])
    tau = v if rec.tau is None else rec.tau[:samples]
    return forward_dynamics(model, q, v, tau + model.passive_forces(q, v))


def _stop_band(sigma: float, lim) -> float:
    """How close [rad or m] a joint with position noise ``sigma`` comes to a stop of its
    ``limits`` to touch it: max(5 noise sigma, 1 % of the range)."""
    return max(5 * sigma, 0.01 * (lim.upper - lim.lower))


def stop_contact(model: ArticulatedModel, rec: Recording) -> np.ndarray:
    """(T, n) True where a joint of ``model`` is in contact with a stop the model declares (its
    URDF limits, within max(5 noise sigma, 1 % of the range)) along ``rec``: back at a stop after
    it had moved clear (an arrival), or at the start resting on one and pressed into it
    (:func:`between_nominal_stops`)."""
    sigma = measurement_sigma(rec.q)
    contact = np.zeros(rec.q.shape, dtype=bool)
    for k, j in enumerate(model.movable_joints):
        lim = j.limits
        if lim is None or not (np.isfinite(lim.lower) and np.isfinite(lim.upper)):
            continue
        tol = _stop_band(sigma[k], lim)
        # an arrival counts once the joint has been clear of both stops, beyond twice the band (a
        # slow start wanders in and out of the band's edge; summing |Δq| would count noise as motion)
        q = rec.q[:, k]
        near = (q <= lim.lower + tol) | (q >= lim.upper - tol)
        clear = (q > lim.lower + 2 * tol) & (q < lim.upper - 2 * tol)
        contact[:, k] = np.maximum.accumulate(clear) & near
        if near[0] and clear.any():  # starts on a stop and leaves it
            resting = int(np.argmax(~near))
            side = -1.0 if q[0] <= lim.lower + tol else 1.0
            # pressed: the nominal model would have moved it into the stop by more than the noise
            # within the time it rested there, so the stop's force held it
            held = 2.0 * sigma[k] / max(rec.t[resting] - rec.t[0], rec.t[1] - rec.t[0]) ** 2
            pressed = np.flatnonzero(side * _rest_acceleration(model, rec, resting)[:, k] > held)
            if pressed.size:  # up to the last sample pressed into the stop
                contact[: int(pressed[-1]) + 1, k] = True
    return contact


# A joint in contact with a stop is held there while its smoothed speed stays within this many
# of the speed's noise sigmas (an impact or a push off the stop is faster) and its position within
# REST_SIGMA noise sigmas of the contact band.
HELD_SIGMA = 3.0
REST_SIGMA = 4.0


def held_on_stops(model: ArticulatedModel, rec: Recording, contact: np.ndarray) -> np.ndarray:
    """(T, n) True where a joint rests on a stop: runs of MIN_CLEAR_SAMPLES or more samples in
    which it is still (its Savitzky–Golay speed within HELD_SIGMA of that speed's noise, from its
    measured position noise) and within REST_SIGMA position noise sigmas of the contact band,
    their median inside the band, each inside a still stretch that was in ``contact`` (T, n)
    with that stop (:func:`stop_contact`) at some sample.  Not only the contact samples: a part
    resting on its stop sits on the band's edge (a MuJoCo drawer shut 1 cm off its limit, with
    2 mm of noise, was in the band at 61 % of its samples).  The samples of an arrival (the
    impact, a bounce) and of a push off the stop read faster: the smoothing window spreads them
    over its width."""
    from ..physics.locate import smooth_derivatives, velocity_noise  # physics.locate builds on this module

    sigma = measurement_sigma(rec.q)
    _, v, _ = smooth_derivatives(rec)
    still = np.abs(v) <= HELD_SIGMA * velocity_noise(sigma, rec.dt)[None, :]
    held = np.zeros_like(still)
    for k, j in enumerate(model.movable_joints):
        if not contact[:, k].any():
            continue
        lim, q = j.limits, rec.q[:, k]
        band = _stop_band(sigma[k], lim)
        reach = band + REST_SIGMA * sigma[k]
        near = (q <= lim.lower + reach) | (q >= lim.upper - reach)
        for a, b in _free_runs(~still[:, k]):  # the still stretches
            if contact[a:b, k].any():
                held[a:b, k] = near[a:b]
        for a, b in _free_runs(~held[:, k]):
            # held: long enough to hold anything still, and resting in the band (a drawer stopped
            # by its damping 1.4 cm short of its limit touched the band only with its noise)
            rest = float(np.median(q[a:b]))
            if b - a < MIN_CLEAR_SAMPLES or min(rest - lim.lower, lim.upper - rest) > band:
                held[a:b, k] = False
    return held


def between_nominal_stops(model: ArticulatedModel, rec: Recording) -> Recording:
    """The recording without its stretches in contact with the stops that the model itself
    declares (its URDF limits, within max(5 noise sigma, 1 % of the range)), except where the
    joints in contact are held still there while another joint is clear: those samples are kept
    with :attr:`~kinemaforge_opt.io.recording.Recording.held` set for the held joints, whose
    stop's force, whatever it is, keeps them still in the fits and simulations
    (:func:`locked_accelerations`).  Contact with a known stop is nominal physics, not a
    mismatch, and carries nothing about the joint's dynamics; the model has no law for the stop's
    force, so a lid resting shut under its weight before a hand lifts it was "explained" by a
    spring holding it up.  In contact: a joint back at a stop after it had moved clear (an
    arrival), and a start resting on one pressed into it.  A part merely resting there at the
    start, nothing pressing it (a door before the hand pushes it open), is kept free: its
    breakaway tells friction.

    Every stretch of MIN_CLEAR_SAMPLES or more kept is a piece of its own: what is left out
    between two is a gap (:func:`recording_gaps`; the fits, derivatives and predictions do not
    carry the dynamics across it).  A drawer pulled against its stop and pushed back keeps both
    strokes; two doors that each hit their stops in turn keep each push (the longest clear
    stretch alone was read before: of a refrigerator's 12 s, 3.3 s); a drawer pulled while a door
    rests open on its stop is kept, the door held (that motion was left out before)."""
    contact_j = stop_contact(model, rec)
    if not contact_j.any():
        return rec
    held = held_on_stops(model, rec, contact_j)
    # left out: a joint striking, bouncing on or pushed off a stop, or every joint at a stop
    contact = (contact_j & ~held).any(axis=1) | held.all(axis=1)
    runs = _clear_runs(contact)
    if not runs:
        free = _free_runs(contact)
        start, end = max(free, key=lambda r: r[1] - r[0]) if free.size else (0, 0)
        where = f"from {rec.t[start] - rec.t[0]:.2f} to {rec.t[end - 1] - rec.t[0]:.2f} s (samples {start}–{end - 1})" \
            if end > start else "at no time"
        raise DataError(f"the recording stays clear of the joint stops the model declares at most {where}; "
                        "too little motion to fit")
    keep = np.zeros(rec.t.size, dtype=bool)
    for a, b in runs:
        keep[a:b] = True
    return replace(rec, held=held).rows(keep)


MIN_CLEAR_SAMPLES = 20
"""The fewest samples of a stretch clear of the model's stops that a fit reads (a shorter one is
left out with the contact around it)."""


def _free_runs(contact: np.ndarray) -> np.ndarray:
    """(R, 2) the [start, end) runs of samples out of ``contact`` (T,), in order."""
    return np.flatnonzero(np.diff(np.concatenate([[0], (~contact).astype(int), [0]]))).reshape(-1, 2)


def _clear_runs(contact: np.ndarray) -> list[tuple[int, int]]:
    """The [start, end) runs of samples out of ``contact`` (T,) kept as pieces: MIN_CLEAR_SAMPLES
    or more, and after a left-out stretch of fewer than GAP_INTERVALS samples the next run starts
    later, so that what is left out is a gap (:func:`recording_gaps`), never bridged."""
    runs: list[tuple[int, int]] = []
    least_hole = int(np.floor(GAP_INTERVALS)) + 1  # samples left out so the interval across exceeds GAP_INTERVALS
    for a, b in _free_runs(contact):
        if runs and a - runs[-1][1] < least_hole:
            a = runs[-1][1] + least_hole
        if b - a >= MIN_CLEAR_SAMPLES:
            runs.append((int(a), int(b)))
    return runs


def fit_span(model: ArticulatedModel, recording: Recording) -> tuple[Recording, tuple[str, ...]]:
    """(the part of ``recording`` a fit of ``model`` reads, what was left out in words): the
    recording matched to the model (:func:`match_recording`), without isolated spikes
    (:func:`without_spikes`), between the stops the model declares (:func:`between_nominal_stops`)."""
    whole = match_recording(model, recording)
    clean, spikes = without_spikes(whole)
    rec = between_nominal_stops(model, clean)
    notes = [spike_words(spikes)] if spikes else []
    if rec.t.size < clean.t.size:
        pieces = [f"{rec.t[a] - whole.t[0]:.3g}–{rec.t[b - 1] - whole.t[0]:.3g} s" for a, b in stretches(rec.t)]
        listed = pieces[0] if len(pieces) == 1 else ", ".join(pieces[:-1]) + " and " + pieces[-1]
        notes.append(f"only {listed} of the {whole.t[-1] - whole.t[0]:.3g}-s recording "
                     f"{'was' if len(pieces) == 1 else 'were'} fitted: the rest is a joint pressed on, or "
                     "reaching, a stop the model declares, whose force the model has no law for")
        notes += held_motion_words(model, clean, np.isin(clean.t, rec.t, invert=True))
    if rec.held is not None:
        for k, name in enumerate(model.joint_names):
            if rec.held[:, k].any():
                runs = [(rec.t[a] - whole.t[0], rec.t[b - 1] - whole.t[0]) for a, b in _free_runs(~rec.held[:, k])]
                notes.append(f"{name} rests on a stop in " + ", ".join(f"{a:.3g}–{b:.3g} s" for a, b in runs)
                             + " while another joint moves: the fit holds it still there (the stop's force, "
                             "whatever it is, is not fitted)")
    return rec, tuple(notes)


# A joint's motion left out of the fit is worth naming when it travels at least this many noise
# sigmas (and HELD_MOTION_SHARE of its recorded range) in the samples left out while clear of its
# own stops.
HELD_MOTION_SIGMA = 10.0
HELD_MOTION_SHARE = 0.05


def held_motion_words(model: ArticulatedModel, rec: Recording, left_out: np.ndarray) -> list[str]:
    """Words for each joint that moves in the samples of ``rec`` marked ``left_out`` (T,) while
    clear of its own stops, with the joints in contact with a stop there: the fit reads a
    recording only where every joint is clear of the declared stops or resting on one
    (:func:`between_nominal_stops`), so motion while another joint strikes, creeps along or is
    pushed off a stop is not fitted at all."""
    contact = stop_contact(model, rec)
    sigma = measurement_sigma(rec.q)
    runs = _free_runs(~left_out)  # the stretches left out, each on its own
    out = []
    for k, name in enumerate(model.joint_names):
        least = max(HELD_MOTION_SIGMA * sigma[k], HELD_MOTION_SHARE * float(np.ptp(rec.q[:, k])))
        moved, holders = [], set()
        for a, b in runs:
            own = np.arange(a, b)[~contact[a:b, k]]
            others = {i for i in range(len(model.joint_names)) if i != k and contact[own, i].any()}
            if own.size > 1 and np.ptp(rec.q[own, k]) >= least and others:
                moved.append((own[0], own[-1]))
                holders |= others
        if not moved:
            continue
        spans = ", ".join(f"{rec.t[i] - rec.t[0]:.3g}–{rec.t[j] - rec.t[0]:.3g} s" for i, j in moved)
        held = " and ".join(model.joint_names[i] for i in sorted(holders))
        out.append(f"{name} moves in {spans} while {held} {'touches' if len(holders) == 1 else 'touch'} a stop without "
                   "resting on it (an impact, a creep along it, a push off it): that motion is not fitted (the stop's "
                   "force is modelled only as holding a joint still); record it with the other joints clear of their "
                   "stops or resting on them")
    return out


def fit_spans(model: ArticulatedModel, recordings: Recording | Sequence[Recording]
              ) -> tuple[list[Recording], tuple[str, ...]]:
    """:func:`fit_span` of one recording or of each of several (its words then begin "recording
    k:", 1-based): ([span, ...], what was left out in words)."""
    recs = (recordings,) if isinstance(recordings, Recording) else tuple(recordings)
    if not recs:
        raise DataError("no recording given")
    spans, notes = [], []
    for k, r in enumerate(recs):
        span, words = fit_span(model, r)
        spans.append(span)
        notes += [f"recording {k + 1}: {w}" if len(recs) > 1 else w for w in words]
    return spans, tuple(notes)


def join_recordings(recordings: Sequence[Recording]) -> Recording:
    """Several recordings of the same system as one, end to end on one time axis: each shifted to
    start JOIN_GAP_S (or 2·GAP_INTERVALS of its intervals, if longer) after the one before ends.
    That pause is a gap (:func:`recording_gaps`), so fits, predictions and derivatives restart
    there: each recording is followed from its own state, one model for all.  One recording is
    returned as it is.  The joints must be the same and in the same order, the sample rates within
    a factor of 2 (a gap is counted in median intervals), velocities recorded in all or in none; a
    recording without applied forces beside others with them is driven by nothing (0)."""
    first = recordings[0]
    if len(recordings) == 1:
        return first
    rates = [1.0 / r.dt for r in recordings]
    for k, r in enumerate(recordings[1:], start=2):
        if r.joint_names != first.joint_names:
            raise DataError(f"recording {k} has joints {list(r.joint_names)}, recording 1 {list(first.joint_names)}: "
                            "recordings fitted together must record the same joints")
        if (r.v is None) != (first.v is None):
            raise DataError(f"recording {k} {'has no' if r.v is None else 'has'} velocities v:<joint> and recording 1 "
                            f"{'has' if r.v is None else 'has none'}: give them for all recordings or for none")
    if max(rates) > 2.0 * min(rates):
        k_lo, k_hi = int(np.argmin(rates)) + 1, int(np.argmax(rates)) + 1
        raise DataError(f"recording {k_hi} is sampled at {max(rates):.4g} Hz and recording {k_lo} at "
                        f"{min(rates):.4g} Hz: recordings fitted together must be sampled within a factor of 2 "
                        "(resample one first)")
    pause = max(JOIN_GAP_S, 2.0 * GAP_INTERVALS * max(r.dt for r in recordings))
    shifts, end = [], None
    for r in recordings:
        shifts.append(0.0 if end is None else end + pause - r.t[0])
        end = r.t[-1] + shifts[-1]
    forced = any(r.tau is not None for r in recordings)

    def stack(field):
        parts = [getattr(r, field) for r in recordings]
        if field == "tau" and forced:
            parts = [np.zeros_like(r.q) if a is None else a for r, a in zip(recordings, parts)]
        return None if parts[0] is None else np.concatenate(parts)

    t = np.concatenate([r.t + s for r, s in zip(recordings, shifts)])
    held = None if all(r.held is None for r in recordings) else \
        np.concatenate([np.zeros(r.q.shape, dtype=bool) if r.held is None else r.held for r in recordings])
    return Recording(t, first.joint_names, stack("q"), stack("v"), stack("tau"), held)


def joined_words(spans: Sequence[Recording], joined: Recording) -> str:
    """The sentence that says where each of several recordings lies on the joined time axis."""
    firsts = np.cumsum([0] + [r.t.size for r in spans[:-1]])
    starts = joined.t[firsts]
    where = ", ".join(f"{k + 1} at {a - joined.t[0]:.4g} s" for k, a in enumerate(starts))
    return (f"{len(spans)} recordings fitted together (one model for all, each followed from its own state); "
            f"on the fit's time axis recording {where}")


def check_units(model: ArticulatedModel, rec: Recording) -> None:
    """Raise :class:`DataError` naming the joint when recorded values are implausible for the
    model in SI units: positions far outside the joint's limits (beyond one range width past
    either end — degrees or millimetres recorded as rad or m) or applied forces above 100× the
    joint's effort limit (e.g. N·mm)."""
    for k, j in enumerate(model.movable_joints):
        lim = j.limits
        if lim is None:
            continue
        unit = "m" if j.type == "prismatic" else "rad"
        if np.isfinite(lim.lower) and np.isfinite(lim.upper) and lim.upper > lim.lower:
            span = lim.upper - lim.lower
            lo, hi = float(rec.q[:, k].min()), float(rec.q[:, k].max())
            if lo < lim.lower - span or hi > lim.upper + span:
                hint = "millimetres instead of metres" if unit == "m" else "degrees instead of radians"
                raise DataError(
                    f"recording q:{j.name} spans [{lo:.4g}, {hi:.4g}] but the joint's limits are "
                    f"[{lim.lower:.4g}, {lim.upper:.4g}] {unit}: {hint}?"
                )
        if rec.tau is not None and np.isfinite(lim.effort) and lim.effort > 0:
            peak = float(np.abs(rec.tau[:, k]).max())
            if peak > 100 * lim.effort:
                raise DataError(
                    f"recording tau:{j.name} reaches {peak:.4g}, over 100× the joint's effort limit "
                    f"{lim.effort:.4g} (SI units expected: N·m or N)"
                )


def noise_std(x: np.ndarray) -> np.ndarray:
    """Per-column noise level of a sampled signal (T, n) from its third differences (robust MAD;
    white noise of std s gives third differences of std s·sqrt(20)).  Floored at 1e-9."""
    d3 = np.diff(np.asarray(x, dtype=float), n=3, axis=0)
    mad = np.median(np.abs(d3 - np.median(d3, axis=0)), axis=0)
    return np.maximum(1.4826 * mad / np.sqrt(20.0), 1e-9)


def quantisation_sigma(q: np.ndarray) -> np.ndarray:
    """Per joint (n,), the standard deviation of the rounding error of a quantised sensor [rad or
    m]: its step (the smallest non-zero change between samples of ``q`` (T, n)) / sqrt(12); about
    0 for an unquantised one."""
    d = np.abs(np.diff(np.asarray(q, dtype=float), axis=0))
    d = np.where(d > 1e-12, d, np.inf)
    step = d.min(axis=0) if d.size else np.full(np.shape(q)[1], np.inf)
    return np.where(np.isfinite(step), step, 0.0) / np.sqrt(12.0)


def measurement_sigma(x: np.ndarray) -> np.ndarray:
    """Per column (n,), the measurement error of a sampled signal (T, n) [its units]: the
    high-frequency noise level (:func:`noise_std`), at least the sensor's rounding error
    (:func:`quantisation_sigma`).  A quantised encoder that stands still for most of a recording
    (a real pendulum come to rest) has third differences that are mostly exactly zero, so their
    MAD, and with it noise_std, reads 0: every misfit would then count as millions of sigmas."""
    return np.maximum(noise_std(x), quantisation_sigma(x))


def friction_smoothing(rec: Recording) -> np.ndarray:
    """Per-joint width eps of the smooth sign tanh(v/eps) [rad/s or m/s]: 3 % of the joint's RMS
    speed in the recording.  Relative to the motion, so the friction law is sharp at the speeds
    that carry information whatever the object's size, yet smooth enough for collocation at the
    sampling rate (floored at 1e-4)."""
    v = velocity_estimate(rec)
    return np.maximum(0.03 * np.sqrt(np.mean(v**2, axis=0)), 1e-4)


def limit_side(model: ArticulatedModel, rec: Recording) -> dict[str, tuple[float, float]]:
    """Per joint, the stop the recording comes closest to: (side, position) with side +1 for the
    upper limit, -1 for the lower; a joint without finite limits gets its recorded extreme."""
    out = {}
    for k, j in enumerate(model.movable_joints):
        lo, hi = float(np.min(rec.q[:, k])), float(np.max(rec.q[:, k]))
        lim = j.limits
        if lim is None or not (np.isfinite(lim.lower) and np.isfinite(lim.upper)):
            out[j.name] = (1.0, hi)
        elif lo - lim.lower < lim.upper - hi:
            out[j.name] = (-1.0, lim.lower)
        else:
            out[j.name] = (1.0, lim.upper)
    return out


def grid_locks(rec: Recording, m: int) -> np.ndarray:
    """(n, (T - 1) m) the lock flags (1.0: held still by its stop) of each joint on each
    collocation interval of ``rec``'s grid with ``m`` intervals per sample interval
    (:meth:`~kinemaforge_opt.io.recording.Recording.locks`)."""
    return np.repeat(rec.locks().T.astype(float), m, axis=1)


def collocation_grid(t: np.ndarray, m: int) -> np.ndarray:
    """Collocation times [s] of sample times ``t`` (T,) with ``m`` equal intervals per sample
    interval: (m (T - 1) + 1,), the samples at every m-th point."""
    inner = t[:-1, None] + np.diff(t)[:, None] * (np.arange(m) / m)[None, :]
    return np.concatenate([inner.ravel(), t[-1:]])


def velocity_estimate(rec: Recording) -> np.ndarray:
    """Recorded v, or central differences of q (T, n)."""
    return rec.v if rec.v is not None else np.gradient(rec.q, rec.t, axis=0)


def data_scales(model: ArticulatedModel, rec: Recording) -> DataScales:
    """Typical joint-space magnitudes of ``rec`` under ``model`` (for parameter scaling)."""
    import pinocchio as pin

    pm = build_pin_model(model)
    pd = pm.createData()
    v = velocity_estimate(rec)
    a = np.gradient(v, rec.t, axis=0)
    tau_id = np.array([pin.rnea(pm, pd, q, vv, aa) for q, vv, aa in zip(rec.q, v, a)])
    inertia = np.diag(pin.crba(pm, pd, np.mean(rec.q, axis=0))).copy()
    force = np.sqrt(np.mean(tau_id**2, axis=0))
    if rec.tau is not None:
        force = np.maximum(force, np.sqrt(np.mean(rec.tau**2, axis=0)))
    return DataScales(
        q=np.maximum(np.std(rec.q, axis=0), 1e-3),
        v=np.maximum(np.sqrt(np.mean(v**2, axis=0)), 1e-3),
        force=np.maximum(force, 1e-9),
        inertia=np.maximum(inertia, 1e-12),
    )


def locked_accelerations(dyn: Dynamics, q, v, tau, theta, lock):
    """Joint accelerations (n,) [rad/s² or m/s²] with the joints flagged in ``lock`` (n, 0 or 1)
    held still by their stops, whatever force that takes (CasADi symbols; q, v, tau (n,), theta
    the bridge's parameters).  The free joints' rows of M a = tau - h hold as they are (a stop's
    force acts on its own joint's row only) and each held joint's row is replaced by a_j = 0:
    (diag(1 - l) M + diag(l)) a = (1 - l) ∘ M a_free, where a_free = ABA(q, v, tau) gives
    M a_free = tau - h.  Exact for any tree (a held parent carries its children as a fixed
    base; a held child rides its moving parent), and a_free itself when nothing is held.
    Pinocchio's reduced model (``buildReducedModel``) is the same system with the joint welded;
    the bridge's CasADi functions take one model, so the weld is written here as a constraint."""
    a_free = dyn.aba(q, v, tau, theta)
    M = dyn.crba(q, theta)
    free = 1 - lock
    return ca.solve(ca.diag(free) @ M + ca.diag(lock), free * (M @ a_free))


@dataclass(frozen=True)
class JointSpaceFit:
    """A built (not yet solved) fit: the Problem plus what is needed to read its solution."""

    problem: Problem
    model: ArticulatedModel
    recording: Recording
    blocks: tuple[ParameterBlock, ...]
    effects: dict[str, tuple[str, ...]]
    dynamics: Dynamics
    sigma_q: np.ndarray
    sigma_v: np.ndarray | None
    substeps: int
    segment_starts: tuple[int, ...]  # grid columns whose state is free (no defect leads into them)
    stop_side: dict[str, tuple[float, float]]  # per joint, (side, initial position) of its limit-contact stop
    defect: ca.Function  # (xk, xk1, uk, uk1, h, theta, phi) -> (defect, work, dE)
    theta_names: tuple[str, ...]
    phi_layout: tuple[tuple[str, str], ...]  # (joint, force param) per entry of phi
    phi_fixed: np.ndarray  # values of phi entries that are not free
    phi_free: dict[int, tuple[str, int]]  # phi index -> (block name, index in block)
    defects: ca.Function  # (x (2n, T), z) -> stacked defects; z = scaled free parameters
    residuals: ca.Function  # (x (2n, T)) -> output residuals divided by the noise levels


def active_effects(model: ArticulatedModel, extra: dict[str, tuple[str, ...]] | None = None) -> dict[str, tuple[str, ...]]:
    """Force effects acting on each movable joint: those with non-zero parameters in the model's
    JointDynamics, plus ``extra`` ({joint: (effect type, …)})."""
    out = {j.name: dynamics_effects(j.dynamics) for j in model.movable_joints}
    for joint, types in (extra or {}).items():
        if joint not in out:
            raise UnknownNameError("movable joint", joint, out)
        for t in types:
            if t not in _EFFECT_PARAMS:
                raise UnknownNameError(f"force effect (joint {joint!r})", t, _EFFECT_PARAMS)
        out[joint] = tuple(dict.fromkeys(out[joint] + tuple(types)))
    return out


def build_joint_space_fit(
    model: ArticulatedModel,
    recording: Recording,
    free: tuple[str, ...] | list[str],
    effects: dict[str, tuple[str, ...]] | None = None,
    energy: str = "soft",
    energy_weight: float = 1.0,
    energy_window_s: float = 1.0,
    energy_tolerance: float = 1e-3,
    sigma_q: np.ndarray | None = None,
    substeps: int = 1,
    friction_eps: np.ndarray | float | None = None,
    segment_s: float | None = None,
    limit_stops: dict[str, tuple[float, float]] | None = None,
) -> JointSpaceFit:
    """Build the fit of ``free`` parameters to ``recording`` (see the module docstring).

    recording: must hold q for every movable joint of ``model`` (extra joints are an error).
    free: parameter names (bridge names and ``<joint>.<force param>``; see ``nlp.parameters``).
    effects: force effects to add per joint beyond those in the model ({joint: (type, …)}); their
    parameters must be listed in ``free`` to be fitted, else they stay at the model's values.
    energy: "soft" (penalty with ``energy_weight``), "hard" (|residual| <= ``energy_tolerance`` ×
    energy scale) or "off".
    substeps: collocation intervals per sample interval (>1 resolves fast transients such as
    friction stops between samples).  friction_eps: width of the smooth sign [rad/s or m/s]
    per joint; default :func:`friction_smoothing` of the recording.
    segment_s: if given, the recording is cut into segments of this length [s], each starting from
    its own free initial state (no continuity across cuts): output-error fits of long oscillating
    recordings otherwise get trapped by phase drift (multiple shooting on a coarse grid).
    limit_stops: per joint, (side, initial stop position) of the limit-contact effect (side +1:
    a stop above the motion, -1: below); default :func:`limit_side`.
    """
    if energy not in ("soft", "hard", "off"):
        raise KinemaforgeError(f"energy must be 'soft', 'hard' or 'off', got {energy!r}")
    rec = match_recording(model, recording)

    bridge_names = set(available_parameters(model))
    ratio_names = {f"{l}.inertia_ratio" for l in model.link_names[1:]}
    valid = bridge_names | set(force_parameter_names(model)) | ratio_names
    for name in free:
        if name not in valid:
            raise UnknownNameError("free parameter", name, valid)
    effects = active_effects(model, effects)
    for name in free:  # freeing a force parameter activates its effect
        joint, field = name.rsplit(".", 1)
        if field in FORCE_PARAMS:
            eff = next(e for e, ps in _EFFECT_PARAMS.items() if field in ps)
            if eff not in effects[joint]:
                effects[joint] = effects[joint] + (eff,)

    # A ratio frees the link's inertia block in the bridge, tied to ratio × nominal.
    theta_names = tuple(n for n in free if n in bridge_names) + tuple(
        n[: -len("_ratio")] for n in free if n in ratio_names and n[: -len("_ratio")] not in free
    )
    dyn = build_dynamics(model, free=theta_names)
    held = {j.name: (j.dynamics.limit_side, j.dynamics.limit_stop) for j in model.movable_joints
            if j.dynamics.limit_stiffness > 0}  # stops the model already holds
    stop_side = {**limit_side(model, rec), **held, **(limit_stops or {})}
    scales = data_scales(model, rec)
    n = model.nq

    # phi: every force parameter of every active effect, in a fixed layout.
    phi_layout, phi_fixed = [], []
    for j in model.joint_names:
        nominal = nominal_force_parameters(model, j)
        nominal["limit_stop"] = stop_side[j][1]
        for eff in effects[j]:
            for p in _EFFECT_PARAMS[eff]:
                phi_layout.append((j, p))
                phi_fixed.append(nominal[p])
    phi_fixed = np.asarray(phi_fixed, dtype=float)

    blocks = []
    for name in free:
        if name in bridge_names:
            nominal = dyn.parameter(name).nominal
        elif name in ratio_names:
            nominal = np.array([1.0])
        else:
            joint, field = name.rsplit(".", 1)
            value = stop_side[joint][1] if field == "limit_stop" else nominal_force_parameters(model, joint)[field]
            nominal = np.array([value])
        blocks.append(make_block(model, name, nominal, scales))
    blocks = tuple(blocks)

    # --- symbolic interval function (SX) ---------------------------------------------------
    theta = ca.SX.sym("theta", dyn.theta0.size)
    phi = ca.SX.sym("phi", len(phi_layout))
    eps = friction_smoothing(rec) if friction_eps is None else np.broadcast_to(np.asarray(friction_eps, float), (n,))

    def passive(q, v):
        tau = [ca.SX(0)] * n
        k = 0
        for ji, j in enumerate(model.joint_names):
            for eff in effects[j]:
                ps = _EFFECT_PARAMS[eff]
                args = [phi[k + i] for i in range(len(ps))]
                extra = {"side": stop_side[j][0]} if eff == "limit_contact" else {}
                tau[ji] = tau[ji] + EFFECTS[eff].force(q[ji], v[ji], *args, eps=float(eps[ji]), **extra)
                k += len(ps)
        return ca.vertcat(*tau)

    holds = rec.held is not None  # some joint rests on a stop while another moves: the interval's lock flags count

    def rhs(x, u, lock):
        q, v = x[:n], x[n:]
        force = u + passive(q, v)
        a = locked_accelerations(dyn, q, v, force, theta, lock) if holds else dyn.aba(q, v, force, theta)
        return ca.vertcat(v, a), ca.dot(force, v)

    def energy_of(x):
        q, v = x[:n], x[n:]
        return 0.5 * ca.dot(v, ca.mtimes(dyn.crba(q, theta), v)) + dyn.potential_energy(q, theta)

    xk, xk1 = ca.SX.sym("xk", 2 * n), ca.SX.sym("xk1", 2 * n)
    uk, uk1, h, lk = ca.SX.sym("uk", n), ca.SX.sym("uk1", n), ca.SX.sym("h"), ca.SX.sym("lock", n)
    fk, pk = rhs(xk, uk, lk)
    fk1, pk1 = rhs(xk1, uk1, lk)
    xm = (xk + xk1) / 2 + h / 8 * (fk - fk1)
    fm, pm_ = rhs(xm, (uk + uk1) / 2, lk)
    defect = xk1 - xk - h / 6 * (fk + 4 * fm + fk1)
    work = h / 6 * (pk + 4 * pm_ + pk1)
    d_energy = energy_of(xk1) - energy_of(xk)
    interval = ca.Function(
        "hermite_simpson", [xk, xk1, uk, uk1, h, theta, phi, lk], [defect, work, d_energy],
        ["xk", "xk1", "uk", "uk1", "h", "theta", "phi", "lock"], ["defect", "work", "dE"],
    )

    # --- the NLP ---------------------------------------------------------------------------
    T = rec.t.size
    m = int(substeps)
    if m < 1:
        raise KinemaforgeError(f"substeps must be >= 1, got {substeps}")
    t_grid = collocation_grid(rec.t, m)
    G = t_grid.size  # collocation points; samples sit at columns 0, m, 2m, …
    prob = Problem(f"calibrate_{model.name}")
    v0 = velocity_estimate(rec)
    x_init = np.vstack([np.array([np.interp(t_grid, rec.t, c) for c in rec.q.T]), np.array([np.interp(t_grid, rec.t, c) for c in v0.T])])
    X = prob.variable("x", (2 * n, G), init=x_init)
    Xs = X[:, ::m]
    z = {}
    for b in blocks:
        z[b.name] = prob.variable(f"p:{b.name}", b.size, lower=b.lower / b.scale, upper=b.upper / b.scale, init=b.nominal / b.scale)
    theta_parts = []
    for name in theta_names:
        if name in z:
            b = next(b for b in blocks if b.name == name)
            theta_parts.append(z[name] * b.scale)
        else:  # tied to an inertia ratio
            theta_parts.append(z[name + "_ratio"][0] * dyn.parameter(name).nominal)
    theta_mx = ca.vertcat(*theta_parts) if theta_parts else ca.MX(0, 1)
    phi_free = {}
    phi_entries = []
    for i, (j, p) in enumerate(phi_layout):
        name = f"{j}.{p}"
        b = next((b for b in blocks if b.name == name), None)
        if b is None:
            phi_entries.append(ca.MX(phi_fixed[i]))
        else:
            phi_entries.append(z[name][0] * b.scale[0])
            phi_free[i] = (name, 0)
    phi_mx = ca.vertcat(*phi_entries) if phi_entries else ca.MX(0, 1)

    U = np.array([np.interp(t_grid, rec.t, c) for c in rec.tau.T]) if rec.tau is not None else np.zeros((n, G))
    H = np.diff(t_grid)[None, :]
    mapped = interval.map(G - 1)
    D, Wk, dE = mapped(X[:, :-1], X[:, 1:], U[:, :-1], U[:, 1:], H, theta_mx, phi_mx, grid_locks(rec, m))
    segment_starts = (0,)
    # no continuity across a cut (grid interval index): every segment_s, and at the last substep
    # of a gap in the recording (the gap's own nodes then end the segment before it, with no data)
    gaps = recording_gaps(rec.t)
    cuts = {int(i) * m + m - 1 for i in gaps}
    if segment_s:
        cuts |= {int(c) for c in np.flatnonzero(np.diff(np.floor((t_grid - t_grid[0]) / segment_s)) > 0)}
    if cuts:
        keep = np.setdiff1d(np.arange(G - 1), sorted(cuts))
        segment_starts = (0,) + tuple(c + 1 for c in sorted(cuts))
        prob.add_constraint("dynamics", D[:, keep.tolist()])
        D = D[:, keep.tolist()]
    else:
        prob.add_constraint("dynamics", D)

    sq = measurement_sigma(rec.q) if sigma_q is None else np.broadcast_to(np.asarray(sigma_q, float), (n,))
    Rq = (Xs[:n, :] - rec.q.T) / sq[:, None]
    prob.add_cost("output_q", ca.sumsqr(Rq) / T)
    sv = None
    if rec.v is not None:
        sv = measurement_sigma(rec.v)
        prob.add_cost("output_v", ca.sumsqr((Xs[n:, :] - rec.v.T) / sv[:, None]) / T)

    if energy != "off":
        # The books accumulate along the grid: B[k+1] = B[k] + (dE_k - W_k) / e_scale, B[0] = 0,
        # and a window's residual is B[end] - B[start].  Summing the window's intervals inside
        # one constraint or cost instead gives rows that touch every state of the window: the
        # Jacobian's colouring then needs one sweep per state of a window and a soft cost a dense
        # (2n·window)² Hessian block (a 2-DOF 6-s fit took 50× longer).  Same optimum, sparse.
        per = max(1, int(round(energy_window_s / rec.dt))) * m
        edges = list(range(0, G - 1, per)) + [G - 1]
        booked = np.ones(G - 1)
        booked[[int(i) * m + s for i in gaps for s in range(m)]] = 0.0  # nothing recorded there to book
        e_scale = _energy_scale(model, rec, v0)
        B = prob.variable("energy_books", G, lower=np.r_[0.0, np.full(G - 1, -np.inf)], upper=np.r_[0.0, np.full(G - 1, np.inf)])
        prob.add_constraint("energy_books", B[1:] - B[:-1] - ((dE - Wk) * ca.DM(booked).T).T / e_scale)
        resid = B[edges[1:]] - B[edges[:-1]]
        if energy == "soft":
            prob.add_cost("energy", ca.sumsqr(resid) / len(edges), weight=energy_weight)
        else:
            prob.add_constraint("energy", resid, -energy_tolerance, energy_tolerance)

    for b in blocks:
        if b.name.endswith(".axis"):
            prob.add_constraint(f"unit_axis:{b.name[:-5]}", ca.sumsqr(z[b.name]) - 1.0)

    z_all = ca.vertcat(*[z[b.name] for b in blocks]) if blocks else ca.MX.sym("z", 0)
    outputs = [ca.vec(Rq)] + ([ca.vec((Xs[n:, :] - rec.v.T) / sv[:, None])] if sv is not None else [])

    return JointSpaceFit(
        problem=prob, model=model, recording=rec, blocks=blocks, effects=effects, dynamics=dyn,
        sigma_q=sq, sigma_v=sv, substeps=m, segment_starts=segment_starts, stop_side=stop_side,
        defect=interval, theta_names=theta_names, phi_layout=tuple(phi_layout),
        phi_fixed=phi_fixed, phi_free=phi_free,
        defects=ca.Function("defects", [X, z_all], [ca.vec(D)]),
        residuals=ca.Function("residuals", [X], [ca.vertcat(*outputs)]),
    )


def _energy_scale(model: ArticulatedModel, rec: Recording, v: np.ndarray) -> float:
    """Typical mechanical energy variation of the recording [J]: kinetic + potential spread."""
    import pinocchio as pin

    pm = build_pin_model(model)
    pd = pm.createData()
    E = np.array([pin.computeKineticEnergy(pm, pd, q, vv) + pin.computePotentialEnergy(pm, pd, q) for q, vv in zip(rec.q, v)])
    return float(max(np.ptp(E), 1e-12))
