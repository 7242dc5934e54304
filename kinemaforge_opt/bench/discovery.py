"""The mismatch-discovery benchmark: ``diagnose`` vs ID-LS vs PySINDy on the concealed-effects
set (each effect alone on a door and a drawer, pairs, null cases).

Per case and method: the effect types reported, true positives (type match), false positives,
missed effects, the relative value error of each true positive, and the held-out RMS of the
prediction before (nominal model) and after (augmented with what the method found): on the last
quarter of the recording, and on the case's second recording (:func:`.recordings.other_recording`,
another hand plan, never shown to a method) over its stretches clear of the nominal stops
(:func:`~kinemaforge_opt.nlp.joint_space.between_nominal_stops`), predicted in
``OTHER_SEGMENT_S`` pieces each from its own least-squares state.  A concealed
``limit_contact`` whose stop the motion never reached is not in the truth set (nothing in the
data shows it); no method has a limit-contact hypothesis, so a reached stop counts as missed.
Each effect case also gets its oracle ΔBIC (:mod:`.detectability`): whether even the true
effects, fitted from their true values, explain the recording better than the nominal model by
``diagnose``'s selection margin; the summary adds the F1 over the null cases and the effect
cases that pass it.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..nlp.joint_space import between_nominal_stops
from ..physics.predict import STATE_WINDOW_S, simulate_segments
from ..physics.selection import DELTA_BIC
from .baselines import BaselineResult, idls, sindy, split
from .predict import augmented, predict
from .recordings import effect_recording, other_recording

METHODS = ("diagnose", "ID-LS", "PySINDy (STLSQ)")
HOLDOUT = 0.25
OTHER_SEGMENT_S = 2.0  # prediction pieces on the second recording [s]: as long as the last quarter
GAIN_BAR = 5.0  # the held-out bar: RMS at least this many times lower after the fix


@dataclass(frozen=True)
class CaseScore:
    """One method on one case.  ``value_error``: effect type -> |found - true| / |true| for true
    positives.  RMS in rad or m on the held-out span."""

    case: str
    method: str
    truth: tuple[str, ...]
    found: tuple[str, ...]
    true_positives: int
    false_positives: int
    missed: int
    value_error: dict[str, float]
    rms_before: float | None
    rms_after: float | None
    time_s: float
    equivalent: dict[str, tuple[str, ...]] = None  # found type -> types reported as explaining the data as well
    class_scores: tuple[int, int, int] = None  # (TP, FP, missed) crediting equivalent explanations
    oracle_delta_bic: float | None = None  # the true effects' ΔBIC on the recording (None: null case or failed fit)
    other_rms_before: float | None = None  # RMS on the second recording, nominal model [rad or m]
    other_rms_after: float | None = None  # ... and with what the method found

    @property
    def supported(self) -> bool:
        """A null case, or one whose true effects the recording supports (oracle ΔBIC below DELTA_BIC)."""
        return not self.truth or (self.oracle_delta_bic is not None and self.oracle_delta_bic < DELTA_BIC)


def _score(case: str, method: str, truth: dict[str, float], found: dict[str, float],
           rms: tuple[float | None, float | None], time_s: float,
           equivalent: dict[str, dict[str, float]] | None = None) -> CaseScore:
    """Strict scores (a found type must equal a true type), and class scores: a found effect
    reported with equivalent explanations (``equivalent``: found type -> {type: value}) counts
    as a true positive when the truth is any member of its class."""
    tp = set(truth) & set(found)
    err = {t: abs(found[t] - truth[t]) / abs(truth[t]) for t in sorted(tp)}
    equivalent = equivalent or {}
    matched, fp = set(), 0
    for t in found:
        cls = {t: found[t], **equivalent.get(t, {})}
        hit = next((c for c in cls if c in truth and c not in matched), None)
        if hit is None:
            fp += 1
        else:
            matched.add(hit)
    return CaseScore(case, method, tuple(sorted(truth)), tuple(sorted(found)), len(tp), len(set(found) - tp),
                     len(set(truth) - tp), err, rms[0], rms[1], time_s,
                     {t: tuple(sorted(v)) for t, v in equivalent.items()}, (len(matched), fp, len(set(truth) - matched)))


def _baseline_model(model, res: BaselineResult):
    """The nominal ``model`` with a baseline's inertia ratios, and its fitted force laws per joint."""
    from .library import force_law

    ratios = {j: 1.0 - c["id"] for j, c in res.coefs.items() if c.get("id", 0.0) != 0.0 and c["id"] < 1.0}
    laws = {j: force_law(res.libraries[j], c) for j, c in res.coefs.items() if any(c.values())}
    return augmented(model, ratios), laws


def _baseline_after(fitted, laws: dict, held) -> float:
    """RMS error [rad or m] of a baseline's model (:func:`_baseline_model`) predicting ``held``."""
    q = predict(fitted, held, laws, state_window_s=STATE_WINDOW_S)
    return float(np.sqrt(np.nanmean((q - held.q) ** 2)))


def segment_rms(model, rec, laws: dict | None = None, segment_s: float = OTHER_SEGMENT_S) -> float:
    """RMS error [rad or m] of ``model`` (plus force ``laws``) predicting ``rec`` in ``segment_s``
    pieces (:func:`~kinemaforge_opt.physics.predict.simulate_segments`; the samples each piece's
    starting state is fitted to are not scored).  A model whose simulation diverges (a baseline's
    fitted law can be unstable) scores inf."""
    try:
        q = simulate_segments(model, rec, segment_s, laws)
    except ValueError:  # least squares on non-finite residuals: the simulation diverged
        return float("inf")
    return float(np.sqrt(np.nanmean((q - rec.q) ** 2)))


def run_case(case: str, noise_seed: int = 0) -> list[CaseScore]:
    """Score the three methods on catalogue case ``case`` with encoder-noise seed ``noise_seed``."""
    from ..physics.diagnose import diagnose
    from .detectability import oracle_delta_bic

    er = effect_recording(case, noise_seed)
    truth = {e.type: e.value for e in er.shown_effects}
    _, held = split(er.recording.select(er.model.joint_names), HOLDOUT)
    other = between_nominal_stops(er.model, other_recording(case, noise_seed).recording.select(er.model.joint_names))
    other_before = segment_rms(er.model, other)
    t0 = time.perf_counter()
    d = diagnose(er.model, er.recording, holdout_fraction=HOLDOUT)
    t_diag = time.perf_counter() - t0
    rms_before = d.held_out.rms_before if d.held_out else None
    eq = {e.type: {a["type"]: a["value"] for a in e.params.get("equivalent", ()) if a["joint"] == e.joint}
          for e in d.effects}
    out = [replace(_score(case, "diagnose", truth, {e.type: e.value for e in d.effects},
                          (rms_before, d.held_out.rms_after if d.held_out else None), t_diag, eq),
                   other_rms_before=other_before, other_rms_after=segment_rms(d.model, other))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # STLSQ warns each time a threshold removes every term
        for fn in (idls, sindy):
            res = fn(er.model, er.recording, HOLDOUT)
            fitted, laws = _baseline_model(er.model, res)
            after = _baseline_after(fitted, laws, held) if held is not None else None
            out.append(replace(_score(case, res.method, truth, {e.type: e.value for e in res.effects},
                                      (rms_before, after), res.time_s),
                               other_rms_before=other_before, other_rms_after=segment_rms(fitted, other, laws)))
    oracle = oracle_delta_bic(er)
    return [replace(s, oracle_delta_bic=oracle) for s in out]


def summarise(scores: list[CaseScore]) -> dict[str, dict]:
    """Per method: effect-type precision, recall and F1 (micro over cases), F1 crediting reported
    equivalent explanations (``f1_equivalence_classes``), both again over the cases the
    recording supports (``f1_supported``, ``f1_supported_equivalence_classes``, over
    ``supported_cases``: see :attr:`CaseScore.supported`), false positives on null cases, median
    relative value error, median held-out RMS improvement (before / after) on the last quarter
    and on the second recording, and the share of effect cases whose second-recording RMS falls
    at least ``GAIN_BAR``-fold (``other_gain_at_bar``, of all and of the supported effect cases)."""

    def f1(tp: int, fp: int, fn: int) -> float | None:
        return 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else None

    def counts(xs: list[CaseScore]) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
        """(TP, FP, missed) summed over ``xs``: strict, and crediting equivalent explanations."""
        strict = tuple(sum(getattr(x, k) for x in xs) for k in ("true_positives", "false_positives", "missed"))
        return strict, tuple(sum(x.class_scores[i] for x in xs if x.class_scores) for i in range(3))

    out = {}
    for m in METHODS:
        s = [x for x in scores if x.method == m]
        if not s:
            continue
        (tp, fp, fn), classes = counts(s)
        errs = [e for x in s for e in x.value_error.values()]
        gains = [x.rms_before / x.rms_after for x in s if x.rms_before and x.rms_after and x.truth]
        other = [x.other_rms_before / x.other_rms_after for x in s
                 if x.truth and x.other_rms_before and x.other_rms_after]
        other_sup = [x.other_rms_before / x.other_rms_after for x in s
                     if x.truth and x.supported and x.other_rms_before and x.other_rms_after]
        sup = [x for x in s if x.supported]
        sup_strict, sup_classes = counts(sup)
        out[m] = {
            "cases": len(s),
            "f1_equivalence_classes": f1(*classes),
            "precision": tp / (tp + fp) if tp + fp else None,
            "recall": tp / (tp + fn) if tp + fn else None,
            "f1": f1(tp, fp, fn),
            "supported_cases": len(sup),
            "f1_supported": f1(*sup_strict),
            "f1_supported_equivalence_classes": f1(*sup_classes),
            "null_false_positives": sum(x.false_positives for x in s if not x.truth),
            "median_value_error": float(np.median(errs)) if errs else None,
            "median_heldout_gain": float(np.median(gains)) if gains else None,
            "median_other_gain": float(np.median(other)) if other else None,
            "other_gain_at_bar": float(np.mean([g >= GAIN_BAR for g in other])) if other else None,
            "other_gain_at_bar_supported": float(np.mean([g >= GAIN_BAR for g in other_sup])) if other_sup else None,
            "mean_time_s": float(np.mean([x.time_s for x in s])),
        }
    return out


def as_dicts(scores: list[CaseScore]) -> list[dict]:
    return [{**asdict(s), "supported": s.supported} for s in scores]
