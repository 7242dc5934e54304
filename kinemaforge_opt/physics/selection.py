"""The explain stage of :func:`~kinemaforge_opt.physics.diagnose.diagnose`: stepwise selection
over the effect library on the search grid (:class:`EffectSearch`), its checks, the full-rate
re-fits with 95 % intervals, and the reported effects (:class:`FoundEffect`).  The module doc of
:mod:`.diagnose` states the procedure; the thresholds are here."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..calibration import Calibration
from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..model.pinocchio import build_pin_model, joint_space_inertia
from ..nlp.joint_space import build_joint_space_fit, match_recording, velocity_estimate
from ..parallel import process_map
from .locate import THRESHOLD_SIGMA, block_means, inverse_dynamics_residual, motion_window, velocity_noise
from .predict import HeldOut, predict_before_after, prediction_signal
from .prescreen import STOP_START, inertia_columns, limit_stop_guess, linear_init, screen_scores, stop_ramp_fraction
from .search import CPU_CAP_STATUS, HypothesisFit, Trial, effect_parameters

DELTA_BIC = -10.0

# Force effects that act on a part at rest, so can hold it against a stop (:meth:`EffectSearch.stop_pair`).
HOLDING_EFFECTS = frozenset({"spring", "constant_bias"})

# What a recording without an applied force cannot determine (EffectSearch.identifiable).
UNFORCED_WORDS = ("no applied force was recorded: the data fix the links' inertia only relative to one another and "
                  "the joint forces only relative to the inertia, so the forces found are in the units of the model's "
                  "inertia, and a common scale of every moving link's inertia is not tested")

# An accepted effect must also matter: it must move the fitted trajectory by at least this RMS,
# in units of the encoder noise (else it only polishes residual model-form error).
MIN_EFFECT_SIZE_SIGMA = 1.0

# A hypothesis whose fit has not converged after this many IPOPT iterations is not accepted
# (well-posed candidates converge in 5–30).
CANDIDATE_MAX_ITER = 200

# BIC counts every residual (N).  Counting only independent ones, N (1 - rho)/(1 + rho) from the
# residual autocorrelation, was tried: it curbed polishing of model-form error but discounted the
# first effect of a pair (whose fit still misses the second) below the threshold; the effect-size
# floor and the final held-out check do that job instead.  Kept as a switch for experiments.
EFFECTIVE_N = False

# Two hypotheses whose fits differ by less than this in log-likelihood (2 ln L on the effective
# sample count) explain the recording equally well ("not worth more than a bare mention",
# Kass & Raftery 1995): the chosen one is reported with the other as an equivalent explanation.
EQUIVALENT_LOGLIK = 2.0

# The selected effects must also simulate the fit span better than the nominal model, in pieces
# of this length [s] (each from its own state over its first STATE_WINDOW_S).
SIMULATION_CHECK_S = 1.0

# Per selection round (and per swap), only this many hypotheses get an NLP fit: those that best
# reduce the inverse-dynamics residual force in a linear least-squares pre-screen (a ranking, not
# evidence: the NLP fit and its ΔBIC still decide).
SCREEN = 5

# A hypothesis that adds one of these effects starts its states from the recording, not from the
# parent fit's trajectory (see EffectSearch.trial_of); one that adds only smooth effects starts
# from the parent's.
STATES_FROM_DATA = frozenset({"limit_contact", "coulomb_friction", "stribeck_friction"})

# Selection stops after this many effects (a bound on the search's cost, not a prior on the
# system: on the real Qube the fifth, arm Coulomb friction, is the one its recordings need; with 4
# it was never tested).
MAX_EFFECTS = 6

# Per selection round, at most this many hypotheses below the model-form floor (strongest ΔBIC
# first) are judged by their prediction of another recording (:meth:`EffectSearch.prediction_gate`).
PREDICTION_TRIES = 3

# How many times a selection round may be re-run after the chosen effects were re-fitted to a
# better optimum from a candidate's solution (see :meth:`EffectSearch.unless_parent_fits_as_well`).
MAX_PARENT_REFITS = 2

# Effect types tested, in order; the parameters freed for each are its EFFECTS[type].params
# (first = reported value).
CANDIDATES: tuple[str, ...] = (
    "viscous_damping", "coulomb_friction", "spring", "constant_bias", "quadratic_drag",
    "stribeck_friction", "axis_tilt", "inertia_error", "limit_contact",
)

# A selection round of at most this many hypotheses, one joint's whole library, is fitted whole
# whatever ``screen`` says (a swap's candidates are still screened).  Over a short stroke of a
# heavy part, damping, Coulomb friction and quadratic drag are nearly collinear forces, and their
# order in the pre-screen is the noise of the measured accelerations: a 4-kg drawer's damping of
# 3.0 ranked sixth and the search settled on Coulomb friction + drag, as did a door whose
# recording lost 2 s of 7.  On one joint fitting the rest costs ~0.5 s of a 10-s recording's
# diagnosis; on more joints the ranking's savings keep the search affordable (the Qube: 18
# hypotheses a round).
FIT_WHOLE_ROUND = len(CANDIDATES)


@dataclass(frozen=True)
class FoundEffect:
    """A selected effect: DESIGN.md ``type``, ``value`` in ``unit``, ``ci95``, ``delta_bic``, and
    extra ``params`` (e.g. spring ``rest``, tilt ``axis_world``)."""

    joint: str
    type: str
    value: float
    unit: str
    ci95: tuple[float, float]
    delta_bic: float
    params: dict

    def to_dict(self) -> dict:
        return {"joint": self.joint, "type": self.type, "value": self.value, "unit": self.unit,
                "ci95": list(self.ci95), "delta_bic": self.delta_bic, "params": self.params}


def span_words(span: str | None) -> str:
    """Plain words for an acceptance-check span name ("held_out", "other_recording_<k>")."""
    if span == "held_out":
        return "held-out span"
    if span and span.startswith("other_recording_"):
        return f"other recording {span.rsplit('_', 1)[1]}"
    return "held-out span"


def _reported_value(model: ArticulatedModel, joint: str, effect: str, values: dict) -> float:
    """DESIGN.md ``value`` of ``effect`` on ``joint`` from fitted parameter values (tilt: the angle
    between fitted and nominal axis [rad])."""
    name = effect_parameters(model, joint, effect)[0]
    if effect == "axis_tilt":
        a = np.asarray(values[name], float)
        return float(np.arccos(np.clip(abs(np.dot(a / np.linalg.norm(a), model.joint(joint).axis)), -1, 1)))
    return float(np.asarray(values[name]).ravel()[0])


def _model_of(model: ArticulatedModel, trial: Trial, stops: dict) -> ArticulatedModel:
    """``model`` with the free parameters of ``trial`` at their fitted values (a limit contact's
    stop on the side :func:`limit_stop_guess` gave it)."""
    from ..calibration import apply_parameters

    return apply_parameters(model, {n: trial.values[n] for n in trial.free}, stops)


def rss_q(q_fit: np.ndarray, q_rec: np.ndarray, sigma_q: np.ndarray) -> float:
    return float(np.sum(((q_fit - q_rec) / sigma_q) ** 2))


def delta_bic(rss: float, rss0: float, k: int, n_eff: float) -> float:
    """BIC of a fit of residual sum of squares ``rss`` with ``k`` more free parameters than one
    of ``rss0``, minus that one's, on ``n_eff`` effective samples (negative: better)."""
    return float(n_eff * np.log(rss / rss0) + k * np.log(n_eff))


def effective_count(residuals: np.ndarray) -> float:
    """Number of independent residuals among ``residuals`` (T, n): N (1 - rho)/(1 + rho), rho the
    pooled lag-1 autocorrelation of the per-joint series (white noise keeps N)."""
    from ..nlp.sensitivity import lag1_autocorrelation

    rho = lag1_autocorrelation(np.atleast_2d(residuals.T))
    return float(residuals.size * (1 - rho) / (1 + rho))


def _at_bound_values(trial: Trial, names: list[str], nominal_z: dict) -> bool:
    """True when the effect's reported parameter sits at its physical lower bound (zero) where the
    model already had it (the fit did not move it: it explains nothing); a parameter the model
    had non-zero and the data drives to zero is a finding."""
    name = names[0]
    if name.endswith(".limit_stop"):  # no stiffness, or a stop pinned at the edge of where it is identifiable
        lo, hi = (trial.bounds or {}).get(name, (-np.inf, np.inf))
        stop = trial.values[name][0]
        at_edge = min(abs(stop - lo), abs(stop - hi)) <= 1e-6 * max(1.0, abs(stop))
        return bool(abs(trial.z[names[1]][0]) <= 1e-6 or at_edge)
    if name.endswith(".stribeck"):  # a speed scale pinned at the top of its identifiable range is Coulomb friction
        lo, hi = (trial.bounds or {}).get(names[1], (-np.inf, np.inf))
        vs = trial.values[names[1]][0]
        if abs(vs - hi) <= 1e-3 * abs(hi):
            return True
    if name.endswith((".axis", ".inertia_ratio", ".spring_rest", ".bias")):
        return False
    return bool(abs(trial.z[name][0]) <= 1e-6 and abs(nominal_z[name][0]) <= 1e-6)


def _calibration(model: ArticulatedModel, rec: Recording, trial: Trial, effects: list[tuple[str, str]],
                 stops: dict, segment_s: float | None, sigma_q: np.ndarray, eps: np.ndarray | None = None,
                 fit=None) -> Calibration:
    """A :class:`Calibration` of ``model`` with the parameters of ``effects`` at the values of
    ``trial`` (95 % intervals from the fit's sensitivity).  fit: the joint-space fit of exactly
    those parameters on ``rec`` if already built (a :class:`HypothesisFit`'s), else built here."""
    from ..calibration import _result
    from ..nlp.problem import Result

    if fit is None:
        names = [n for j, e in effects for n in effect_parameters(model, j, e)]
        fit = build_joint_space_fit(model, rec, names, energy="off", segment_s=segment_s, limit_stops=stops,
                                    sigma_q=sigma_q, friction_eps=eps)
    z = np.concatenate([trial.z[b.name] for b in fit.blocks]) if fit.blocks else np.zeros(0)
    res = Result(trial.success, trial.status, trial.iterations, float("nan"), {}, {}, {}, trial.solve_time_s)
    return _result(fit, res, trial.X, z, trial.solve_time_s)


def interval_holds_off(model: ArticulatedModel, joint: str, effect: str, final: Calibration,
                        motion: tuple[float, float] | None = None) -> float | None:
    """For an effect the model lacked (its parameter's nominal is its "off" value: zero force,
    unit inertia ratio, the nominal axis), how far inside its 95 % interval the off value sits
    (0 at an end, 1 in the middle), or None when the interval excludes it (a supported effect) or
    the model already had it.  A stop has no off value of its position; it is unsupported (1.0)
    when its position's interval holds the whole recorded ``motion`` (lowest, highest position):
    the data cannot place it, and what it fits is a one-sided spring over the motion."""
    e = final.estimates[effect_parameters(model, joint, effect)[0]]
    if effect == "axis_tilt":
        angle = _reported_value(model, joint, effect, {e.name: e.value})
        half = e.ci95_angle_rad
        return None if half is None or not np.isfinite(half) or angle > half else 1.0 - angle / max(half, 1e-300)
    if _model_had(model, joint, effect, e):
        return None
    lo, hi = float(np.ravel(e.ci95_low)[0]), float(np.ravel(e.ci95_high)[0])
    if effect == "limit_contact":
        return 1.0 if motion is not None and lo <= motion[0] and hi >= motion[1] else None
    off = _off_value(effect)
    if not (np.isfinite(lo) and np.isfinite(hi)) or not lo <= off <= hi or hi <= lo:
        return None
    return 1.0 - abs(2.0 * off - lo - hi) / (hi - lo)


def _interval_words(model: ArticulatedModel, joint: str, effect: str, final: Calibration,
                    motion: tuple[float, float]) -> str:
    """Why :func:`interval_holds_off` finds ``effect`` unsupported, in words with the numbers."""
    e = final.estimates[effect_parameters(model, joint, effect)[0]]
    if effect == "axis_tilt":
        return f"the tilt's 95% interval (±{e.ci95_angle_rad:.3g} rad) holds the nominal axis"
    lo, hi = float(np.ravel(e.ci95_low)[0]), float(np.ravel(e.ci95_high)[0])
    if effect == "limit_contact":
        return (f"the stop's 95% interval [{lo:.4g}, {hi:.4g}] {e.unit} holds every recorded position, "
                f"{motion[0]:.4g} to {motion[1]:.4g} {e.unit}: the data cannot place it")
    return f"its 95% interval [{lo:.4g}, {hi:.4g}] {e.unit} holds its off value {_off_value(effect):g}"


def _off_value(effect: str) -> float:
    """The value of an effect's first parameter that switches it off (unit inertia ratio, else 0)."""
    return 1.0 if effect == "inertia_error" else 0.0


def _model_had(model: ArticulatedModel, joint: str, effect: str, estimate) -> bool:
    """Whether ``model`` already had ``effect`` on ``joint`` (so a fit changed its value): a stop
    its dynamics hold, or a first parameter whose nominal ``estimate`` is not the off value."""
    if effect == "limit_contact":
        return model.joint(joint).dynamics.limit_stiffness > 0
    return abs(float(np.ravel(estimate.nominal)[0]) - _off_value(effect)) > 1e-12


def n_free_params(names: list[str]) -> int:
    """Free scalar parameters of the named blocks (an axis direction has 2)."""
    return sum(2 if n.endswith(".axis") else 1 for n in names)


def _axis_world(model: ArticulatedModel, joint: str) -> np.ndarray:
    import pinocchio as pin

    pm = build_pin_model(model)
    pd = pm.createData()
    pin.forwardKinematics(pm, pd, np.zeros(pm.nq))
    j = model.joint(joint)
    return pd.oMi[pm.getJointId(joint)].rotation @ j.axis


class EffectSearch:
    """The explain stage (module doc, step 2) on the search grid ``srch``: the shared hypothesis
    fits, the nominal fit, and the selection as it stands — ``selected`` [(joint, effect, ΔBIC)],
    its fit ``current``, the alternatives that fit as well as each selected effect
    (``equivalents``), the record of every test (``tested``) and the effects each later check
    dropped (``dropped``).  Its methods are the stages of the selection, run in order by
    :func:`~kinemaforge_opt.physics.diagnose.diagnose`.

    sigma_q (n,): the measurement error of one recorded sample (at least the sensor's rounding
    error; a span's nominal prediction error must pass THRESHOLD_SIGMA of it to show signal);
    sigma_s (n,): the noise of the search grid's block means; eps (n,): the smooth-sign width [rad/s or m/s].  workers: processes
    for a round's independent hypothesis fits (None: :func:`~kinemaforge_opt.parallel.workers`).
    fit_rec: the full-rate fit span whose block means ``srch`` is (the pre-screen's derivatives
    come from it).  cpu_cap_s: IPOPT's CPU-time cap of each hypothesis fit [s] (None: the
    default of :class:`~kinemaforge_opt.physics.search.HypothesisFit`)."""

    def __init__(self, model: ArticulatedModel, srch: Recording, sigma_q: np.ndarray, sigma_s: np.ndarray,
                 eps: np.ndarray, candidates: tuple[str, ...], segment_s: float | None,
                 screen: int | None, other_recordings: tuple[Recording, ...], say, fit_rec: Recording,
                 workers: int | None = None, cpu_cap_s: float | None = None):
        self.model, self.srch = model, srch
        self.workers, self.cpu_cap_s = workers, cpu_cap_s
        self.sigma_q, self.sigma_s, self.eps = sigma_q, sigma_s, eps
        self.candidates, self.segment_s, self.screen = candidates, segment_s, screen
        self.other_recordings, self.say = other_recordings, say
        self.stops = limit_stop_guess(model, srch)
        # Without an applied force the equations of motion hold for any common scale of every
        # moving link's inertia (mass included, so gravity's torque too) and every joint force:
        # the data fix inertia only relative to other links' (:meth:`identifiable`).
        self.forced = srch.tau is not None and bool(np.any(srch.tau != 0.0))
        self.moving_links = {j.child for j in model.movable_joints}
        self.hyps = [(j, e) for j in model.joint_names for e in candidates if e != "axis_tilt"]
        self.fits = {"base": HypothesisFit(model, srch, self.hyps, segment_s, self.stops, CANDIDATE_MAX_ITER,
                                           sigma_s, eps, max_cpu_s=cpu_cap_s)}
        self.nominal_trial = self.fits["base"].solve([])
        self.nominal_z = {n: self.fits["base"].nominal_z(n) for n in self.fits["base"].blocks}
        self.v_scale = np.sqrt(np.mean(velocity_estimate(srch) ** 2, axis=0))
        # the missing generalised force on the search grid: derivatives of the full-rate fit span
        # under a window short against the motion (a fast swing's acceleration, smoothed over a
        # long window, comes out low, and the pre-screen's inertia column "explains" that error),
        # then block means (full-rate accelerations alone are mostly differentiated noise, which
        # the inertia column would "explain" too)
        block = max(1, int(round(srch.dt / fit_rec.dt)))
        window_s = motion_window(fit_rec)
        self.r_nom, self.q_s, self.v_s, a_s = inverse_dynamics_residual(model, fit_rec, window_s, block)
        self.v_noise = velocity_noise(sigma_q, fit_rec.dt, window_s, block)
        self.id_force = inertia_columns(model, self.q_s, self.v_s, a_s,
                                        block_means(fit_rec.tau, block, fit_rec.t) if self.forced else None)
        self.nominal_model = _model_of(model, self.nominal_trial, self.stops)
        self.n_res = srch.q.size
        # per joint, the fraction of the recorded range inside the extreme a new stop's fit starts at
        self.stop_start = {j: STOP_START for j in model.joint_names}
        self.lone_stops: dict[str, Trial] = {}  # per joint, the stop alone fitted from the nominal fit
        if "limit_contact" in candidates:
            self.choose_stop_starts()
        # The prediction gate's judge (``prediction_gate``): the first other recording whose
        # nominal prediction errs by THRESHOLD_SIGMA noise sigmas or more, found on first use.
        self.judge: dict = {}
        self.selected: list[tuple[str, str, float]] = []
        self.gated_in: set[tuple[str, str]] = set()  # selected through prediction_gate
        self.equivalents: dict[tuple[str, str], list[dict]] = {}
        self.tested: list[dict] = []
        self.dropped: dict[str, list[str]] = {}
        self.current = self.nominal_trial
        if not self.forced:
            self.tested.append({"identifiability": UNFORCED_WORDS})

    def identifiable(self, effects: list[tuple[str, str]]) -> bool:
        """Whether the recording can tell the (joint, effect) set from its equivalents: without an
        applied force, a set that frees the inertia of every moving link holds their common scale,
        which only trades against the joint forces' (a pendulum three times lighter with a third
        of the damping swings the same), so it is not tested; the joint forces found are then in
        the units of the model's inertia (module doc of :mod:`.diagnose`)."""
        if self.forced:
            return True
        freed = {self.model.joint(j).child for j, e in effects if e == "inertia_error"}
        return not self.moving_links <= freed

    # --- fits ------------------------------------------------------------------------------

    def rss(self, trial: Trial) -> float:
        """Noise-normalised residual sum of squares of ``trial``'s fit of the search grid."""
        return rss_q(trial.q_fit, self.srch.q, self.sigma_s)

    def chosen(self) -> list[tuple[str, str]]:
        """The selected (joint, effect) pairs."""
        return [x[:2] for x in self.selected]

    def fit_for(self, effects: list[tuple[str, str]]) -> HypothesisFit:
        """The shared fit that holds ``effects`` (one with symbolic axes only when a tilt is among
        them: the symbolic axis makes the fit's build dearer, so it is built on demand)."""
        if not any(e == "axis_tilt" for _, e in effects):
            return self.fits["base"]
        if "axis" not in self.fits:
            tilts = [(j, "axis_tilt") for j in self.model.joint_names if "axis_tilt" in self.candidates]
            self.fits["axis"] = HypothesisFit(self.model, self.srch, self.hyps + tilts, self.segment_s, self.stops,
                                              CANDIDATE_MAX_ITER, self.sigma_s, self.eps, max_cpu_s=self.cpu_cap_s)
        return self.fits["axis"]

    def trial_of(self, effects: list[tuple[str, str]], start: Trial) -> Trial:
        """The hypothesis ``effects`` fitted from the values ``start`` holds, with states from the
        data when it adds a stop or dry friction (else from ``start``'s trajectory); a new force
        coefficient starts from its inverse-dynamics estimate, a new stop from its joint's
        :attr:`stop_start` (:meth:`choose_stop_starts`)."""
        if start is self.nominal_trial and len(effects) == 1 and effects[0][0] in self.lone_stops \
                and effects[0][1] == "limit_contact":
            return self.lone_stops[effects[0][0]]
        return self.trial_from(effects, start, self.stop_start)

    def choose_stop_starts(self) -> None:
        """Per joint, fit a stop alone from the nominal fit starting STOP_START inside the
        recorded extreme and, where it differs, from the pre-screen ramp's best start
        (:func:`~.prescreen.stop_ramp_fraction` of the nominal residual force).  The
        ramp's start is where every later new stop on that joint starts if its fit converged and
        beat the other's by the selection margin (DELTA_BIC; a start better by the noise, on a
        recording with no stop, made a later pair's fit run to its iteration cap).  Why two: a
        stiff stop barely touched (a drawer run 1.6 mm into a 5000 N/m stop at 30 Hz: a few
        samples in contact) has local minima in its position: from 5 % inside, one seed's fit
        stalled at 0.172 m (ΔBIC -126 against the oracle's -902), another's at 0.185 m; from the
        ramp's 2 % both reach 0.197 / 0.200 m for 0.2.  Both starts for every stop fit cost the
        10-s door 0.7 s more."""
        ramp = {j: stop_ramp_fraction(self.q_s[:, k], self.r_nom[:, k], side, stop)
                for k, (j, (side, stop)) in enumerate(self.stops.items())}
        starts = [(j, x) for j, f in ramp.items() if f != STOP_START for x in (STOP_START, f)]
        fits = dict(zip(starts, process_map(
            lambda jx: self.trial_from([(jx[0], "limit_contact")], self.nominal_trial, {jx[0]: jx[1]}),
            starts, self.workers)))
        for j, f in ramp.items():
            if f == STOP_START:
                continue
            default, alt = fits[(j, STOP_START)], fits[(j, f)]
            gain = delta_bic(self.rss(alt), self.rss(default), 0, self.sample_count(alt))
            better = alt.success and (not default.success or gain < DELTA_BIC)
            self.stop_start[j], self.lone_stops[j] = (f, alt) if better else (STOP_START, default)

    def trial_from(self, effects: list[tuple[str, str]], start: Trial, stop_start: dict[str, float]) -> Trial:
        """:meth:`trial_of` with a new stop on joint j starting ``stop_start[j]`` of the recorded
        range inside the recorded extreme on its side."""
        model, srch = self.model, self.srch
        names = [n for j, e in effects for n in effect_parameters(model, j, e)]
        init, bounds, coefficient = {}, {}, {}
        from_data = False  # states from the recording (see below)
        for j, e in effects:
            k = model.joint_index(j)
            carried = all(n in start.free for n in effect_parameters(model, j, e))  # values from the parent fit
            from_data |= not carried and e in STATES_FROM_DATA
            if not carried:
                lin = linear_init(model, j, e, start, self.r_nom, self.q_s, self.v_s, self.eps, self.v_scale)
                first = effect_parameters(model, j, e)[0]
                init.update({n: x for n, x in lin.items() if n != first})
                if first in lin:
                    coefficient[first] = lin[first]
            if e == "stribeck_friction":
                # A Stribeck excess is static friction that fades with speed: identifiable only if
                # it fades within the recorded speeds (else it is Coulomb friction by another name).
                b = self.fit_for([(j, e)]).blocks[f"{j}.v_stribeck"]
                bounds[f"{j}.v_stribeck"] = (float(b.lower[0]), 0.5 * float(np.max(np.abs(self.v_s[:, k]))))
            if e == "limit_contact":  # start in contact, stop_start[j] of the range before the extreme, with a stiffness
                # whose force over 5 % of the range is the recording's force scale
                span = float(np.ptp(srch.q[:, k]))
                # A stop is identifiable only if the recording both moves free of it and touches
                # it: keep it inside the half of the recorded range on its side (else a "stop"
                # beyond all the data is just a spring), give or take the noise (a rigid stop sits
                # at the recorded extreme, which the noise puts on either side of it).
                lo, hi = float(srch.q[:, k].min()), float(srch.q[:, k].max())
                margin = 3.0 * float(self.sigma_s[k])
                side, stop = self.stops[j]
                bounds[f"{j}.limit_stop"] = (lo + 0.5 * span, hi + margin) if side > 0 \
                    else (lo - margin, hi - 0.5 * span)
                bounds.update(self.rigid_bounds(j))
                if carried:
                    continue
                init[f"{j}.limit_stop"] = np.array([stop - side * stop_start[j] * span])
                init[f"{j}.limit_stiffness"] = self.fit_for([(j, e)]).blocks[f"{j}.limit_stiffness"].scale * 0.01 \
                    * float(np.std(srch.q[:, k])) / (0.05 * span)
        # A new stop or dry friction starts its states from the recording, not the parent's
        # trajectory: a stop can act where the data went but the parent's fit did not, and a
        # parent trajectory can hold a new dry-friction coefficient in a poor basin.  A smooth
        # effect (damping, spring, bias, drag, tilt, inertia) starts from the parent's trajectory,
        # which already follows the data: on the 10-s door 337 -> 291 IPOPT iterations, the same
        # findings on the quick discovery set.
        hf = self.fit_for(effects)
        if coefficient:
            # Dry friction and stops make the fit multimodal: the new coefficients start from
            # their inverse-dynamics estimate, and only if that fit does not converge from their
            # "off" values too.  (With both starts always run, on the 23 cases of the quick
            # discovery set at 100 Hz, the off start never fitted better than a converged
            # estimate start: 134 of 145 pairs alike, 5 better from the estimate, 4 where only
            # the off start converged.)
            trial = hf.solve(names, start=start, init={**init, **coefficient}, states_from_data=from_data, bounds=bounds)
            if trial.success or trial.status == CPU_CAP_STATUS:
                # a hypothesis that used up its CPU budget gets no second one
                return trial
        return hf.solve(names, start=start, init=init, states_from_data=from_data, bounds=bounds)

    def rigid_bounds(self, joint: str) -> dict[str, tuple[float, float]]:
        """Upper bounds of a stop's stiffness and contact damper on ``joint``: those that stop the
        fastest recorded motion (speed v, what the joint moves M at the recorded extreme on the
        stop's side) within one noise sigma s of penetration, k = M v² / s² (its kinetic energy
        stored) and c = 2 M v / s² (dissipated by the damper alone).  A stiffer stop cannot be told
        from a rigid one by these data, and without a bound the fit of a rigid stop (Drake's joint
        limit) ran both to infinity and to its iteration cap, or held the part off the tail of
        its contact's rounded corner 3 mm before the stop."""
        k = self.model.joint_index(joint)
        side, _ = self.stops[joint]
        at = self.srch.q[np.argmax(side * self.srch.q[:, k])]
        M = float(joint_space_inertia(self.model, at)[k, k])
        v = float(np.max(np.abs(self.v_s[:, k])))
        s = float(self.sigma_s[k])
        return {f"{joint}.limit_stiffness": (0.0, M * v**2 / s**2), f"{joint}.limit_damping": (0.0, 2.0 * M * v / s**2)}

    def trials(self, hypotheses: list[list[tuple[str, str]]], start: Trial) -> list[Trial]:
        """:meth:`trial_of` of each of ``hypotheses`` from ``start``, in forked processes on up to
        ``workers`` cores (independent fits; see :func:`~kinemaforge_opt.parallel.process_map`).
        The shared fits they need are built here first, so no process builds one for itself, and
        the fits with symbolic axes go first: their Hessians cost about ten times a force law's
        (docs/NOTES.md), and taken last they would leave one core idle while another finishes them."""
        dear_first = sorted(range(len(hypotheses)), key=lambda i: self.fit_for(hypotheses[i]) is self.fits["base"])
        trials = process_map(lambda i: self.trial_of(hypotheses[i], start), dear_first, self.workers)
        return [trials[dear_first.index(i)] for i in range(len(hypotheses))]

    def trial_of_parent(self, effects: list[tuple[str, str]], start: Trial) -> Trial:
        """The hypothesis ``effects`` fitted from ``start``'s states and values (its other
        effects fixed off)."""
        names = [n for j, e in effects for n in effect_parameters(self.model, j, e)]
        return self.fit_for(effects).solve(names, start=start,
                                           bounds={n: b for n, b in (start.bounds or {}).items() if n in names})

    def model_of(self, trial: Trial) -> ArticulatedModel:
        return _model_of(self.model, trial, self.stops)

    # --- predictions ---------------------------------------------------------------------

    def judge_span(self) -> tuple[str, Recording] | None:
        """(name, recording) of the first other recording whose nominal prediction errs by
        THRESHOLD_SIGMA noise sigmas or more, or None (looked for once)."""
        if "span" not in self.judge:
            self.judge["span"] = None
            for k, o in enumerate(self.other_recordings):
                span = match_recording(self.model, o)
                self.say(f"checking whether other recording {k + 1} can judge effects below the model-form floor")
                h = predict_before_after(self.nominal_model, self.nominal_model, span, self.segment_s, workers=self.workers)
                signal = prediction_signal(h, self.sigma_q)
                self.judge.setdefault("signal_sigma", {})[f"other_recording_{k + 1}"] = signal
                if signal >= THRESHOLD_SIGMA:
                    self.judge["span"] = (f"other_recording_{k + 1}", span)
                    break
        return self.judge["span"]

    def prediction_rms_sigma(self, m: ArticulatedModel, span: Recording) -> float:
        """Noise-normalised RMS of ``m``'s prediction of ``span`` (pooled over joints)."""
        h = predict_before_after(m, m, span, self.segment_s, workers=self.workers)
        return float(np.sqrt(np.mean(((h.q_after - h.q_rec) / np.maximum(self.sigma_q, 1e-12)) ** 2)))

    def prediction_gate(self, rows: list[dict]) -> dict | None:
        """The first of ``rows`` (hypotheses with ΔBIC below DELTA_BIC whose effect on the fit is
        above the noise but below the model-form floor) that predicts the judge recording better
        than the current selection by more than MIN_EFFECT_SIZE_SIGMA noise sigmas, or None.
        An effect the system has shows in every recording of it; polishing one recording's
        model-form error does not carry over to another."""
        js = self.judge_span()
        if js is None:
            return None
        name, span = js
        base = self.prediction_rms_sigma(self.model_of(self.current), span)
        for r in rows:
            self.say(f"predicting {span_words(name)} with {r['type']} on {r['joint']}")
            new = self.prediction_rms_sigma(self.model_of(r["trial"]), span)
            ok = base - new >= MIN_EFFECT_SIZE_SIGMA
            self.tested.append({"prediction_gate": f"{r['type']} on {r['joint']}", "span": name,
                                "prediction_rms_sigma": [base, new], "passed": ok})
            if ok:
                self.judge["used"] = True
                return r
        return None

    # --- forward selection ------------------------------------------------------------------

    def screened(self, pending: list[tuple[str, str]], keep: list[tuple[str, str]],
                 strong_before: set[tuple[str, str]], whole: bool = False) -> list[tuple[str, str]]:
        """The hypotheses of ``pending`` (each added to ``keep``) that get an NLP fit: the
        ``screen`` best of the linear pre-screen, plus those the previous round's NLP fits found
        strong (the linear ranking is weak once an effect is in: its column absorbs what
        collinear ones would explain); all of them in a ``whole`` round (a selection round, not
        a swap) of at most FIT_WHOLE_ROUND."""
        if self.screen is None or len(pending) <= self.screen or (whole and len(pending) <= FIT_WHOLE_ROUND):
            return pending
        scores = screen_scores(self.model, pending, keep, self.r_nom, self.id_force, self.q_s, self.v_s, self.eps,
                               self.v_scale, self.v_noise, self.stops)
        top = sorted(pending, key=lambda je: scores[je])[: self.screen]
        return [je for je in pending if je in top or je in strong_before]

    def select(self, max_effects: int) -> None:
        """Forward selection by ΔBIC with an effect-size floor, the prediction gate for effects
        below the model-form floor, a parent re-fit, then a stepwise revision (swaps, removals)
        after each addition; at most ``max_effects`` effects."""
        rounds = 0
        strong_before: set[tuple[str, str]] = set()  # hypotheses the last round's fits found strong
        while len(self.selected) < max_effects and rounds < max_effects + MAX_PARENT_REFITS:
            rounds += 1
            rss0 = self.rss(self.current)
            pending = [(j, e) for j in self.model.joint_names for e in self.candidates
                       if not any(s[:2] == (j, e) for s in self.selected)
                       and self.identifiable(self.chosen() + [(j, e)])]
            screened = self.screened(pending, self.chosen(), strong_before, whole=True)
            rows = self.fit_round(screened)
            if not rows:
                break
            n_eff, ok, strong, gated = self.judge_round(rows, rss0)
            rest = [je for je in pending if je not in screened]
            if not (strong or gated or self.selected) and rest and self.mismatch_left(rss0):
                # The linear pre-screen is a ranking, and where the residual force is mostly the
                # noise of the measured accelerations its order is noise too (a 4-kg drawer at
                # 30 Hz: M·a noise ~2 N against its 0.2 N of damping, ranked 10th of 18): when its
                # best explain nothing of a mismatch the nominal model leaves, the rest are fitted.
                self.say("the pre-screen's best hypotheses explain nothing; fitting the others")
                rows, rest = self.fit_round(rest), []
                n_eff, ok, strong, gated = self.judge_round(rows, rss0)
            pair = self.stop_pair(screened, strong, rss0) if not self.selected else None
            if pair is not None:
                (joint, effect), row = pair
                self.current = row["trial"]
                for e in ("limit_contact", effect):
                    self.selected.append((joint, e, row["delta_bic"]))
                    self.say(f"selected {e} on {joint} (with {'the stop' if e == effect else effect}: ΔBIC {row['delta_bic']:.0f})")
                strong_before = set()
                continue
            strong_before = {(r["joint"], r["type"]) for r in strong}
            strong, ok = self.gate_in(strong, gated, ok, strong_before)
            if not (strong or self.selected) and rest and self.mismatch_left(rss0):
                # The same when what the best offered is below the model-form floor and another
                # recording refutes it (the Qube's fin11: the arm's inertia and a pendulum tilt
                # predicted fin12 worse, while the pendulum's damping, ranked below them, was
                # never fitted).
                self.say("the pre-screen's best hypotheses do not carry over to another recording; fitting the others")
                n_eff, ok, strong, gated = self.judge_round(self.fit_round(rest), rss0)
                strong_before |= {(r["joint"], r["type"]) for r in strong}
                strong, ok = self.gate_in(strong, gated, ok, strong_before)
            if not strong:
                break
            best = self.unless_parent_fits_as_well(strong[0], rss0, n_eff)
            if best is None:
                continue
            # Hypotheses that explain the data as well as the chosen one (log-likelihood within
            # EQUIVALENT_LOGLIK on the same scale) are reported with it: the recording cannot tell them apart.
            self.equivalents[(best["joint"], best["type"])] = [
                {"joint": r["joint"], "type": r["type"], "trial": r["trial"]} for r in ok
                if r is not best and abs(n_eff * np.log(r["rss"] / best["rss"])) < EQUIVALENT_LOGLIK]
            self.current = best["trial"]
            self.selected.append((best["joint"], best["type"], best["delta_bic"]))
            self.say(f"selected {best['type']} on {best['joint']} (ΔBIC {best['delta_bic']:.0f})")
            self.swap_earlier(strong_before, revise_last=best.get("parent_refit", False))
            self.drop_earlier()

    def gate_in(self, strong: list[dict], gated: list[dict], ok: list[dict],
                strong_before: set[tuple[str, str]]) -> tuple[list[dict], list[dict]]:
        """(strong, ok) of a round after the prediction gate: with nothing strong, the first of
        ``gated`` that predicts another recording better (:meth:`prediction_gate`) becomes the
        round's one strong row.  The gated hypotheses join ``strong_before`` (in place: the next
        round fits them again whatever the pre-screen says)."""
        if strong or not gated or not self.other_recordings:
            return strong, ok
        strong_before |= {(r["joint"], r["type"]) for r in gated}
        passed = self.prediction_gate(gated[:PREDICTION_TRIES])
        if passed is None:
            return strong, ok
        self.gated_in.add((passed["joint"], passed["type"]))
        passed = {**passed, "supported": True}
        return [passed], ok + [passed]

    def judge_round(self, rows: list[dict], rss0: float) -> tuple[float, list[dict], list[dict], list[dict]]:
        """:meth:`score_round` of ``rows``, then (its sample count, the supported rows, the strong
        ones and those below the model-form floor, each strongest first)."""
        n_eff = self.score_round(rows, rss0)
        ok = [r for r in rows if r["supported"]]
        strong = sorted((r for r in ok if r["delta_bic"] < DELTA_BIC), key=lambda r: r["delta_bic"])
        # Below the model-form floor: strong evidence (ΔBIC) and a fit moved by more than the
        # noise, but by less than the model-form error the round's best fit still leaves.  The
        # fit span alone cannot tell such an effect from polishing that error; another
        # recording of the system can (see ``prediction_gate``).
        gated = sorted((r for r in rows if r["below_floor"] and r["delta_bic"] < DELTA_BIC),
                       key=lambda r: r["delta_bic"])
        return n_eff, ok, strong, gated

    def stop_pair(self, screened: list[tuple[str, str]], strong: list[dict], rss0: float) -> tuple | None:
        """((joint, effect), row) of the best pair of a stop and a force effect on one joint that
        the first round's single hypotheses cannot reach, or None.

        A part held against a stop by a force the model lacks (a self-closing door: a spring
        pulling it onto its stop) rests where neither alone fits: the spring alone pulls it
        through the stop, the stop alone does not bring it back (a Drake door: the pair fits to
        the noise, the spring alone fitted to nothing).  So each force that acts at rest
        (HOLDING_EFFECTS) the round screened is fitted with a stop on its joint; a dissipative
        force vanishes at rest and is fitted alone.  The best pair is taken if it beats the
        round's best single hypothesis by the selection margin (DELTA_BIC) after paying for its
        extra parameters, with both effects supported.  The round's best single effect is left to
        the next round, which tests it with a stop anyway (taken here, a door's Coulomb friction
        got a stop it does not have, and its second recording was predicted 4× worse)."""
        if "limit_contact" not in self.candidates:
            return None
        # the round's best single hypothesis with a stop is the next round's to test
        best = (strong[0]["joint"], strong[0]["type"]) if strong else None
        pairs = [(j, e) for j, e in screened if e in HOLDING_EFFECTS and (j, e) != best]
        if not pairs:
            return None
        for j, e in pairs:
            self.say(f"testing {e} on {j} with a stop")
        trials = self.trials([[(j, "limit_contact"), (j, e)] for j, e in pairs], self.current)
        n_eff = self.sample_count(min(trials, key=self.rss))
        best_single = min([r["delta_bic"] for r in strong] + [0.0])
        rows = []
        for (j, e), trial in zip(pairs, trials):
            names = [effect_parameters(self.model, j, x) for x in ("limit_contact", e)]
            k = sum(n_free_params(n) for n in names)
            supported = trial.success and not any(_at_bound_values(trial, n, self.nominal_z) for n in names)
            d = delta_bic(self.rss(trial), rss0, k, n_eff)
            self.tested.append({"joint": j, "type": f"limit_contact+{e}", "delta_bic": d, "supported": supported,
                                "iterations": trial.iterations, "status": trial.status, "n_eff": n_eff})
            if supported and d < best_single + DELTA_BIC:
                rows.append(((j, e), {"trial": trial, "delta_bic": d}))
        return min(rows, key=lambda r: r[1]["delta_bic"]) if rows else None

    def mismatch_left(self, rss0: float) -> bool:
        """Whether a fit of residual sum of squares ``rss0`` (:meth:`rss`) leaves the search grid
        THRESHOLD_SIGMA noise sigmas (RMS) or more from the recording."""
        return bool(np.sqrt(rss0 / self.n_res) >= THRESHOLD_SIGMA)

    def fit_round(self, pending: list[tuple[str, str]]) -> list[dict]:
        """One row per hypothesis (the selection plus one of ``pending``): its fit, parameter
        count, reported value, RSS, how far it moves the fit (in encoder noise sigmas) and whether
        it converged off its "off" bound."""
        rows = []
        for joint, effect in pending:
            self.say(f"testing {effect} on {joint}")
        trials = self.trials([self.chosen() + [je] for je in pending], self.current)
        for (joint, effect), trial in zip(pending, trials):
            names = effect_parameters(self.model, joint, effect)
            # in units of the encoder noise of one recorded sample (not of the search grid's block
            # means, whose noise is lower): whether an effect matters does not depend on the rate
            size = float(np.sqrt(np.mean(((trial.q_fit - self.current.q_fit) / self.sigma_q) ** 2)))
            supported = trial.success and not _at_bound_values(trial, names, self.nominal_z)
            rows.append({"joint": joint, "type": effect, "trial": trial, "k": n_free_params(names),
                         "value": _reported_value(self.model, joint, effect, trial.values),
                         "rss": self.rss(trial), "effect_size_sigma": size, "supported": supported})
        return rows

    def sample_count(self, trial: Trial) -> float:
        """Effective sample count for BIC from ``trial``'s residuals on the search grid
        (:func:`effective_count`; all of them without EFFECTIVE_N)."""
        return effective_count((trial.q_fit - self.srch.q) / self.sigma_s) if EFFECTIVE_N else float(self.n_res)

    def score_round(self, rows: list[dict], rss0: float) -> float:
        """Adds ΔBIC, "below_floor" and the effect-size test to each row (and records them in
        ``tested``); returns the round's sample count for BIC."""
        # One effective sample count for the whole round (so candidates compare on one scale):
        # from the residuals of the round's best-fitting supported hypothesis.
        pool = [r for r in rows if r["supported"]] or rows
        best_fit = min(pool, key=lambda r: r["rss"])
        n_eff = self.sample_count(best_fit["trial"])
        # An effect must move the fit by more than the noise, and by more than what the round's
        # best hypothesis still leaves unexplained (the noise floor the data and library reach:
        # the high-frequency noise estimate can be low).
        floor = max(1.0, float(np.sqrt(np.mean(((best_fit["trial"].q_fit - self.srch.q) / self.sigma_q) ** 2))))
        for r in rows:
            r["below_floor"] = r["supported"] and MIN_EFFECT_SIZE_SIGMA <= r["effect_size_sigma"] < MIN_EFFECT_SIZE_SIGMA * floor
            r["supported"] = r["supported"] and r["effect_size_sigma"] >= MIN_EFFECT_SIZE_SIGMA * floor
            r["delta_bic"] = delta_bic(r["rss"], rss0, r["k"], n_eff)
            self.tested.append({"joint": r["joint"], "type": r["type"], "value": r["value"], "delta_bic": r["delta_bic"],
                                "effect_size_sigma": r["effect_size_sigma"], "supported": r["supported"],
                                "iterations": r["trial"].iterations, "status": r["trial"].status, "n_eff": n_eff,
                                "residual_floor_sigma": floor})
        return n_eff

    def unless_parent_fits_as_well(self, best: dict, rss0: float, n_eff: float) -> dict | None:
        """``best`` (with its ΔBIC against a better parent fit if there is one), or None when the
        round must run again.  The gain must be the new effect's, not a better optimum of the
        effects already chosen that the new fit reached from its own start (dry friction makes the
        fit multimodal): the parent hypothesis is re-fitted from the new fit's solution with the
        new effect off.  If the parent then fits decisively better than the current fit, it
        replaces it, and if the new effect's ΔBIC against it is no longer below DELTA_BIC, the
        round is run again against it."""
        parent = self.trial_of_parent(self.chosen(), best["trial"])
        if not parent.success:
            return best
        rss_p = self.rss(parent)
        if n_eff * np.log(rss_p / rss0) >= -EQUIVALENT_LOGLIK:
            return best
        d_new = delta_bic(best["rss"], rss_p, best["k"], n_eff)
        self.tested.append({"parent_refit": [f"{e} on {j}" for j, e, _ in self.selected],
                            "from": f"{best['type']} on {best['joint']}",
                            "delta_bic_parent": float(n_eff * np.log(rss_p / rss0)), "delta_bic": d_new})
        self.say(f"the chosen effects fit better from the {best['type']} fit's start; "
                 f"{best['type']} then gains ΔBIC {d_new:.0f}")
        self.current = parent
        return None if d_new >= DELTA_BIC else {**best, "delta_bic": d_new, "parent_refit": True}

    def swap_earlier(self, strong_before: set[tuple[str, str]], revise_last: bool = False) -> None:
        """Stepwise revision: an effect chosen earlier, when a later one was still missing, may
        have stood in for it (a stop for a spring); with the new effect in, replace an earlier one
        by any other candidate whose set has lower BIC (by DELTA_BIC).  revise_last: the effect
        just added won its round against a parent re-fitted after the round's other candidates
        were fitted (:meth:`unless_parent_fits_as_well`), so they were judged against the old
        parent: each is fitted in its place from the new fit, and one that fits better at all
        replaces it, as it would have won the round (a drawer's Coulomb friction + damping: drag
        won by ΔBIC −221 against the re-fitted parent, while damping, fitted against the old one,
        scored −167; in drag's place it fits better by 4.7)."""
        model, n_res = self.model, self.n_res
        last = len(self.selected) - 1
        for i in range(len(self.selected) if revise_last else last):
            threshold = 0.0 if i == last else DELTA_BIC
            keep = [x[:2] for k, x in enumerate(self.selected) if k != i]
            k_old = n_free_params(effect_parameters(model, *self.selected[i][:2]))
            others = [(j, e) for j in model.joint_names for e in self.candidates
                      if (j, e) not in keep and (j, e) != self.selected[i][:2] and self.identifiable(keep + [(j, e)])]
            swaps = []
            tried = self.screened(others, keep, strong_before)
            for joint, effect in tried:
                self.say(f"testing {effect} on {joint} in place of {self.selected[i][1]}")
            for (joint, effect), trial in zip(tried, self.trials([keep + [je] for je in tried], self.current)):
                names = effect_parameters(model, joint, effect)
                if not trial.success or _at_bound_values(trial, names, self.nominal_z):
                    continue
                gain = delta_bic(self.rss(trial), self.rss(self.current), n_free_params(names) - k_old, n_res)
                if gain < threshold:
                    swaps.append((gain, joint, effect, trial))
            swaps.sort(key=lambda x: x[0])
            swap = self.gated_swap(i, swaps) if self.selected[i][:2] in self.gated_in else (swaps[0] if swaps else None)
            if swap is not None:
                swap = self.unless_chosen_fit_as_well(i, swap, k_old, threshold)
            if swap is not None:
                gain, joint, effect, trial = swap
                self.tested.append({"swap": f"{self.selected[i][1]} on {self.selected[i][0]} -> {effect} on {joint}",
                                    "delta_bic": float(gain)})
                self.say(f"replaced {self.selected[i][1]} on {self.selected[i][0]} by {effect} on {joint} (ΔBIC {gain:.0f})")
                self.equivalents.pop(self.selected[i][:2], None)
                self.selected[i] = (joint, effect, self.selected[i][2] + gain)
                self.current = trial

    def unless_chosen_fit_as_well(self, i: int, swap: tuple, k_old: int, threshold: float = DELTA_BIC) -> tuple | None:
        """``swap`` (gain, joint, effect, trial) in place of chosen effect ``i``, with its gain
        against a better fit of the chosen effects if there is one, or None.  As for an addition
        (:meth:`unless_parent_fits_as_well`), the gain must be the swap's, not a better optimum of
        the chosen effects that the swap's fit reached from its own start: they are re-fitted from
        it, and replace the current fit if they fit better (a drawer's damping + Coulomb friction
        from a poor start was "beaten" by Coulomb friction + a spring by ΔBIC −164; re-fitted, the
        spring's interval held 0, and the damping was lost).  threshold: the ΔBIC the swap must
        still gain, below 0."""
        gain, joint, effect, trial = swap
        again = self.trial_of_parent(self.chosen(), trial)
        if not again.success or self.rss(again) >= self.rss(self.current):
            return swap
        k_new = n_free_params(effect_parameters(self.model, joint, effect))
        gain_again = delta_bic(self.rss(trial), self.rss(again), k_new - k_old, self.n_res)
        self.tested.append({"parent_refit": [f"{e} on {j}" for j, e, _ in self.selected],
                            "from": f"{effect} on {joint} in place of {self.selected[i][1]}",
                            "delta_bic_parent": delta_bic(self.rss(again), self.rss(self.current), 0, self.n_res),
                            "delta_bic": gain_again})
        self.say(f"the chosen effects fit better from the {effect} fit's start; the swap then gains ΔBIC "
                 f"{gain_again:.0f}")
        self.current = again
        return (gain_again, joint, effect, trial) if gain_again < threshold else None

    def gated_swap(self, i: int, swaps: list[tuple]) -> tuple | None:
        """An effect accepted for its prediction of another recording is replaced only by one of
        ``swaps`` whose set predicts that recording at least as well (the fit span's ΔBIC cannot
        tell polishing from physics here: that is why it was judged so)."""
        if not swaps:
            return None
        name, span = self.judge_span()
        base = self.prediction_rms_sigma(self.model_of(self.current), span)
        for sw in swaps:
            new = self.prediction_rms_sigma(self.model_of(sw[3]), span)
            self.tested.append({"prediction_gate": f"{sw[2]} on {sw[1]} in place of {self.selected[i][1]} on "
                                                   f"{self.selected[i][0]}",
                                "span": name, "prediction_rms_sigma": [base, new], "passed": new <= base})
            if new <= base:
                self.gated_in.add((sw[1], sw[2]))
                return sw
        return None

    def drop_earlier(self) -> None:
        """Drop an earlier effect that no longer earns its place beside the others (its removal
        must cost at least as much BIC as the entry threshold)."""
        n_res = self.n_res
        for i in range(len(self.selected) - 2, -1, -1):
            keep = [x[:2] for k, x in enumerate(self.selected) if k != i]
            self.say(f"testing the model without {self.selected[i][1]} on {self.selected[i][0]}")
            trial = self.trial_of(keep, self.nominal_trial) if keep else self.nominal_trial
            if keep and not trial.success:
                continue
            k_old = n_free_params(effect_parameters(self.model, *self.selected[i][:2]))
            cost = delta_bic(self.rss(self.current), self.rss(trial), k_old, n_res)  # BIC(with) - BIC(without)
            if cost >= DELTA_BIC:
                self.tested.append({"removed": f"{self.selected[i][1]} on {self.selected[i][0]}", "delta_bic": float(cost)})
                self.say(f"removed {self.selected[i][1]} on {self.selected[i][0]} (ΔBIC of keeping it {cost:.0f})")
                self.equivalents.pop(self.selected[i][:2], None)
                del self.selected[i]
                self.current = trial

    # --- checks of the selection ------------------------------------------------------------

    def drop_until_better(self, span: Recording, span_s: float | None, check: str, rms_key: str, doing: str,
                          stage: str, first: HeldOut | None = None, required_gain: float = MIN_EFFECT_SIZE_SIGMA,
                          every_joint: bool = False, signal_sigma: float | None = None, phases: int = 1) -> None:
        """Drop selected effects until the selection simulates ``span`` better than the nominal
        model by ``required_gain`` noise sigmas or more (or none is left) on some joint (with
        ``every_joint``, on every joint): backward elimination, each step dropping the effect
        whose removal (the rest re-fitted) simulates ``span`` best.
        ``doing``: progress text, formatted with the number of effects ``n``; ``stage``: the key of
        ``dropped`` the dropped effects are listed under; ``first``: the current selection's
        prediction of ``span`` if already made; ``signal_sigma``: judge the gain only where a model
        errs by that many noise sigmas (:meth:`~.predict.HeldOut.joint_gains_sigma`); ``phases``: of
        the pieces (:func:`~.predict.predict_before_after`).  Only effects on joints that move in
        ``span`` are dropped: one resting on its stop throughout (``span.held``) is predicted
        alike by every model, so the span cannot judge its effects (a door's friction, found
        while it swung, was dropped on a held-out span in which it rested shut)."""
        resting = set() if span.held is None else {j for k, j in enumerate(span.joint_names) if span.held[:, k].all()}
        keys = [key for key in self.chosen() if key[0] not in resting]
        self.say(doing.format(n=len(self.selected)))
        h = first or predict_before_after(self.nominal_model, self.model_of(self.current), span, span_s, phases,
                                         self.workers)
        if keys and not h.scored:  # no piece long enough to simulate: nothing verifies the selection
            self.tested.append({check: [f"{e} on {j}" for j, e, _ in self.selected], "unscored": True})
            self.dropped.setdefault(f"{stage}_unscored", []).extend(f"{e} on {j}" for j, e, _ in self.selected)
            self.selected.clear()
            self.current = self.nominal_trial
            self.equivalents.clear()
            return
        while True:
            gain = float(np.min(h.joint_gains_sigma(self.sigma_q, signal_sigma))) if every_joint \
                else h.gain_sigma(self.sigma_q, signal_sigma)
            self.tested.append({check: [f"{e} on {j}" for j, e, _ in self.selected], rms_key: [h.rms_before, h.rms_after],
                                "gain_sigma": gain})
            # better by more than the noise: a smaller gain is no evidence the selection explains the motion
            if gain >= required_gain or not keys:
                return
            options = []  # (prediction, dropped effect, trial) per removal
            for key in keys:
                rest = [x[:2] for x in self.selected if x[:2] != key]
                trial = self.trial_of(rest, self.nominal_trial) if rest else self.nominal_trial
                self.say(f"simulating the fit span without {key[1]} on {key[0]}")
                after = self.model_of(trial) if rest else self.nominal_model
                options.append((predict_before_after(self.nominal_model, after, span, span_s, phases, self.workers),
                                key, trial))
            # a removal whose re-fit converged is preferred; one is made in any case
            converged = [o for o in options if o[2].success] or options
            h, (joint, effect), self.current = min(converged, key=lambda o: o[0].rms_after)
            self.selected[:] = [x for x in self.selected if x[:2] != (joint, effect)]
            keys.remove((joint, effect))
            self.dropped.setdefault(stage, []).append(f"{effect} on {joint}")
            self.say(f"dropped {effect} on {joint}: its simulation got no better")
            self.equivalents.pop((joint, effect), None)
            if not self.selected:
                return

    def simulation_check(self) -> None:
        """The collocation fit lets states bend where the dynamics are soft, so a set of effects
        can fit it without explaining the motion.  The selection must also simulate the fit span
        better than the nominal model, by a noise sigma or more (in SIMULATION_CHECK_S pieces,
        each from its own best state: open-loop replays of many seconds diverge for any model); if
        it does not, effects are dropped (:meth:`drop_until_better`).  A limit contact is judged
        like every other effect: the model holds its stop."""
        self.drop_until_better(self.srch, self.segment_s or SIMULATION_CHECK_S, "simulation_check",
                               "fit_span_simulated_rms", "simulating the fit span with {n} effect(s)", "simulation_check",
                               signal_sigma=THRESHOLD_SIGMA, phases=2)

    def held_out_check(self, held: Recording | None) -> bool:
        """Whether the held-out span ``held`` judged the selection.  A selection that predicts it
        worse than the nominal model by more than MIN_EFFECT_SIZE_SIGMA noise sigmas is
        contradicted by data outside the fit, whatever the fit span said (a friction invented to
        hold a door against a stiff stop halts the door where it coasts on): effects are then
        dropped as in the simulation check until it predicts the span no worse, and the span is no
        longer independent (the summary says so)."""
        if held is None or not self.selected:
            return False
        self.say("checking the effects against the held-out span")
        h = predict_before_after(self.nominal_model, self.model_of(self.current), held, self.segment_s,
                                 workers=self.workers)
        if not h.scored or np.min(h.joint_gains_sigma(self.sigma_q)) >= -MIN_EFFECT_SIZE_SIGMA:
            return False
        self.drop_until_better(held, self.segment_s, "held_out_check", "prediction_rms",
                               "checking {n} effect(s) on the held-out span", "held_out_check", first=h,
                               required_gain=-MIN_EFFECT_SIZE_SIGMA, every_joint=True)
        return True

    def acceptance_check(self, held: Recording | None) -> tuple[dict | None, bool]:
        """(``Diagnosis.acceptance_check``, whether the held-out span judged it).

        When even the selection's fit stays above the located-mismatch level (THRESHOLD_SIGMA),
        the output error is dominated by model-form error the library cannot express, and its
        likelihood is no longer evidence for specific effects: the selection must then also
        predict data outside the fit better than the nominal model, else effects are dropped as
        in the simulation check.  That data is the held-out span ``held`` if the nominal model's
        prediction of it errs by more than THRESHOLD_SIGMA noise sigmas (else it shows nothing an
        effect could predict better, e.g. a system come to rest), otherwise the first other
        recording that does; the span used is then no longer independent (the summary and
        diagnosis.json say which).  If no span carries such a signal the check is skipped, and
        said so."""
        floor_final = float(np.sqrt(self.rss(self.current) / self.n_res))
        acceptance, judged_by_held_out = None, False
        if self.selected and floor_final > THRESHOLD_SIGMA:
            spans = ([("held_out", held)] if held is not None else []) + \
                [(f"other_recording_{k + 1}", match_recording(self.model, o)) for k, o in enumerate(self.other_recordings)]
            signal = {}
            for name, span in spans:
                self.say(f"checking whether the {span_words(name)} can judge the effects")
                h = predict_before_after(self.nominal_model, self.model_of(self.current), span, self.segment_s,
                                         workers=self.workers)
                signal[name] = prediction_signal(h, self.sigma_q)
                if signal[name] < THRESHOLD_SIGMA:
                    continue
                judged_by_held_out = name == "held_out"
                acceptance = {"span": name, "signal_sigma": signal, "fit_rms_sigma": floor_final, "reason": (
                    f"the fit stays {floor_final:.0f}x the noise whatever effect is added — model-form error the effect "
                    f"library cannot express — so effects were accepted only if they also predicted the {span_words(name)} "
                    f"better (its nominal prediction errs by {signal[name]:.0f} sigma): that span is not independent here")}
                self.drop_until_better(span, self.segment_s, "acceptance_check", "prediction_rms",
                                       f"checking {{n}} effect(s) on the {span_words(name)}", "acceptance_check", first=h)
                break
            else:
                acceptance = {"span": None, "signal_sigma": signal, "fit_rms_sigma": floor_final, "reason": (
                    f"the fit stays {floor_final:.0f}x the noise, but no span outside the fit ("
                    + (", ".join(f"{span_words(n)}: nominal prediction error {x:.1f} sigma" for n, x in signal.items())
                       or "none given") + f") errs by {THRESHOLD_SIGMA:g} sigma or more, so none can show an effect: "
                    "the effects are judged by the fit span alone (ΔBIC, effect size, simulation check)")}
        if self.judge.get("used"):
            gate = self.judge["span"][0]
            acceptance = {"span": None, "reason": "", **(acceptance or {}), "gate_span": gate,
                          "gate_signal_sigma": self.judge.get("signal_sigma", {}), "gate_reason": (
                              f"effects that moved the fit by more than the noise but less than the model-form error "
                              f"were accepted only if they predicted {span_words(gate)} better by more than the "
                              "noise: that recording is not independent here")}
        return acceptance, judged_by_held_out

    def checks(self, held: Recording | None) -> tuple[dict | None, bool]:
        """The simulation, acceptance and held-out checks (:meth:`simulation_check`,
        :meth:`acceptance_check`, :meth:`held_out_check`), each run again on what is left after
        another dropped an effect, until the set passes all three: the set reported is the set
        every check judged (what a later check leaves was never judged by the earlier ones).  As
        before the loop, the held-out check is skipped once the acceptance check was judged by
        the held-out span (a span already used to accept is not checked again per joint: an
        arm's Coulomb friction, 200x better on it overall, was dropped for a joint 4.5σ worse)."""
        acceptance, judged_by_held_out = None, False
        passed: set[str] = set()
        while True:
            for name in ("simulation", "acceptance", "held_out"):
                if name in passed:
                    continue
                before = len(self.selected)
                if name == "simulation":
                    self.simulation_check()
                elif name == "acceptance":
                    record, by_held_out = self.acceptance_check(held)
                    acceptance = acceptance if acceptance and acceptance.get("span") else record or acceptance
                    judged_by_held_out |= by_held_out
                elif not judged_by_held_out:  # the held-out span already judged acceptance: not checked twice
                    judged_by_held_out = self.held_out_check(held)
                dropped = len(self.selected) < before
                if dropped and not self.selected:
                    return acceptance, judged_by_held_out
                passed = {name} if dropped else passed | {name}
            if len(passed) == 3:
                return acceptance, judged_by_held_out

    # --- the full-rate fits -----------------------------------------------------------------

    def final_fits(self, fit_rec: Recording, k_dec: int) -> tuple[Calibration, Calibration]:
        """(nominal, final) calibrations on the full-rate fit span ``fit_rec`` (search grid: block
        means of ``k_dec`` samples).  An effect the model lacked whose 95 % interval still holds
        its "off" value (zero force, unit inertia ratio, nominal axis; for a stop, every recorded
        position) is not supported by the data, whatever the BIC of the search said (a fit can
        gain from reaching another optimum of the other effects): it is dropped, the weakest
        first, and the rest re-fitted."""
        model, stops, segment_s, sigma_q, eps = self.model, self.stops, self.segment_s, self.sigma_q, self.eps
        chosen = self.chosen()
        if k_dec == 1:
            nominal = _calibration(model, fit_rec, self.nominal_trial, [], stops, segment_s, sigma_q, eps)
            final = _calibration(model, fit_rec, self.current, chosen, stops, segment_s, sigma_q, eps)
        else:
            # One fit at the full rate holding the selected effects: the nominal model (effects
            # fixed out) and the selected model, each started from its search-grid solution.
            # No CPU-time cap: these fits are what is reported, and with one they depended on the
            # machine's speed (a soft-close drawer's pair stopped at the 1-s cap after 104
            # iterations, and the interval check, reading that point, dropped both effects).
            full = HypothesisFit(model, fit_rec, chosen, segment_s, stops, CANDIDATE_MAX_ITER, sigma_q, eps,
                                 max_cpu_s=math.inf)
            t_s = self.fits["base"].t_grid
            nominal_full = full.solve([], x0=full.states_from(t_s, self.nominal_trial.X))
            names = [n for j, e in chosen for n in effect_parameters(model, j, e)]
            final_full = self.full_rate_fit(full, names, {n: self.current.values[n] for n in names}, self.current.bounds,
                                            x0=full.states_from(t_s, self.current.X)) if chosen else nominal_full
            nominal = _calibration(model, fit_rec, nominal_full, [], stops, segment_s, sigma_q, eps)
            final = _calibration(model, fit_rec, final_full, chosen, stops, segment_s, sigma_q, eps, fit=full.fit)

        def motion_of(joint: str) -> tuple[float, float]:
            q = fit_rec.q[:, model.joint_index(joint)]
            return float(q.min()), float(q.max())

        while True:
            weak = [(i, w) for i, (j, e, _) in enumerate(self.selected)
                    if (w := interval_holds_off(model, j, e, final, motion_of(j))) is not None]
            if not weak:
                return nominal, final
            i = max(weak, key=lambda iw: iw[1])[0]
            joint, effect, _ = self.selected.pop(i)
            reason = _interval_words(model, joint, effect, final, motion_of(joint))
            self.say(f"dropped {effect} on {joint}: {reason}")
            self.tested.append({"interval_check": f"{effect} on {joint}", "dropped": True, "reason": reason})
            self.dropped.setdefault("interval_check", []).append(f"{effect} on {joint}")
            self.equivalents.pop((joint, effect), None)
            chosen = self.chosen()
            names = [n for j, e in chosen for n in effect_parameters(model, j, e)]
            if k_dec == 1:
                self.current = self.trial_of_parent(chosen, self.current) if chosen else self.nominal_trial
                final = _calibration(model, fit_rec, self.current, chosen, stops, segment_s, sigma_q, eps)
            else:
                final_full = self.full_rate_fit(full, names, {n: final_full.values[n] for n in names},
                                                {n: b for n, b in self.current.bounds.items() if n in names},
                                                start=final_full) if chosen else nominal_full
                final = _calibration(model, fit_rec, final_full, chosen, stops, segment_s, sigma_q, eps)

    def full_rate_fit(self, full: HypothesisFit, names: list[str], values: dict[str, np.ndarray],
                      bounds: dict[str, tuple[float, float]], **start) -> Trial:
        """The fit of the parameters ``names`` at the full rate (``full``), from ``values`` and the
        states ``start`` gives (``x0=`` or ``start=`` of :meth:`HypothesisFit.solve`).  If it does
        not converge (a rigid stop's stiffness and damper climb for all the iterations), the
        converged ``values`` it started from (the search grid's) are reported: the states are
        re-fitted with them held."""
        trial = full.solve(names, init=values, bounds=bounds, **start)
        if trial.success:
            return trial
        self.say(f"the full-rate fit did not converge ({trial.status}); the values it started from are kept")
        self.tested.append({"full_rate_fit": names, "converged": False, "after_iterations": trial.iterations,
                            "kept": "the values it started from, the states re-fitted with them held"})
        return full.solve(names, init=values, bounds={n: (v, v) for n, v in values.items()}, **start)

    def found_effects(self, final: Calibration) -> list[FoundEffect]:
        """The selected effects as reported: value, unit, 95 % interval, ΔBIC and extra params
        (spring rest, stop stiffness and contact damper, Stribeck speed, tilted axis, equivalent
        explanations, and the model's old value when it had the effect)."""
        model, found = self.model, []
        for joint, effect, d in self.selected:
            names = effect_parameters(model, joint, effect)
            e = final.estimates[names[0]]
            params = {}
            if effect == "spring":
                params["rest"] = float(final.estimates[names[1]].value[0])
            if effect == "limit_contact":
                params["stiffness"] = float(final.estimates[names[1]].value[0])
                params["damping"] = float(final.estimates[names[2]].value[0])
            if effect == "stribeck_friction":
                params["v_stribeck"] = float(final.estimates[names[1]].value[0])
            alts = self.equivalents.get((joint, effect), [])
            if alts:
                params["equivalent"] = [{"joint": a["joint"], "type": a["type"],
                                         "value": _reported_value(model, a["joint"], a["type"], a["trial"].values)}
                                        for a in alts]
            if effect == "axis_tilt":
                value = _reported_value(model, joint, effect, {names[0]: e.value})
                params["axis_world"] = _axis_world(final.model, joint).tolist()
                half = e.ci95_angle_rad or 0.0
                found.append(FoundEffect(joint, effect, value, "rad", (max(value - half, 0.0), value + half), d, params))
                continue
            if _model_had(model, joint, effect, e):  # a correction of the value the model had
                params["nominal"] = float(e.nominal[0])
            found.append(FoundEffect(joint, effect, float(e.value[0]), e.unit, (float(e.ci95_low[0]), float(e.ci95_high[0])),
                                     d, params))
        return found
