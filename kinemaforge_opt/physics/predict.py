"""Open-loop predictions of a recording: a model simulated under the recorded forcing, each
span (or each piece of it) from the state that best fits its first ``STATE_WINDOW_S``, and the
before/after comparison (:class:`HeldOut`) that :func:`~kinemaforge_opt.physics.diagnose.diagnose`
and the benchmarks score.  The bridge's ABA integrated by CVODES (CasADi)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..nlp.joint_space import locked_accelerations, recording_gaps
from .locate import running_rms

# Held-out prediction: each model's starting state is fitted over this first part of a span [s]
# (see simulate_recording); the rest of the span is the prediction that is scored.
STATE_WINDOW_S = 0.3
# A piece of a span with fewer samples is not simulated (too few to fit its starting state from).
MIN_PIECE_SAMPLES = 8
# Why an unscored span (:attr:`HeldOut.scored`) has no prediction, in words.
TOO_SPARSE = f"each piece needs {MIN_PIECE_SAMPLES} samples, its first ones fit its starting state"

# Simulations (held-out and fit-span checks): CVODES tolerances (relative, absolute [rad or m]),
# far below the encoder noise; the starting state's least-squares fit differentiates them with
# this fixed step in its scaled variables (q [rad or m], v × window [rad or m]).
SIM_RTOL, SIM_ATOL = 1e-5, 1e-7
STATE_FIT_STEP = 1e-4
# ... and stops once an iteration changes its squared error or its scaled state by less than this
# fraction (a 0.01 % change of the error is far below anything a prediction is judged by;
# MINPACK's default, 1e-8, spent about twice the integrations on digits below the noise).
STATE_FIT_TOL = 1e-4


@dataclass(frozen=True)
class HeldOut:
    """Prediction on the held-out span: RMS joint error [rad or m] and per-joint error (T, n)."""

    t: np.ndarray
    q_rec: np.ndarray
    q_before: np.ndarray
    q_after: np.ndarray

    @property
    def scored(self) -> bool:
        """False when no sample of the span could be predicted (every piece too short to fit its
        starting state from): then both RMS are NaN."""
        return bool(self.t.size)

    @property
    def rms_before(self) -> float:
        return float(np.sqrt(np.mean((self.q_before - self.q_rec) ** 2))) if self.scored else float("nan")

    @property
    def rms_after(self) -> float:
        return float(np.sqrt(np.mean((self.q_after - self.q_rec) ** 2))) if self.scored else float("nan")

    def joint_gains_sigma(self, sigma_q: np.ndarray, signal_sigma: float | None = None) -> np.ndarray:
        """(n,) how much better the after-model predicts each joint, in noise sigmas: the drop of
        the joint's RMS error normalised by its ``sigma_q`` (n,).  signal_sigma: if given, each
        joint's RMS is taken only where either model's error, as a running RMS over
        SIGNAL_WINDOW_S, reaches that many noise sigmas (where both predict to the noise the span
        cannot tell the models apart, and pooling it dilutes the gain: a door stopped dead by a
        rigid stop on its way shut is mispredicted for a fraction of a second); 0 for a joint
        with no such sample."""
        s = np.maximum(np.asarray(sigma_q, float), 1e-12)
        e_b, e_a = ((q - self.q_rec) / s for q in (self.q_before, self.q_after))
        if signal_sigma is None:
            return np.sqrt(np.mean(e_b**2, axis=0)) - np.sqrt(np.mean(e_a**2, axis=0))
        # the phases of predict_before_after repeat times: the period is that of the distinct ones
        period = np.diff(np.unique(self.t))
        w = max(1, int(round(SIGNAL_WINDOW_S / float(np.median(period))))) if period.size else 1
        gains = np.zeros(e_b.shape[1])
        for k in range(e_b.shape[1]):
            m = np.maximum(running_rms(e_b[:, k], w), running_rms(e_a[:, k], w)) >= signal_sigma
            if m.any():
                gains[k] = np.sqrt(np.mean(e_b[m, k] ** 2)) - np.sqrt(np.mean(e_a[m, k] ** 2))
        return gains

    def gain_sigma(self, sigma_q: np.ndarray, signal_sigma: float | None = None) -> float:
        """How much better the after-model predicts, in noise sigmas: the largest of
        :meth:`joint_gains_sigma` — an effect on one joint of several shows on that joint (pooled
        over joints, a well-predicted door diluted the gain of the drawer beside it below a
        sigma)."""
        return float(np.max(self.joint_gains_sigma(sigma_q, signal_sigma)))


SIGNAL_WINDOW_S = 0.25
"""Window of the running RMS error that :meth:`HeldOut.joint_gains_sigma` judges signal by [s]."""


def prediction_signal(h: HeldOut, sigma_q: np.ndarray) -> float:
    """How far the nominal ("before") prediction of a span errs, in noise sigmas: the largest
    per-joint RMS of (q_before - q_rec) / sigma_q.  Below THRESHOLD_SIGMA the span shows nothing
    the nominal model gets wrong (e.g. a pendulum at rest at encoder resolution), so no effect can
    predict it better: it cannot judge one."""
    if h.t.size == 0:
        return 0.0
    return float(np.max(np.sqrt(np.mean((h.q_before - h.q_rec) ** 2, axis=0)) / np.maximum(sigma_q, 1e-12)))


def segment_pieces(rec: Recording, segment_s: float | None, offset_s: float = 0.0) -> list[tuple[np.ndarray, Recording | None]]:
    """The pieces :func:`simulate_segments` simulates ``rec`` in: per piece (its samples' mask
    (T,), the piece as a recording, or None when it has fewer than MIN_PIECE_SAMPLES samples).
    Pieces of ``segment_s`` [s] (one piece without), starting ``offset_s`` [s] into the recording
    (its first ``offset_s`` a piece of its own); a gap in the recording starts a piece too."""
    edges = [rec.t[0]] if not segment_s else \
        sorted({rec.t[0], *np.arange(rec.t[0] + offset_s, rec.t[-1], segment_s)})
    edges = sorted({*edges, *rec.t[recording_gaps(rec.t) + 1]})  # a gap starts a piece of its own
    edges.append(np.inf)
    pieces = []
    for a, b in zip(edges[:-1], edges[1:]):
        m = (rec.t >= a) & (rec.t < b)
        pieces.append((m, rec.window(rec.t[m][0], rec.t[m][-1]) if m.sum() >= MIN_PIECE_SAMPLES else None))
    return pieces


def _simulate_pieces(jobs: list[tuple[ArticulatedModel, list[tuple[np.ndarray, Recording | None]]]],
                     extra: dict | None, workers: int | None) -> list[np.ndarray]:
    """Per job (model, :func:`segment_pieces`), q (T, n) of the model simulated piece by piece
    (:func:`simulate_recording`, each piece from its own best state; NaN over those fitted samples
    and over a piece too short to simulate).  The pieces of all jobs are independent simulations,
    run side by side on ``workers`` processes (:func:`~kinemaforge_opt.parallel.process_map`;
    CVODES holds the GIL)."""
    from ..parallel import process_map

    todo = [(model, piece) for model, pieces in jobs for _, piece in pieces if piece is not None]
    done = iter(process_map(lambda mp: simulate_recording(mp[0], mp[1], extra, state_window_s=STATE_WINDOW_S),
                            todo, workers))
    out = []
    for model, pieces in jobs:
        out.append(np.vstack([next(done) if piece is not None else np.full((int(m.sum()), model.nq), np.nan)
                              for m, piece in pieces]))
    return out


def simulate_segments(model: ArticulatedModel, rec: Recording, segment_s: float | None,
                      extra: dict | None = None, offset_s: float = 0.0, workers: int | None = 1) -> np.ndarray:
    """q (T, n) of ``model`` (plus ``extra`` force laws, see :func:`simulate_recording`) on ``rec``,
    segment by segment when ``segment_s`` [s] is given, each from its own best state over the
    first ``STATE_WINDOW_S`` of a segment; NaN over those fitted samples and over a segment too
    short to estimate a starting state.  offset_s: the segments start this far [s] into the
    recording (its first ``offset_s`` a segment of its own).  workers: processes simulating the
    segments side by side (None: :func:`~kinemaforge_opt.parallel.workers`)."""
    return _simulate_pieces([(model, segment_pieces(rec, segment_s, offset_s))], extra, workers)[0]


def predict_before_after(before: ArticulatedModel, after: ArticulatedModel, rec: Recording, segment_s: float | None,
                         phases: int = 1, workers: int | None = 1) -> HeldOut:
    """Simulated q of both models on ``rec`` (:func:`simulate_segments`), scored where both are
    predictions.  phases: with segments, the span is predicted this many times with the segments
    shifted by segment_s / phases, and the predictions pooled (each sample once per phase): an
    event at a segment's start, where the segment's state is fitted and nothing is predicted,
    is then predicted in another phase (a drawer stopped dead 0.05 s before a segment's edge
    went unseen).  workers: processes simulating the pieces of both models and every phase side
    by side (None: :func:`~kinemaforge_opt.parallel.workers`); the predictions do not depend on it."""
    offsets = [k * segment_s / phases for k in range(phases)] if segment_s else [0.0]
    models = [before] if after is before else [before, after]
    jobs = [(m, segment_pieces(rec, segment_s, offset)) for offset in offsets for m in models]
    q = iter(_simulate_pieces(jobs, None, workers))
    parts = []
    for _ in offsets:
        q_b = next(q)
        q_a = q_b if after is before else next(q)
        ok = ~(np.isnan(q_b).any(axis=1) | np.isnan(q_a).any(axis=1))
        parts.append((rec.t[ok], rec.q[ok], q_b[ok], q_a[ok]))
    return HeldOut(*(np.concatenate(x) for x in zip(*parts)))


def _dynamics_dae(model: ArticulatedModel, extra: dict | None, holds: bool = False) -> dict:
    """The CasADi DAE of ``model`` under a joint force linear in time between samples:
    x = (q, v) (2n,), u = (a, b) (2n,) with tau(t) = a + b t on an interval, ode = (v, ABA(q, v,
    tau + passive)); passive = the model's joint dynamics (the effect library's laws) plus the
    ``extra`` laws f(q, v) per joint name, evaluated on CasADi symbols.  With ``holds``, u also
    carries the interval's lock flags l (n,) (:meth:`~kinemaforge_opt.io.recording.Recording.locks`):
    a held joint stands still on its stop (q' = 0, its velocity ignored) and the others move with
    it held (:func:`~kinemaforge_opt.nlp.joint_space.locked_accelerations`)."""
    import casadi as ca

    from ..symbolic import build_dynamics
    from .effects import EFFECTS, dynamics_effects, effect_arguments

    dyn = build_dynamics(model)
    n = model.nq
    x, u, t = ca.SX.sym("x", 2 * n), ca.SX.sym("u", 3 * n if holds else 2 * n), ca.SX.sym("t")
    q, v = x[:n], x[n:]
    if holds:
        v = (1 - u[2 * n:]) * v
    passive = []
    for k, j in enumerate(model.movable_joints):
        f = 0
        for e in dynamics_effects(j.dynamics):
            params, kwargs = effect_arguments(j.dynamics, e)
            f += EFFECTS[e].force(q[k], v[k], *params, **kwargs)
        if (extra or {}).get(j.name) is not None:
            f += extra[j.name](q[k], v[k])
        passive.append(f)
    tau = u[:n] + u[n: 2 * n] * t + ca.vertcat(*passive)
    a = locked_accelerations(dyn, q, v, tau, dyn.theta0, u[2 * n:]) if holds else dyn.aba(q, v, tau, dyn.theta0)
    return {"x": x, "u": u, "t": t, "ode": ca.vertcat(v, a)}


def _integrate(dae: dict, t: np.ndarray, U: np.ndarray, x0: np.ndarray, opts: dict, cache: dict) -> np.ndarray:
    """States (m, 2n) of ``dae`` at times ``t`` (m,) [s] from ``x0`` (2n,), ``U`` (2n, m - 1) the
    force coefficients per interval.  ``cache`` keeps the integrator of each grid length (a state
    fit integrates one grid many times).  Where CVODES gives up (a diverging law), the longest
    prefix of the grid that integrates is kept, found by bisection, and its last state held."""
    import casadi as ca

    def states(m: int) -> np.ndarray:
        if m < 2:
            return x0[None, :].copy()
        if m not in cache:
            cache[m] = ca.integrator("simulate", "cvodes", dae, float(t[0]), t[1:m].tolist(), opts)
        return np.vstack([x0, cache[m](x0=x0, u=U[:, : m - 1])["xf"].full().T])

    try:
        return states(t.size)
    except RuntimeError:
        good, bad = 1, t.size
        while bad - good > 1:
            mid = (good + bad) // 2
            try:
                states(mid)
                good = mid
            except RuntimeError:
                bad = mid
        x = states(good)
        return np.vstack([x, np.repeat(x[-1:], t.size - good, axis=0)])


def simulate_recording(model: ArticulatedModel, rec: Recording, extra: dict | None = None,
                       state_window_s: float | None = None) -> np.ndarray:
    """q (T, n) of ``model`` simulated over ``rec`` under its recorded tau (linear between
    samples), with the model's joint dynamics plus optional per-joint ``extra`` force laws
    f(q, v) [N·m or N] (written for CasADi symbols).  Pinocchio's ABA (the bridge's, on
    ``casadi.SX``) integrated by CVODES (BDF, error-controlled: the smooth sign of friction is stiff).

    The initial state is the smoothed first state of the recording, or, with ``state_window_s``
    [s], the state that best reproduces (least squares) the model's motion over the first
    ``state_window_s`` of the recording (or its first max(5, 2n + 1) samples, if more) — each
    model gets its own best starting state, as an observer would give it; those samples are then
    fitted, not predicted, and come back as NaN.
    (A state differentiated from a few noisy samples at the edge of a span can be so far off
    that it dominates the prediction error of every model alike.)"""
    from scipy.optimize import least_squares

    from .locate import smooth_derivatives

    n = model.nq
    holds = rec.held is not None
    dae = _dynamics_dae(model, extra, holds)
    q0, v0, _ = smooth_derivatives(rec)
    tau = rec.tau if rec.tau is not None else np.zeros((rec.t.size, n))
    slope = np.diff(tau, axis=0) / np.diff(rec.t)[:, None]
    # per interval: tau = a + b t, then the lock flags if a joint is held somewhere
    U = np.hstack([tau[:-1] - slope * rec.t[:-1, None], slope] + ([rec.locks()] if holds else [])).T
    # max_step_size: one sample interval, so a force pulse after a free coast is never stepped
    # over; csparse: CVODES's default dense QR fails (too much work) on the 1e-156 entries the
    # stop's softplus puts in the Jacobian far from the stop
    opts = {"reltol": SIM_RTOL, "abstol": SIM_ATOL, "max_step_size": float(np.min(np.diff(rec.t))),
            "linear_solver": "csparse"}
    cache: dict = {}

    def run(x0: np.ndarray, m: int) -> np.ndarray:  # q (m, n) over the first m samples
        return _integrate(dae, rec.t[:m], U, x0, opts, cache)[:, :n]

    x0 = np.concatenate([q0[0], v0[0]])
    window = np.zeros(rec.t.size, dtype=bool)
    if state_window_s:
        # at least enough samples to fit the 2n state components from (a slow recording's first
        # 0.3 s may hold two or three)
        need = max(5, 2 * n + 1)
        window = rec.t <= rec.t[0] + max(state_window_s, (rec.t[min(need, rec.t.size) - 1] - rec.t[0]))
        m = int(window.sum())
        if m >= need and m < rec.t.size:
            scale = np.concatenate([np.full(n, 1.0), np.full(n, 1.0 / max(rec.t[m - 1] - rec.t[0], 1e-9))])

            seen: dict[bytes, np.ndarray] = {}  # residuals by z: MINPACK asks for the Jacobian where it just evaluated them

            def resid(z):
                key = np.asarray(z, float).tobytes()
                if key not in seen:
                    seen.clear()
                    seen[key] = (run(z * scale, m) - rec.q[window]).ravel()
                return seen[key]

            def jac(z):
                # forward differences with a fixed step, far above the integration error (MINPACK's
                # default relative step, ~1e-8, is below it: the Jacobian was noise and the state
                # fit landed anywhere)
                r0 = resid(z)
                return np.stack([(resid(z + STATE_FIT_STEP * e) - r0) / STATE_FIT_STEP for e in np.eye(z.size)], axis=1)

            fit = least_squares(resid, x0 / scale, jac=jac, method="lm", ftol=STATE_FIT_TOL, xtol=STATE_FIT_TOL)
            x0 = fit.x * scale
        else:
            window[:] = False
    q = run(x0, rec.t.size)
    q[window] = np.nan
    return q
