"""Two peer methods for mismatch discovery, run on the same recordings as ``diagnose``:

* :func:`idls` — classical inverse-dynamics least squares: the nominal model's inverse-dynamics
  residual force r = M(q) a + h(q, v) - τ_applied - τ_passive (v, a from a Savitzky–Golay fit) is
  regressed on the effect library's columns (:mod:`.library`) with physical sign bounds; effects
  enter by forward selection while ΔBIC < ``DELTA_BIC``.
* :func:`sindy` — PySINDy's sequentially thresholded least squares (STLSQ): the acceleration the
  nominal model does not explain, a - a_nom = M⁻¹ r, regressed on M⁻¹ × the same columns; the
  threshold is swept over the path of the data's own coefficient magnitudes and the sparsity
  chosen by the same ΔBIC rule (Mangan et al. 2017, information criteria for SINDy).

Both regress only the samples where every joint moves (speed above ``THRESHOLD_SIGMA`` times the
velocity noise): at standstill, dry friction holds whatever force is applied and is no function
of sign(v), the usual exclusion in friction identification.  Both use the same fit / held-out
split as ``diagnose`` and the same evidence rule: BIC on the
effective number of independent residuals N(1 - ρ)/(1 + ρ) (ρ: lag-1 autocorrelation), the
same threshold (:data:`kinemaforge_opt.physics.selection.DELTA_BIC`).  Neither is told the
concealed effects.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..nlp.sensitivity import lag1_autocorrelation
from ..physics.selection import DELTA_BIC
from ..nlp.joint_space import noise_std
from ..physics.locate import THRESHOLD_SIGMA, inverse_dynamics_residual, smooth_derivatives
from ..synth.effects import unit_of
from .library import GROUPS, NONNEGATIVE, JointLibrary, joint_library, selected_effects

Column = tuple[int, str]  # (joint index, column name)


@dataclass(frozen=True)
class BaselineEffect:
    """An effect a baseline reports: DESIGN.md ``type``, ``value`` in ``unit``, extra ``params``."""

    joint: str
    type: str
    value: float
    unit: str
    params: dict = field(default_factory=dict)


@dataclass(frozen=True)
class BaselineResult:
    """What a baseline found: ``effects``, the fitted coefficients per joint (column name ->
    value, see :mod:`.library`), the libraries, and the wall time [s]."""

    method: str
    effects: tuple[BaselineEffect, ...]
    coefs: dict[str, dict[str, float]]
    libraries: dict[str, JointLibrary]
    time_s: float


@dataclass(frozen=True)
class _Data:
    libs: list[JointLibrary]
    r: np.ndarray  # (T, n) inverse-dynamics residual force
    Minv: np.ndarray  # (T, n, n)


def split(rec: Recording, holdout_fraction: float) -> tuple[Recording, Recording | None]:
    """The fit span and the held-out span, exactly as ``diagnose`` splits a recording."""
    k = int(round(rec.t.size * (1 - holdout_fraction)))
    fit = rec.window(rec.t[0], rec.t[k - 1])
    held = rec.window(rec.t[k], rec.t[-1]) if k < rec.t.size - 3 else None
    return fit, held


def velocity_noise(rec: Recording) -> np.ndarray:
    """(n,) std of the smoothed velocity's noise [rad/s or m/s]: the encoder noise of each joint
    times the gain of the very smoother the regressions use (measured on unit white noise)."""
    unit = np.random.default_rng(0).normal(size=rec.q.shape)
    _, v, _ = smooth_derivatives(Recording(rec.t, rec.joint_names, unit))
    return noise_std(rec.q) * np.std(v, axis=0)


def _data(model: ArticulatedModel, rec: Recording) -> _Data:
    import pinocchio as pin

    from ..model.pinocchio import build_pin_model

    rec = rec.select(model.joint_names)
    r, q, v, a = inverse_dynamics_residual(model, rec)
    moving = np.all(np.abs(v) > THRESHOLD_SIGMA * velocity_noise(rec), axis=1)
    tau = rec.tau if rec.tau is not None else np.zeros_like(q)
    joints = model.movable_joints
    id_force = r + tau + model.passive_forces(q, v)
    r, q, v, id_force = r[moving], q[moving], v[moving], id_force[moving]
    pm = build_pin_model(model)
    pd = pm.createData()
    Minv = np.array([pin.computeMinverse(pm, pd, qq) for qq in q])
    Minv = np.triu(Minv) + np.swapaxes(np.triu(Minv, 1), 1, 2)  # Pinocchio fills the upper triangle
    libs = [joint_library(model, j.name, q[:, k], v[:, k], id_force[:, k]) for k, j in enumerate(joints)]
    return _Data(libs, r, Minv)


def _design(d: _Data, cols: list[Column], weighted: bool) -> np.ndarray:
    """(T·n, len(cols)) stacked design: column (k, c) acts on joint k; ``weighted`` maps forces to
    accelerations through M⁻¹."""
    T, n = d.r.shape
    out = np.zeros((T, n, len(cols)))
    for i, (k, c) in enumerate(cols):
        x = d.libs[k].columns[c]
        out[:, :, i] = d.Minv[:, :, k] * x[:, None] if weighted else np.eye(n)[k][None, :] * x[:, None]
    return out.reshape(T * n, len(cols))


def _target(d: _Data, weighted: bool) -> np.ndarray:
    return (np.einsum("tij,tj->ti", d.Minv, d.r) if weighted else d.r).reshape(-1)


def _delta_bic(res_rich: np.ndarray, res_simple: np.ndarray, extra: int, n: int) -> float:
    """BIC(rich) - BIC(simple) on the effective number of independent residuals (as diagnose)."""
    rho = lag1_autocorrelation(res_rich.reshape(-1, n).T)
    n_eff = max(res_rich.size * (1 - rho) / (1 + rho), 2.0)
    rss1, rss0 = float(res_rich @ res_rich), float(res_simple @ res_simple)
    return float(n_eff * np.log(max(rss1, 1e-300) / max(rss0, 1e-300)) + extra * np.log(n_eff))


def _bounded_lstsq(A: np.ndarray, y: np.ndarray, cols: list[Column]) -> np.ndarray:
    from scipy.optimize import lsq_linear

    scale = np.maximum(np.linalg.norm(A, axis=0), 1e-300)
    lower = np.array([0.0 if c in NONNEGATIVE else -np.inf for _, c in cols])
    sol = lsq_linear(A / scale, y, bounds=(lower, np.full(len(cols), np.inf)), method="bvls")
    return sol.x / scale


def _result(method: str, model: ArticulatedModel, d: _Data, cols: list[Column], theta: np.ndarray, t0: float) -> BaselineResult:
    coefs = {lib.joint: {} for lib in d.libs}
    for (k, c), x in zip(cols, theta):
        coefs[d.libs[k].joint][c] = float(x)
    found = []
    for lib in d.libs:
        jtype = model.joint(lib.joint).type
        for etype, (value, params) in selected_effects(lib, coefs[lib.joint]).items():
            found.append(BaselineEffect(lib.joint, etype, float(value), unit_of(etype, jtype), params))
    return BaselineResult(method, tuple(found), coefs, {lib.joint: lib for lib in d.libs}, time.perf_counter() - t0)


def idls(model: ArticulatedModel, recording: Recording, holdout_fraction: float = 0.25) -> BaselineResult:
    """Inverse-dynamics least squares with forward selection by ΔBIC over effect groups.  A group
    whose sign-bounded coefficient sits at zero explains nothing and is not accepted."""
    t0 = time.perf_counter()
    fit, _ = split(recording, holdout_fraction)
    d = _data(model, fit)
    n = d.r.shape[1]
    y = _target(d, weighted=False)
    cols: list[Column] = []
    theta = np.zeros(0)
    res = y
    while True:
        best = None
        for k, lib in enumerate(d.libs):
            for effect in lib.effects:
                new = [(k, c) for c in GROUPS[effect] if (k, c) not in cols]
                if not new:
                    continue
                trial = cols + new
                A = _design(d, trial, weighted=False)
                th = _bounded_lstsq(A, y, trial)
                if any(th[trial.index(c)] == 0.0 for c in new if c[1] in NONNEGATIVE):
                    continue
                r1 = y - A @ th
                db = _delta_bic(r1, res, len(new), n)
                if best is None or db < best[0]:
                    best = (db, trial, th, r1)
        if best is None or best[0] >= DELTA_BIC:
            break
        _, cols, theta, res = best
    return _result("ID-LS", model, d, cols, theta, t0)


def sindy(model: ArticulatedModel, recording: Recording, holdout_fraction: float = 0.25) -> BaselineResult:
    """PySINDy STLSQ on the unexplained acceleration; sparsity by the ΔBIC rule along the
    threshold path (thresholds = the magnitudes of the column-normalised least-squares solution)."""
    import pysindy as ps

    t0 = time.perf_counter()
    fit, _ = split(recording, holdout_fraction)
    d = _data(model, fit)
    n = d.r.shape[1]
    cols = [(k, c) for k, lib in enumerate(d.libs) for c in lib.columns]
    A = _design(d, cols, weighted=True)
    y = _target(d, weighted=True)
    scale = np.maximum(np.linalg.norm(A, axis=0), 1e-300)
    full = np.linalg.lstsq(A / scale, y, rcond=None)[0]
    path = {}
    for thr in [0.0] + sorted(np.nextafter(np.abs(full), np.inf)):
        opt = ps.STLSQ(threshold=float(thr), normalize_columns=True).fit(A, y[:, None])
        th = np.asarray(opt.coef_).reshape(-1)
        path.setdefault(tuple(np.flatnonzero(th)), th)
    theta, res, size = np.zeros(len(cols)), y, 0
    for support, th in sorted(path.items(), key=lambda kv: len(kv[0])):
        if len(support) <= size:
            continue
        r1 = y - A @ th
        if _delta_bic(r1, res, len(support) - size, n) < DELTA_BIC:
            theta, res, size = th, r1, len(support)
    return _result("PySINDy (STLSQ)", model, d, cols, theta, t0)
