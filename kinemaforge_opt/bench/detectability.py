"""Whether a concealed-effect recording shows its effect at all: the oracle ΔBIC.

A discovery method can only be asked to find an effect the data support.  The oracle knows the
truth: it fits the whole recording (``diagnose``'s joint-space collocation, noise level and
friction smoothing) once with the nominal model and once with the true effects' parameters free,
started at their true values, and scores the gain with the information criterion ``diagnose``
selects by: ΔBIC = n ln(RSS_true / RSS_nominal) + k ln n.  At or above ``selection.DELTA_BIC``
even the truth, fitted from the right start, does not explain the recording better than the
nominal model by the margin a BIC selection demands: either the data do not show the effect,
or this transcription of the dynamics cannot represent it at the recording's rate, or the true
law makes the model open-loop unstable under the recorded force: a friction F(v) that falls with
speed grows any error at the rate -F'(v)/m, and a steep Stribeck drop dwelt in for seconds
amounts to tens of e-folds, so no single trajectory from one initial state, however exact the
law, follows the recording (see tests/bench/test_detectability.py).  The oracle is an upper
bound on what the fit can show, not a detector: it uses the answer.
"""

from __future__ import annotations

import numpy as np

from ..physics.search import HypothesisFit, effect_parameters
from ..physics.selection import n_free_params, rss_q
from ..nlp.joint_space import fit_span, friction_smoothing, measurement_sigma
from ..synth.effects import ConcealedEffect, tilted_axis
from .recordings import EffectRecording

ORACLE_MAX_ITER = 300


def true_start(model, effect: ConcealedEffect) -> dict[str, np.ndarray]:
    """The fit's parameters of ``effect`` at their true values (names as ``diagnose`` frees them)."""
    j, p = effect.joint, dict(effect.params)
    if effect.type == "axis_tilt":
        axis = tilted_axis(model.joint(j).axis, effect.value, float(p.get("azimuth", 0.0)))
        return {f"{j}.axis": np.asarray(axis, float)}
    if effect.type == "inertia_error":
        return {f"{model.joint(j).child}.inertia_ratio": np.array([effect.value])}
    values = {
        "viscous_damping": {"damping": effect.value},
        "coulomb_friction": {"coulomb": effect.value},
        "stribeck_friction": {"stribeck": effect.value, "v_stribeck": p.get("v_stribeck")},
        "spring": {"spring_stiffness": effect.value, "spring_rest": p.get("rest")},
        "constant_bias": {"bias": effect.value},
        "quadratic_drag": {"drag": effect.value},
        "limit_contact": {"limit_stop": effect.value, "limit_stiffness": p.get("stiffness")},
    }[effect.type]
    return {f"{j}.{k}": np.array([float(v)]) for k, v in values.items() if v is not None}


def oracle_delta_bic(er: EffectRecording) -> float | None:
    """ΔBIC of the true effects (free, started at their true values) against the nominal model on
    ``er.recording``; None on a null case or when either fit fails."""
    effects = er.shown_effects
    if not effects:
        return None
    model = er.model
    fit_rec, _ = fit_span(model, er.recording)  # what diagnose reads
    sigma = measurement_sigma(fit_rec.q)
    hyps = [(e.joint, e.type) for e in effects]
    stops = {e.joint: (1.0 if dict(e.params).get("side") == "upper" else -1.0, e.value)
             for e in effects if e.type == "limit_contact"}
    fit = HypothesisFit(model, fit_rec, hyps, None, stops, ORACLE_MAX_ITER, sigma, friction_smoothing(fit_rec))
    nominal = fit.solve([])
    init = {k: v for e in effects for k, v in true_start(model, e).items()}
    # the synthetic world's stops are elastic: their law has no contact damper to fit
    names = [n for e in effects for n in effect_parameters(model, e.joint, e.type)
             if not n.endswith(".limit_damping") or n in init]
    truth = fit.solve(names, start=nominal, init=init, states_from_data=True)
    if not (nominal.success and truth.success):
        return None
    n = fit_rec.q.size
    gain = rss_q(truth.q_fit, fit_rec.q, sigma) / rss_q(nominal.q_fit, fit_rec.q, sigma)
    return float(n * np.log(gain) + n_free_params(names) * np.log(n))
