"""Turn fitted relations into log-probabilities: which type joins a pair, and which parent a child has.

Residuals of real recordings are rarely white: a gripper slipping on a handle or a slightly
warped drawer rail leaves a smooth, millimetre-level model error that white-noise BIC would
"explain" with every extra parameter (a drifting helix, a 6 m-radius hinge).  The χ² is therefore
rescaled by c = s·min(1, σ²/σ_flex²): s = (1 − ρ₁)/(1 + ρ₁) is the effective sample fraction of
an AR(1) process, ρ₁ the lag-1 autocorrelation of the best-fitting model's residuals,
and σ_flex the per-coordinate scale of those residuals — the level of noise *plus* model error,
the σ that Mallows' Cp takes from the largest model (a robust scale, see ``effective_fraction``).  Latent joint values count s·N parameters.
White residuals at the sensor noise level give c = 1 and plain BIC.

Identifiability: a richer model is a candidate only when each simpler model it would replace is
clearly inadequate — that model's residual RMS exceeds SIGNIFICANCE (3, the usual 3σ level) times
the richer model's, both floored at the white-noise level, in positions or (full-pose tracks)
in rotations: a prismatic joint cannot explain a lid turning 80°, however small the lid's
position residual.  Otherwise the extra geometry (an arc's
sagitta, a helix's rise, a drawer's stroke) is not resolved by the data: a 6 m-radius "hinge"
on a drawer's 2 mm wobble, or a helix on a door's out-of-plane jitter, or a prismatic joint on
a static part's noise.

Conversely, a simpler model that an identifiable richer one *explains away* is no candidate
either: on a strongly autocorrelated track (one moving camera's, c ≈ 1/N) every χ² shrinks to
nothing and the parameter count alone would let a rigid "joint" with 15× the hinge's rotation
residual win.  The richer model must fit clearly better and nowhere clearly worse, and account
for the orientations: fit them clearly better, or to the noise.  A track whose orientation
wanders 20σ under every model (a fragment spanning two drawers) is no rigid body; a better fit
of its centroid rules nothing out.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.special import logsumexp

from .fit import SIGNIFICANCE, JointHypothesis
from .motion import MIN_SAMPLES, SIGMA_FLOOR

# Which simpler models each richer model must clearly beat to be identifiable.
SIMPLER = {"rigid": (), "prismatic": ("rigid",), "revolute": ("rigid", "prismatic"), "helical": ("revolute", "prismatic")}
# ... and every model nested in it (the simpler models' simpler models).
NESTED = {"rigid": (), "prismatic": ("rigid",), "revolute": ("rigid", "prismatic"), "helical": ("rigid", "prismatic", "revolute")}


def effective_fraction(hyps: dict[str, JointHypothesis]) -> tuple[float, float]:
    """(s, c): effective independent-sample fraction s ∈ [1/N, 1] of a pair's data and the χ²
    scale c = s·min(1, σ²/σ_flex²) (see module doc).

    The best fit is the one with the lowest robust χ² (the fits' own objective), and σ_flex²/σ²
    the mean squared normalised residual that, were all residuals alike, would give that χ² under
    the soft-L1 loss 2(√(1 + r²) − 1): a model error spread over every sample counts in full, as
    in an RMS, while a few gross outliers (one mis-registered frame) raise it only in proportion
    to their share — an RMS would let one 7 cm jump scale every model's χ² down fifty-fold and
    leave a drawer's 25 cm stroke indistinguishable from rest."""
    ref = min(hyps.values(), key=lambda h: h.chi2)  # the best fit: noise + model error
    n = ref.n_samples
    rho1 = float(np.clip(ref.residual_autocorr, 0.0, 1.0 - 1.0 / n))
    s = max((1.0 - rho1) / (1.0 + rho1), 1.0 / n)
    per_residual = ref.chi2 / (n * (6 if ref.rotation_sigma > 0 else 3))
    flex2 = (per_residual / 2.0 + 1.0) ** 2 - 1.0  # σ_flex²/σ², inverting the soft-L1 loss
    return s, s * min(1.0, 1.0 / flex2) if flex2 > 0 else s


def score_pair(hyps: dict[str, JointHypothesis]) -> dict[str, JointHypothesis]:
    """Rescore each type's BIC for correlated residuals and set ``confidence`` to the type's
    posterior probability for this pair, exp(−BIC/2) normalised over the identifiable types that
    no identifiable richer type explains away (the others get bic = inf, confidence = 0)."""
    s, c = effective_fraction(hyps)
    bic = {
        k: c * h.chi2 + (h.n_params + s * h.n_latent) * np.log(h.n_samples) for k, h in hyps.items()
    }
    # the white-noise floors, never above the best fit's residual (but not below SIGMA_FLOOR's):
    # that residual is noise plus model error, so a noise estimate above it is inflated by the
    # motion itself (a lid slammed 80° between two of 12 samples defeats the local-quadratic
    # smoother of ``noise_sigma``)
    first, least = next(iter(hyps.values())), np.sqrt(3.0) * SIGMA_FLOOR
    floor = max(least, min(np.sqrt(3.0) * first.noise_sigma, min(h.residual_rms for h in hyps.values())))
    floor_r = max(least, min(np.sqrt(3.0) * first.rotation_sigma, min(h.rotation_rms for h in hyps.values())))
    rms = {k: max(h.residual_rms, floor) for k, h in hyps.items()}
    rot = {k: max(h.rotation_rms, floor_r) for k, h in hyps.items()}

    def inadequate(j, k):  # simpler model j clearly misfits where k fits (positions or rotations)
        return rms[j] > SIGNIFICANCE * rms[k] or (rot[k] > 0 and rot[j] > SIGNIFICANCE * rot[k])

    def explains_away(k, j):  # richer k accounts for the track where simpler j fails (module doc)
        turns_better = rot[k] > 0 and rot[j] > SIGNIFICANCE * rot[k]
        holds_orientation = first.rotation_sigma == 0 or rot[k] <= SIGNIFICANCE * np.sqrt(3.0) * first.rotation_sigma
        fits_better = turns_better or (rms[j] > SIGNIFICANCE * rms[k] and holds_orientation)
        return fits_better and not inadequate(k, j)

    identifiable = [k for k in bic if all(inadequate(j, k) for j in SIMPLER[k])]
    ruled_out = {j for k in identifiable for j in NESTED[k] if explains_away(k, j)}
    bic = {k: bic[k] for k in identifiable if k not in ruled_out}
    log_w = log_posterior(bic)
    return {
        k: dataclasses.replace(h, bic=float(bic.get(k, np.inf)), confidence=float(np.exp(log_w.get(k, -np.inf))))
        for k, h in hyps.items()
    }


def log_posterior(bic: dict) -> dict:
    """{key: BIC} -> {key: log posterior} with exp(−BIC/2) weights (log-space, never underflows)."""
    keys = list(bic)
    v = -0.5 * np.array([bic[k] for k in keys])
    return dict(zip(keys, v - logsumexp(v)))


def closeness_z(a: JointHypothesis, b: JointHypothesis) -> float:
    """Vuong's closeness statistic for two non-nested fits of one child's positions (e.g. the
    child seen from two candidate parents) on their common samples: z > 0 favours ``a``; z is
    ≈ N(0, 1) when both explain the data equally well.  NaN when they share fewer than
    MIN_SAMPLES samples or either lacks its per-sample residuals.

    Per-sample Gaussian log-likelihood of the 3-D position residual, each fit at its own ML
    variance; the log-likelihood ratio less the BIC parameter correction, over its standard
    error √(N·var(d)/s), s the effective sample fraction of the per-sample differences d (lag-1
    autocorrelation, as in :func:`effective_fraction`)."""
    if a.position_residuals is None or b.position_residuals is None:
        return float("nan")
    t, ia, ib = np.intersect1d(a.times, b.times, return_indices=True)
    n = t.size
    if n < MIN_SAMPLES:
        return float("nan")

    def loglik(h, idx):
        e2 = np.sum(h.position_residuals[idx] ** 2, axis=1)
        v = max(float(np.mean(e2)) / 3.0, SIGMA_FLOOR**2)
        return -1.5 * np.log(v) - e2 / (2.0 * v)

    d = loglik(a, ia) - loglik(b, ib)
    dc = d - d.mean()
    ss = float(np.sum(dc * dc))
    rho1 = float(np.clip(np.sum(dc[1:] * dc[:-1]) / ss, 0.0, 1.0 - 1.0 / n)) if ss > 0 else 0.0
    s = max((1.0 - rho1) / (1.0 + rho1), 1.0 / n)
    ka, kb = (h.n_params + (s * n if h.n_latent else 0.0) for h in (a, b))
    lr = float(np.sum(d)) - 0.5 * (ka - kb) * np.log(n)
    se = np.sqrt(ss / s)  # √(N · var(d) / s)
    if se == 0.0:
        return 0.0 if lr == 0.0 else float(np.sign(lr) * np.inf)
    return lr / se
