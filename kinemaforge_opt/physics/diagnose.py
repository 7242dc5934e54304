"""Mismatch discovery: locate → explain → model → show.

``diagnose(model, recording)``:
1. fits the nominal model (only the initial state is free) and locates where the residual sits
   (:mod:`.locate`);
2. explains it by stepwise selection over the effect library, on block means of the fit span
   sampled at ``SEARCH_RATE_HZ`` or more (a faster recording is averaged down; its noise level is
   re-estimated there).  Per round only ``SCREEN`` hypotheses, ranked by a linear
   inverse-dynamics pre-screen, plus those the previous round found strong, get an NLP fit
   (all of them on a one-joint model: ``FIT_WHOLE_ROUND``).
   Every hypothesis (a set of (joint, effect) pairs) is a fit of one shared collocation NLP built once per recording
   (:mod:`.search`; effects left out are fixed at their "off" values), with physical sign bounds
   and identifiability bounds (a stop inside the half of the recorded range on its side, a
   Stribeck speed below half the peak speed), states started from the data, and new force
   coefficients started from their inverse-dynamics least-squares estimate (from zero if that
   fit does not converge).
   Evidence is ΔBIC = BIC(with) - BIC(without), BIC = N ln(RSS/N) + k ln N on the
   noise-normalised output error.  Per round the best hypothesis is accepted while ΔBIC <
   ``DELTA_BIC`` (−10: "very strong" on the Kass–Raftery scale) and it moves the fitted
   trajectory by more than the noise and than what the round's best fit leaves unexplained; an
   effect whose parameter stays at its "off" bound explains nothing.  After each addition an
   earlier effect is swapped for a decisively better one (ΔBIC < ``DELTA_BIC``) or dropped if it
   no longer earns its place.  Alternatives that fit as well as the chosen one (log-likelihood
   within ``EQUIVALENT_LOGLIK``) are reported with it (``params["equivalent"]``): e.g. a
   prismatic joint's axis tilt and a constant bias are the same force in joint space.  A
   recording without an applied force fixes the links' inertia only relative to one another: the
   equations of motion hold for any common scale of every moving link's inertia and every joint
   force (a pendulum three times lighter with a third of the damping swings the same), so a set
   that frees every moving link's inertia is not tested, and the forces found are in the units of
   the model's inertia (the summary says so).  When even
   the final set leaves residual above the located-mismatch level (model-form error the library
   cannot express), the set must also predict data outside the fit better than the nominal model,
   else effects are dropped: the held-out span if it shows signal (the nominal prediction of it
   errs by ``THRESHOLD_SIGMA`` noise sigmas or more; a system come to rest shows none), else the
   first other recording (``other_recordings``) that does, else the check is skipped; the summary
   and ``Diagnosis.acceptance_check`` say which span was used (it is then not independent).
   With other recordings given, a round whose only strong hypotheses (ΔBIC < ``DELTA_BIC``, fit
   moved by more than the noise) fall below the model-form floor lets up to
   ``PREDICTION_TRIES`` of them, strongest first, be judged by that first other recording
   instead: the first that predicts it better by more than the noise is accepted (an effect the
   system has shows in every recording of it; polishing one recording's model-form error does
   not carry over to another).  Whatever the fit span said, a selection that predicts the
   held-out span worse than the nominal model by more than a noise sigma is contradicted by data
   outside the fit (a friction invented to hold a door against a stiff stop halts it where it
   coasts on): effects are dropped as in the simulation check until it predicts the span no
   worse, which then is not independent (the summary says so);
3. re-fits the nominal model and the model with every selected effect at the full rate (started
   from their search-grid solutions; 95 % intervals from the fit's sensitivity), drops an effect
   the model lacked whose interval holds its "off" value, and writes the augmented model;
4. shows the fit before vs after on a held-out later span: each model starts from its own
   least-squares state over the first ``STATE_WINDOW_S`` of a span and predicts the rest under
   the recorded forcing.

Where each step lives: 1 in :mod:`.locate`; 2 and 3 in :mod:`.selection` (the hypothesis fits
of :mod:`.search`, ranked and started by :mod:`.prescreen`); 4 in :mod:`.predict`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..calibration import Calibration
from ..errors import DataError
from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..nlp.joint_space import (
    MIN_SAMPLES,
    fit_spans,
    friction_smoothing,
    join_recordings,
    joined_words,
    match_recording,
    measurement_sigma,
    noise_std,
)
from .locate import THRESHOLD_SIGMA, JointMismatch, block_means, locate
from .predict import TOO_SPARSE, HeldOut, predict_before_after
from .selection import CANDIDATES, DELTA_BIC, MAX_EFFECTS, SCREEN, EffectSearch, FoundEffect, span_words
from .search import CPU_CAP_STATUS

# The hypothesis search runs on block means of the recording at no less than this rate [Hz]:
# the effects of the library are low-bandwidth forces, so a recording sampled faster carries no
# more about them than its block means (whose noise falls as 1/sqrt(block)), at a fraction of the
# cost; the nominal and the selected model are then fitted at the full rate.
SEARCH_RATE_HZ = 30.0


@dataclass(frozen=True)
class Diagnosis:
    """Everything ``diagnose`` found: the located mismatch, the selected effects, the nominal and
    augmented fits, the augmented model, and the held-out comparison."""

    mismatch: tuple[JointMismatch, ...]
    effects: tuple[FoundEffect, ...]
    tested: tuple[dict, ...]
    nominal_fit: Calibration
    final_fit: Calibration
    model: ArticulatedModel
    held_out: HeldOut | None
    held_out_others: tuple[HeldOut, ...] = ()
    # True when the held-out span judged the selection: model-form error forced a check on it, or
    # the selection predicted it worse than the nominal model (it is then not independent)
    held_out_used_for_selection: bool = False
    # The prediction check that model-form error forced (see ``diagnose``): ``{"span": "held_out" |
    # "other_recording_<k>" (1-based) | None, "reason": str, "signal_sigma": {span: nominal
    # prediction RMS / noise}}``; None when no such check was needed.
    acceptance_check: dict | None = None
    # Effects the search selected and a later check dropped: {check: ["<type> on <joint>", ...]},
    # check one of "simulation_check", "acceptance_check", "held_out_check", "interval_check" (with
    # "_unscored" appended when no piece of its span was long enough to simulate).
    dropped: dict = field(default_factory=dict)
    segment_s: float | None = None  # the fit's segment length [s] (None: one trajectory)

    @property
    def other_used_for_selection(self) -> int | None:
        """0-based index into ``held_out_others`` of the recording that judged acceptance, or None."""
        check = self.acceptance_check or {}
        for span in (check.get("span") or "", check.get("gate_span") or ""):
            if span.startswith("other_recording_"):
                return int(span.rsplit("_", 1)[1]) - 1
        return None

    def summary(self) -> str:
        """A plain-words account for the terminal."""
        lines = []
        for m in sorted(self.mismatch, key=lambda m: -m.share_of_residual):
            where = ", ".join(f"{a:.2f}–{b:.2f} s" for a, b in m.windows_s[:4]) or "nowhere above 3σ"
            lines.append(f"joint {m.joint}: {100 * m.share_of_residual:.0f}% of the residual, "
                         f"RMS {m.rms_over_noise:.1f}× noise; windows: {where}")
        dropped = {c: ", ".join(e.replace("_", " ") for e in v) for c, v in self.dropped.items() if v}
        check = self.acceptance_check or {}
        if not self.effects and dropped.get("interval_check"):
            checks = [t for t in self.tested if "interval_check" in t]
            why = "; ".join((f"{t['interval_check'].replace('_', ' ')}: " if len(checks) > 1 else "") + t["reason"]
                            for t in checks)
            lines.append(f"the search selected {dropped['interval_check']}, but the full-rate re-fit does not support "
                         f"it ({why}): no effect is reported")
        elif not self.effects and dropped.get("acceptance_check"):
            lines.append(f"no effect of the library both explains the recording (ΔBIC threshold {DELTA_BIC:g}) and "
                         f"predicts the {span_words(check.get('span'))} better (dropped: "
                         f"{dropped['acceptance_check']}): the remaining mismatch is model-form error the library "
                         "cannot express")
        elif not self.effects and (unscored := [v for c, v in dropped.items() if c.endswith("_unscored")]):
            lines.append(f"the search selected {unscored[0]}, but no piece of the span that would check it is long "
                         f"enough to simulate ({TOO_SPARSE}): unverified, no effect is reported")
        elif not self.effects and dropped.get("held_out_check"):
            lines.append(f"the search selected {dropped['held_out_check']}, but with them the model predicts the "
                         "held-out span worse than the nominal model: no effect is reported")
        elif not self.effects and dropped.get("simulation_check"):
            lines.append(f"the search selected {dropped['simulation_check']}, but the selection did not simulate the "
                         "fit span better than the nominal model by more than the noise: no effect is reported")
        elif not self.effects and any(m.windows_s for m in self.mismatch):
            capped = sorted({f"{t['type'].replace('_', ' ')} on {t['joint']}" for t in self.tested
                             if t.get("status") == CPU_CAP_STATUS})
            lines.append(f"no effect is supported by the data (ΔBIC threshold {DELTA_BIC:g}): the mismatch located "
                         "above remains unexplained" + (f"; the fits of {', '.join(capped)} did not converge within "
                                                        "their CPU budget" if capped else ""))
        elif not self.effects:
            lines.append("no effect is supported by the data (ΔBIC threshold "
                         f"{DELTA_BIC:g}): the nominal model explains the recording to its noise level")
        for e in self.effects:
            if "nominal" in e.params:  # a value the model had, corrected
                lines.append(f"wrong value on {e.joint}: {e.type.replace('_', ' ')} {e.params['nominal']:.4g} -> "
                             f"{e.value:.4g} {e.unit} (95% [{e.ci95[0]:.4g}, {e.ci95[1]:.4g}]), ΔBIC {e.delta_bic:.0f}")
                continue
            lines.append(f"missing physics on {e.joint}: {e.type.replace('_', ' ')} = {e.value:.4g} {e.unit} "
                         f"(95% [{e.ci95[0]:.4g}, {e.ci95[1]:.4g}]), ΔBIC {e.delta_bic:.0f}")
        for c, words in (("simulation_check", "simulating the fit span no better"),
                         ("acceptance_check", f"predicting the {span_words(check.get('span'))} no better"),
                         ("interval_check", "its 95% interval holding the off value"),
                         ("held_out_check", "predicting the held-out span worse than the nominal model")):
            if self.effects and dropped.get(c):
                lines.append(f"dropped {dropped[c]}: {words}")
        used = self.other_used_for_selection
        unpredicted = f"no sample could be predicted ({TOO_SPARSE})"
        for k, h in enumerate(self.held_out_others):
            note = " (used to accept the effects: not independent)" if k == used else ""
            lines.append(f"other recording {k + 1}: prediction RMS before {h.rms_before:.4g}, after {h.rms_after:.4g}{note}"
                         if h.scored else f"other recording {k + 1}: {unpredicted}")
        if self.held_out is not None and not self.held_out.scored:
            lines.append(f"held-out span: {unpredicted}")
        elif self.held_out is not None:
            span = "held-out span (used to check the effects: not independent)" if self.dropped.get("held_out_check") \
                else "held-out"
            before, after = self.held_out.rms_before, self.held_out.rms_after
            # a span at rest, predicted exactly by both models, has no ratio
            ratio = f" (×{before / after:.1f} better)" if after > 1e-9 else ""
            lines.append(f"{span} prediction RMS: before {before:.4g}, after {after:.4g}{ratio}"
                         + ("" if (x := check.get("signal_sigma", {}).get("held_out")) is None or x >= THRESHOLD_SIGMA
                            else f"; the nominal model errs there by only {x:.1f} noise sigmas: the span shows no "
                                 "effect, this figure says nothing"))
        for key in ("gate_reason", "reason"):
            if check.get(key):
                lines.append(f"({check[key]})")
        lines += [f"({t['identifiability']})" for t in self.tested if "identifiability" in t]
        lines += [f"({t[key]})" for key in ("joined", "left_out") for t in self.tested if key in t]
        if not self.effects and self.segment_s is None and any(t.get("status") == CPU_CAP_STATUS for t in self.tested):
            lines.append("(the recording was fitted as one trajectory: a long recording of a sensitive system, such "
                         "as a swinging pendulum, may fit only in pieces; try segment_s=1, `--segment 1`)")
        return "\n".join(lines)


def search_decimation(rec: Recording) -> int:
    """Samples per block of the search grid: the largest k whose block means are still sampled
    at SEARCH_RATE_HZ or more (1 for a recording at or below it)."""
    return max(1, int(np.floor((1.0 / rec.dt) / SEARCH_RATE_HZ + 1e-6)))


def block_average(rec: Recording, k: int) -> Recording:
    """``rec`` as means over consecutive blocks of ``k`` samples (t, q, v and tau alike; each
    stretch between gaps on its own, its last incomplete block dropped; a joint is held in a block
    held throughout).  k = 1 returns ``rec``."""
    if k <= 1:
        return rec

    def mean(a):
        return block_means(a, k, rec.t)

    held = None if rec.held is None else mean(rec.held.astype(float)) > 1.0 - 1e-9  # held throughout the block
    return Recording(mean(rec.t), rec.joint_names, mean(rec.q), mean(rec.v), mean(rec.tau), held)


def _split(rec: Recording, holdout_fraction: float, k: int | None) -> tuple[Recording, Recording | None]:
    """(the fit part, the held-out last ``holdout_fraction`` or None if under 4 samples) of the
    fit span ``rec`` (recording ``k``, 0-based, of several; None: the only one)."""
    split = int(round(rec.t.size * (1 - holdout_fraction)))
    if split < 10:
        which = "recording" if k is None else f"recording {k + 1}"
        raise DataError(f"{which} has {rec.t.size} samples: too few to fit and hold out {holdout_fraction:.0%}")
    return rec.window(rec.t[0], rec.t[split - 1]), (rec.window(rec.t[split], rec.t[-1]) if split < rec.t.size - 3
                                                     else None)


def diagnose(
    model: ArticulatedModel,
    recording: Recording | Sequence[Recording],
    holdout_fraction: float = 0.25,
    candidates: tuple[str, ...] = CANDIDATES,
    max_effects: int = MAX_EFFECTS,
    progress=None,
    segment_s: float | None = None,
    other_recordings: tuple[Recording, ...] = (),
    screen: int | None = SCREEN,
    workers: int | None = None,
    cpu_cap_s: float | None = None,
) -> Diagnosis:
    """Locate, explain, model and show the mismatch between ``model`` and ``recording``.

    recording: one recording, or several of the same system fitted together (one model for all,
    each followed from its own state: :func:`~kinemaforge_opt.nlp.joint_space.join_recordings`;
    the fits, windows and plots are then on the joined time axis, which the summary gives).
    holdout_fraction: the last part of the recording (of each) kept out of every fit and used to
    compare predictions before vs after.  candidates: effect types to test (DESIGN.md names).
    progress: optional callable(str) receiving one line per stage.
    segment_s: fit in segments of this length [s] (see ``nlp.joint_space``), and predict held-out
    data segment by segment from each segment's first state; use it for long oscillating
    recordings.  other_recordings: further recordings of the same system, used only to compare
    predictions before vs after (``Diagnosis.held_out_others``).  screen: per selection round,
    fit only this many hypotheses by NLP, those that best reduce the inverse-dynamics residual
    in a linear least-squares pre-screen (default ``SCREEN``; None: fit every hypothesis; a
    round of at most ``FIT_WHOLE_ROUND`` hypotheses, one joint's, is fitted whole); the
    same ranking picks the candidates tried in place of an earlier effect.  workers: processes
    that fit a round's hypotheses side by side (None: the CPUs this process may use, or
    OMP_NUM_THREADS; 1: all in this process); the findings do not depend on it.  More than one
    forks this process (only the calling thread lives on in a child): pass 1 from a program whose
    other threads may be inside CasADi or hold a lock the fits need while this runs.
    cpu_cap_s: IPOPT's CPU-time cap of each hypothesis fit of the search [s] (None: 100
    evaluations of its derivatives, timed, at least 1 s; a fit that reaches it is unsupported).
    The findings then depend on the machine's speed where a fit ends near the cap;
    ``math.inf`` makes them the same on every machine, at the cost of the rare hypothesis that
    spends minutes in IPOPT's restoration phase (the real Qube: 2-4x the time).  The final
    full-rate fits never have a cap.
    """
    say = progress or (lambda s: None)
    spans, left_out = fit_spans(model, recording)
    unknown = [c for c in candidates if c not in CANDIDATES]
    if unknown:
        raise DataError(f"unknown candidate effect(s) {unknown}; available: {', '.join(CANDIDATES)}")
    if workers is not None and workers < 1:
        raise DataError(f"workers={workers}: the hypothesis fits need at least one process")
    if cpu_cap_s is not None and not cpu_cap_s > 0:
        raise DataError(f"cpu_cap_s={cpu_cap_s}: a CPU-time cap must be a positive number of seconds (math.inf: none)")
    fits, helds = zip(*(_split(r, holdout_fraction, k if len(spans) > 1 else None) for k, r in enumerate(spans)))
    fit_rec = join_recordings(fits)
    held_parts = [h for h in helds if h is not None]
    held = join_recordings(held_parts) if held_parts else None
    joined = ({"joined": joined_words(fits, fit_rec)},) if len(spans) > 1 else ()
    sigma_q = measurement_sigma(fit_rec.q)
    # The hypothesis search runs on a coarser copy of the fit span (effects are low-bandwidth):
    # block means at SEARCH_RATE_HZ or more, with their own noise level; only the nominal and
    # the final model are fitted at the full rate.
    k_dec = search_decimation(fit_rec)
    srch = block_average(fit_rec, k_dec)
    if srch.t.size < MIN_SAMPLES:
        raise DataError(
            f"the fit span is {fit_rec.t[-1] - fit_rec.t[0]:.3g} s, {srch.t.size} samples on the "
            f"{1 / srch.dt:.0f}-Hz search grid: too few to identify anything (at least {MIN_SAMPLES}); "
            f"the last {holdout_fraction:.0%} of the span is kept for held-out predictions"
            + "".join(f"; {w}" for w in left_out))
    sigma_s = np.maximum(noise_std(srch.q), sigma_q / np.sqrt(k_dec))

    say("fitting the nominal model" if k_dec == 1 else
        f"fitting the nominal model ({1 / srch.dt:.0f} Hz search grid, {k_dec}-sample block means)")
    search = EffectSearch(model, srch, sigma_q, sigma_s, friction_smoothing(srch), candidates,
                           segment_s, screen, other_recordings, say, fit_rec, workers, cpu_cap_s)
    search.select(max_effects)
    acceptance, judged_by_held_out = search.checks(held)
    say("re-fitting with the selected effects" + ("" if k_dec == 1 else f" at the full {1 / fit_rec.dt:.0f} Hz"))
    nominal, final = search.final_fits(fit_rec, k_dec)
    mismatch = locate(model, fit_rec, nominal.q_fit, sigma_q)
    found = search.found_effects(final)

    held_out = None
    if held is not None:
        say("predicting the held-out span")
        held_out = predict_before_after(model, final.model, held, segment_s, workers=workers)
    others = []
    for k, other in enumerate(other_recordings):
        say(f"predicting other recording {k + 1}/{len(other_recordings)}")
        others.append(predict_before_after(model, final.model, match_recording(model, other), segment_s,
                                           workers=workers))
    tested = joined + tuple({"left_out": words} for words in left_out) + tuple(search.tested)
    return Diagnosis(tuple(mismatch), tuple(found), tested, nominal, final, final.model, held_out, tuple(others),
                     held_out_used_for_selection=judged_by_held_out, acceptance_check=acceptance,
                     dropped=search.dropped, segment_s=segment_s)
