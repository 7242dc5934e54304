"""Inverse-dynamics calibration: torque error through the bridge's RNEA on filtered states.

For recordings with measured joint torques (a robot arm at 1 kHz), this is the scalable
alternative to output-error collocation (:mod:`kinemaforge_opt.nlp.joint_space`):

1. **States.**  q, v and tau get the same zero-phase 4th-order Butterworth low-pass (parallel
   filtering, as :func:`kinemaforge_opt.arm.idim.filtered_states`); a = d/dt of the filtered v
   (v = d/dt of the filtered q when v is not recorded).  Default cutoff: :func:`motion_cutoff_hz`.
   ``trim_s`` is dropped at each end (filter transients) and the rest decimated to at most
   ``max_samples`` samples (the filter removed everything above the new Nyquist frequency).
   A recording with gaps (several joined end to end) is filtered and trimmed per stretch.
2. **Residual.**  r_k = tau_model(q_k, v_k, a_k; theta, phi) − tau_k, with
   tau_model = RNEA(q, v, a; theta) (the native bridge, armature included) − passive(q, v; phi),
   passive = −damping·v − coulomb·tanh(v/eps) + bias (the effect library's laws with its default
   ``V_SMOOTH``, i.e. the law :meth:`JointDynamics.passive_force` and the embedding use), plus the
   model's fixed passive terms.  The per-sample function is ``casadi.Function.map``-ped over the
   samples.  Every supported free parameter enters tau_model *linearly*, so r(z) = J z + r(0)
   exactly; the mapped function and its Jacobian are evaluated once (2 threads) at the nominal
   values and the NLP sees the QR-compressed least-squares term ``‖R z − c‖² + rss⊥`` — exact,
   and independent of the number of samples.
3. **NLP** (:class:`~kinemaforge_opt.nlp.problem.Problem`, IPOPT), named terms:
   ``torque`` = Σ_k Σ_j (r_kj/σ_j)² / (N n) over the samples where joint j moves (|v_j| at least
   ``slow_fraction`` of its RMS speed; friction at rest is stiction or creep, not the sign law);
   ≈ 1 at the noise level; σ_j: per-joint RMS residual of an ordinary least-squares
   fit on the base parameters — weighted least squares in the IDIM-WLS sense) and
   ``prior`` = Σ_i ((z_i − z0_i)/κ)² / (N n), a Gaussian prior N(nominal, (κ·scale_i)²) with
   κ = ``PRIOR_WIDTH`` = 1 parameter scale (100 % of the parameter's typical size; its weight is
   1/(N n) that of one σ-normalised torque residual squared, 7e-5 for 2000 samples of 7 joints):
   negligible wherever the data speak, it holds the
   combinations the data cannot determine at their nominal values instead of fitting noise;
   ``inertia_prior``, the same tiny weight on the log-det divergence of each freed pseudo-inertia
   from its nominal (:func:`entropic_divergence`), keeps the optimum off the boundary of physical
   consistency, which the log-Cholesky coordinates only reach at infinity.
   Variables: z = p / scale (``nlp.parameters.make_block`` scales from the data) for armature and
   friction (sign bounds), and for every freed ``<link>.inertia`` the 10 log-Cholesky parameters
   of its pseudo-inertia (Rucker & Wensing 2022): J = U Uᵀ, U = e^α [[e^d1, s12, s13, t1],
   [0, e^d2, s23, t2], [0, 0, e^d3, t3], [0, 0, 0, 1]], so J ≻ 0 — positive mass and an inertia
   satisfying the triangle inequalities — for every value of the variables.
4. **Identifiability.**  Base parameters by QR with column pivoting of the weighted,
   column-normalised regressor J (:func:`kinemaforge_opt.arm.idim.base_columns`); every other
   parameter is reported in words (no effect at all, or determined only together with named
   base parameters).  95 % intervals from the Gauss–Newton covariance s² (JᵀJ + prior)⁻¹, s² the
   weighted residual variance inflated for AR(1)-correlated residuals.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import casadi as ca
import numpy as np
import scipy.signal

from ..arm.idim import base_columns
from ..calibration import _UNITS, Calibration, Estimate, apply_parameters
from ..errors import DataError, UnknownNameError
from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..model.pinocchio import DYNAMIC_PARAMETER_NAMES
from ..physics.effects import EFFECTS
from ..symbolic import build_dynamics
from .joint_space import active_effects, data_scales, stretches
from .parameters import make_block
from .problem import Problem
from .sensitivity import ar1_inflation

#: Width of the Gaussian prior toward the nominal value, in parameter scales (see module doc).
PRIOR_WIDTH = 1.0
#: Relative threshold on |R_kk| for a parameter to count as a base parameter.
BASE_RTOL = 1e-6
#: Force parameters fitted here, each entering the torque linearly, and the effect they belong to.
_FORCE_FIELDS = {"damping": "viscous_damping", "coulomb": "coulomb_friction", "bias": "constant_bias"}


# --- log-Cholesky parameterisation of the pseudo-inertia -----------------------------------


def pseudo_inertia(pi: np.ndarray) -> np.ndarray:
    """4×4 pseudo-inertia J = [[½ tr(I) 1 − I, h], [hᵀ, m]] of Pinocchio dynamic parameters
    pi (10,) = [m, h (3) = m c, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] (inertia about the link origin)."""
    m, h = pi[0], pi[1:4]
    I = np.array([[pi[4], pi[5], pi[7]], [pi[5], pi[6], pi[8]], [pi[7], pi[8], pi[9]]])
    J = np.zeros((4, 4))
    J[:3, :3] = 0.5 * np.trace(I) * np.eye(3) - I
    J[:3, 3] = J[3, :3] = h
    J[3, 3] = m
    return J


def log_cholesky_from_dynamic(pi: np.ndarray) -> np.ndarray:
    """Log-Cholesky parameters (10,) [α, d1, d2, d3, s12, s23, s13, t1, t2, t3] of ``pi``.
    A pseudo-inertia that is not positive definite (massless or degenerate link) is first moved
    inside the cone by adding ε·1 (ε = 1e-6 × its largest entry)."""
    J = pseudo_inertia(np.asarray(pi, dtype=float))
    eps = 1e-6 * max(np.abs(J).max(), 1e-6)
    while np.linalg.eigvalsh(J).min() <= 0:
        J = J + eps * np.eye(4)
        eps *= 10
    P = np.eye(4)[::-1]
    U = P @ np.linalg.cholesky(P @ J @ P) @ P  # upper triangular, J = U Uᵀ
    ea = U[3, 3]
    d = np.log(np.diag(U)[:3] / ea)
    return np.array([np.log(ea), *d, U[0, 1] / ea, U[1, 2] / ea, U[0, 2] / ea, *(U[:3, 3] / ea)])


def dynamic_from_log_cholesky(x):
    """Pinocchio dynamic parameters (10,) of log-Cholesky parameters x (10,); numpy or casadi."""
    sym = isinstance(x, (ca.SX, ca.MX, ca.DM))
    exp = ca.exp if sym else np.exp
    a, d1, d2, d3, s12, s23, s13, t1, t2, t3 = (x[i] for i in range(10))
    rows = [[exp(d1), s12, s13, t1], [0, exp(d2), s23, t2], [0, 0, exp(d3), t3], [0, 0, 0, 1]]
    U = exp(a) * (ca.vertcat(*[ca.horzcat(*r) for r in rows]) if sym else np.array(rows, dtype=float))
    J = ca.mtimes(U, U.T) if sym else U @ U.T
    S = J[:3, :3]
    trS = S[0, 0] + S[1, 1] + S[2, 2]
    I = [[trS - S[0, 0], -S[0, 1], -S[0, 2]], [-S[0, 1], trS - S[1, 1], -S[1, 2]], [-S[0, 2], -S[1, 2], trS - S[2, 2]]]
    out = [J[3, 3], J[0, 3], J[1, 3], J[2, 3], I[0][0], I[0][1], I[1][1], I[0][2], I[1][2], I[2][2]]
    return ca.vertcat(*out) if sym else np.array(out, dtype=float)


def entropic_divergence(x, x0: np.ndarray):
    """Bregman (log-det) divergence of the pseudo-inertia J(x) from J(x0),
    −log det(J0⁻¹ J) + tr(J0⁻¹ J) − 4 ≥ 0 (Lee & Wensing): zero at x0, infinite on the boundary of
    physical consistency; x casadi (10,), x0 numpy (10,)."""
    J0 = pseudo_inertia(dynamic_from_log_cholesky(x0))
    J = _pseudo_inertia_sym(dynamic_from_log_cholesky(x))
    log_det_ratio = 2 * (4 * x[0] + x[1] + x[2] + x[3]) - np.log(np.linalg.det(J0))
    return -log_det_ratio + ca.trace(ca.mtimes(ca.DM(np.linalg.inv(J0)), J)) - 4


def _pseudo_inertia_sym(pi):
    I = ca.vertcat(ca.horzcat(pi[4], pi[5], pi[7]), ca.horzcat(pi[5], pi[6], pi[8]), ca.horzcat(pi[7], pi[8], pi[9]))
    top = ca.horzcat(0.5 * ca.trace(I) * ca.DM.eye(3) - I, pi[1:4])
    return ca.vertcat(top, ca.horzcat(pi[1:4].T, pi[0]))


# --- data -----------------------------------------------------------------------------------


def motion_cutoff_hz(rec: Recording, factor: float = 8.0, power: float = 0.99) -> float:
    """Low-pass cutoff [Hz] from the data: ``factor`` × the frequency below which ``power`` of the
    (mean-removed) velocity power lies, summed over joints; clipped to [1 Hz, fs/10].  For a
    Fourier excitation of harmonics up to f_max this is ≈ 8 f_max: the filter passes the motion
    untouched (4th-order Butterworth, gain error < 1e-7 at f_c/8) and removes sensor noise and the
    recording controller's reaction to it."""
    v = rec.v if rec.v is not None else np.gradient(rec.q, rec.t, axis=0)
    f, p = scipy.signal.periodogram(v - v.mean(axis=0), fs=1.0 / rec.dt, axis=0)
    c = np.cumsum(p.sum(axis=1))
    f_motion = f[min(np.searchsorted(c, power * c[-1]), f.size - 1)]
    return float(np.clip(factor * f_motion, 1.0, 0.1 / rec.dt))


def filtered_states(rec: Recording, cutoff_hz: float) -> tuple[np.ndarray, ...]:
    """(q, v, a, tau), each (T, n): zero-phase 4th-order Butterworth at ``cutoff_hz`` [Hz] on q,
    v (or d/dt q) and tau; a = d/dt of the filtered v [rad/s²].  Each stretch between gaps in the
    recording (:func:`~kinemaforge_opt.nlp.joint_space.stretches`; e.g. recordings joined end to
    end) on its own; one too short for the filter's edge padding is NaN (left out of the fit)."""
    fs = 1.0 / rec.dt
    if not 0 < cutoff_hz < fs / 2:
        raise DataError(f"cutoff {cutoff_hz} Hz must lie between 0 and the Nyquist frequency {fs / 2} Hz")
    sos = scipy.signal.butter(4, cutoff_hz, fs=fs, output="sos")
    tau = rec.tau if rec.tau is not None else np.zeros_like(rec.q)
    out = [np.full(rec.q.shape, np.nan) for _ in range(4)]
    f = lambda x: scipy.signal.sosfiltfilt(sos, x, axis=0)  # noqa: E731
    for i, j in stretches(rec.t):
        if j - i <= 3 * (2 * len(sos) + 1):  # sosfiltfilt's default edge padding
            continue
        t = rec.t[i:j]
        q = f(rec.q[i:j])
        v = f(rec.v[i:j]) if rec.v is not None else np.gradient(q, t, axis=0)
        for k, x in enumerate((q, v, np.gradient(v, t, axis=0), f(tau[i:j]))):
            out[k][i:j] = x
    return tuple(out)


def _check_inputs(model: ArticulatedModel, recording: Recording) -> Recording:
    from .joint_space import match_recording

    if recording.tau is None:
        raise DataError("inverse-dynamics calibration needs measured torques: the recording has no tau:<joint> columns")
    rec = match_recording(model, recording)  # joint names, motion, SI units
    still = [j for j, span in zip(model.joint_names, np.ptp(rec.q, axis=0)) if span < 1e-6]
    if still:
        raise DataError(f"recording shows no motion of joint(s) {still}: their dynamics cannot be identified")
    return rec


def _free_parameters(model: ArticulatedModel, free, effects) -> tuple[str, ...]:
    """Validated free names; effects' parameters are freed too.  Default: every moving link's
    inertia and every movable joint's armature, damping, Coulomb friction and bias."""
    if free is None:
        free = [f"{j.child}.inertia" for j in model.movable_joints]
        free += [f"{j.name}.{p}" for j in model.movable_joints for p in ("armature", *_FORCE_FIELDS)]
    free = list(free)
    field_of = {v: k for k, v in _FORCE_FIELDS.items()}
    for joint, types in (effects or {}).items():
        for t in types:
            if t not in field_of:
                raise UnknownNameError(f"effect fitted by inverse dynamics (joint {joint!r})", t, field_of)
        active_effects(model, {joint: tuple(types)})  # validates the joint name
        free += [f"{joint}.{field_of[t]}" for t in types]
    free = list(dict.fromkeys(free))
    links = {l.name for l in model.links if l.name != model.root.name}
    valid = {f"{l}.inertia" for l in links} | {f"{j}.{p}" for j in model.joint_names for p in ("armature", *_FORCE_FIELDS)}
    for name in free:
        if name not in valid:
            raise UnknownNameError(
                "free parameter of the inverse-dynamics method (parameters entering the torque "
                "linearly; use method='collocation' for the others)", name, valid)
    return tuple(free)


# --- the fit --------------------------------------------------------------------------------


def calibrate_inverse_dynamics(
    model: ArticulatedModel,
    recording: Recording,
    free=None,
    effects: dict[str, tuple[str, ...]] | None = None,
    max_iter: int = 500,
    cutoff_hz: float | None = None,
    max_samples: int = 2000,
    trim_s: float = 0.1,
    slow_fraction: float = 0.1,
    on_iteration: Callable[[int, float], None] | None = None,
) -> Calibration:
    """Fit ``free`` parameters of ``model`` to the measured torques of ``recording`` (module doc).
    on_iteration: passed to :meth:`~kinemaforge_opt.nlp.problem.Problem.solve`.

    free: names among ``<link>.inertia`` (10, log-Cholesky inside), ``<joint>.armature``,
    ``<joint>.damping``, ``<joint>.coulomb``, ``<joint>.bias``; default: all of them for the
    moving links and movable joints.  effects: {joint: ("viscous_damping" | "coulomb_friction" |
    "constant_bias", …)} frees those parameters too.  cutoff_hz: low-pass [Hz], default
    :func:`motion_cutoff_hz`; max_samples: samples kept after decimation; trim_s [s]: dropped at
    each end; slow_fraction: samples where |v_j| is below this fraction of joint j's RMS speed are
    left out of joint j's residual (friction there is the real joint's stiction or creep, not the
    sign law, and filtered torques smear its jump).  The returned :class:`Calibration` has
    ``q_fit``/``v_fit`` = the filtered states (T, n; NaN on a stretch between gaps too short to filter) and ``rms_q`` = per-joint RMS torque residual on the fitting samples [N·m] (there is no
    output error in q in this method).  Raises for bad input before any work starts.
    """
    start = time.perf_counter()
    rec = _check_inputs(model, recording)
    free = _free_parameters(model, free, effects)
    cutoff = motion_cutoff_hz(rec) if cutoff_hz is None else float(cutoff_hz)
    qf, vf, af, tauf = filtered_states(rec, cutoff)
    inside = np.flatnonzero(np.any([(rec.t >= rec.t[i] + trim_s) & (rec.t <= rec.t[j - 1] - trim_s)
                                    for i, j in stretches(rec.t)], axis=0) & np.isfinite(qf).all(axis=1))
    if inside.size < 10:
        raise DataError(f"recording of {rec.t[-1] - rec.t[0]:.3g} s is too short for inverse-dynamics calibration")
    keep = inside[:: max(1, int(np.ceil(inside.size / max_samples)))]
    q, v, a, tau = qf[keep], vf[keep], af[keep], tauf[keep]
    n, N = model.nq, keep.size

    bridge = tuple(p for p in free if p.endswith((".inertia", ".armature")))
    forces = tuple(p for p in free if p not in bridge)
    dyn = build_dynamics(model, bridge)
    scales = data_scales(model, Recording(rec.t[keep], rec.joint_names, q, v, tau))
    blocks = [make_block(model, p, dyn.parameter(p).nominal, scales) for p in bridge]
    blocks += [make_block(model, p, np.array([getattr(model.joint(p.rsplit(".", 1)[0]).dynamics, p.rsplit(".", 1)[1])]), scales)
               for p in forces]
    z0 = np.concatenate([b.nominal / b.scale for b in blocks])
    nz = z0.size

    # Per-sample residual, linear in z: r = J_k z + r0_k; mapped over the samples (2 threads).
    zs, qs, vs, as_, us = ca.SX.sym("z", nz), ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("a", n), ca.SX.sym("tau", n)
    theta = ca.vertcat(*[zs[_slice(blocks, b.name)] * b.scale for b in blocks[: len(bridge)]]) if bridge else ca.SX(0, 1)
    model_tau = dyn.rnea(qs, vs, as_, theta) - _passive(model, forces, blocks, zs, qs, vs)
    r = model_tau - us
    # The bridge divides by the mass internally, so J_k is evaluated at a point with positive
    # masses (nominal, moved inside the physical cone): r(z) = J_k (z - z_eval) + r(z_eval).
    z_eval = np.concatenate([dynamic_from_log_cholesky(log_cholesky_from_dynamic(b.nominal)) / b.scale
                             if b.name.endswith(".inertia") else b.nominal / b.scale for b in blocks])
    per_sample = ca.Function("torque_residual", [qs, vs, as_, us, zs], [ca.jacobian(r, zs), r])
    Js, r_eval = per_sample.map(N, "thread", 2)(q.T, v.T, a.T, tau.T, z_eval)
    J = np.asarray(Js.full()).reshape(n, N, nz).transpose(1, 0, 2).reshape(N * n, nz)  # rows sample-major
    r0 = np.asarray(r_eval.full()).T.reshape(-1) - J @ z_eval  # residual at z = 0

    # Rows of slow joints are left out (weight 0); weighted least squares with sigma_j from an
    # OLS fit on the base parameters.  Only two tall QR factorisations touch all N n rows: the
    # rest works on the (nz + 1)-square triangular factors.
    moving = (np.abs(v) >= slow_fraction * np.sqrt(np.mean(v**2, axis=0))).reshape(-1)
    R1, c1, _ = _compress(J[moving], -r0[moving])
    base = _base_parameters(R1)
    beta = np.linalg.lstsq(R1[:, base], c1, rcond=None)[0]
    ols = np.where(moving, r0 + J[:, base] @ beta, 0.0).reshape(N, n)
    count = np.maximum(moving.reshape(N, n).sum(axis=0), 1)
    sigma = np.maximum(np.sqrt(np.sum(ols**2, axis=0) / count), 1e-6 * np.sqrt(np.mean(tau**2, axis=0)) + 1e-12)
    w = np.tile(1.0 / sigma, N) * moving
    R, c, rss_perp = _compress(J * w[:, None], -r0 * w)
    base = _base_parameters(R)

    prob = Problem(f"calibrate_id_{model.name}")
    parts, divergence = [], ca.MX(0)
    for b in blocks:
        if b.name.endswith(".inertia"):
            x0 = log_cholesky_from_dynamic(b.nominal)
            x = prob.variable(f"logchol:{b.name}", 10, init=x0)
            parts.append(dynamic_from_log_cholesky(x) / b.scale)
            divergence += entropic_divergence(x, x0)
        else:
            parts.append(prob.variable(f"p:{b.name}", b.size, lower=b.lower / b.scale, upper=b.upper / b.scale, init=b.nominal / b.scale))
    z = ca.vertcat(*parts)
    prob.add_cost("torque", (ca.sumsqr(ca.mtimes(R, z) - c) + rss_perp) / (N * n))
    prob.add_cost("prior", ca.sumsqr(z - z0) / (PRIOR_WIDTH**2 * N * n))
    if any(b.name.endswith(".inertia") for b in blocks):
        prob.add_cost("inertia_prior", divergence / (PRIOR_WIDTH**2 * N * n))
    res = prob.solve(max_iter=max_iter, options={"expand": True}, on_iteration=on_iteration)
    zhat = np.concatenate([
        dynamic_from_log_cholesky(res.values[f"logchol:{b.name}"]) / b.scale if b.name.endswith(".inertia")
        else res.values[f"p:{b.name}"] for b in blocks])

    # Covariance (Gauss-Newton, prior included) and the fitted residuals.
    resid = J @ zhat + r0
    dof = max(int(moving.sum()) - base.size, 1)
    resid_w = (resid * w).reshape(N, n)
    s2 = float(np.sum(resid_w**2)) / dof * ar1_inflation(resid_w.T)
    cov = s2 * np.linalg.inv(R.T @ R + np.eye(nz) / PRIOR_WIDTH**2)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    rms = np.sqrt(np.mean(resid.reshape(N, n) ** 2, axis=0))

    estimates, values = {}, {}
    for b in blocks:
        s = _slice(blocks, b.name)
        value = zhat[s] * b.scale
        if not b.name.endswith(".inertia"):
            value = np.clip(value, b.lower, b.upper)  # IPOPT may overstep bounds by ~1e-8
        half = 1.96 * sd[s] * b.scale
        owner, field = b.name.rsplit(".", 1)
        linear = owner in model.joint_names and model.joint(owner).type == "prismatic"
        estimates[b.name] = Estimate(b.name, value, b.nominal, value - half, value + half, _UNITS[field][1 if linear else 0])
        values[b.name] = value
    words = _identifiability_words(blocks, R, base, estimates)
    fitted = apply_parameters(model, values)
    used = {j: tuple(_FORCE_FIELDS[p.rsplit(".", 1)[1]] for p in forces if p.startswith(j + ".")) for j in model.joint_names}
    return Calibration(
        success=res.success, status=res.status, iterations=res.iterations, estimates=estimates,
        model=fitted, effects={j: tuple(dict.fromkeys(active_effects(model)[j] + e)) for j, e in used.items()},
        identifiability=tuple(words), costs=res.costs, violations=res.violations,
        rms_q=dict(zip(model.joint_names, map(float, rms))), q_fit=qf, v_fit=vf, recording=rec,
        solve_time_s=time.perf_counter() - start,
    )


def _compress(A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(R, c, rss) with ‖A z − y‖² = ‖R z − c‖² + rss for every z; R (p, p) upper triangular
    from the QR factorisation of [A | y] (same column norms and dependencies as A)."""
    Raug = np.linalg.qr(np.column_stack([A, y]), mode="r")
    p = A.shape[1]
    return Raug[:p, :p], Raug[:p, p], float(Raug[p, p] ** 2) if Raug.shape[0] > p else 0.0


def _base_parameters(J: np.ndarray) -> np.ndarray:
    """Indices of base parameters of the regressor J (rows × parameters): QR with column pivoting
    of the column-normalised J; columns below ``BASE_RTOL`` × the largest norm count as zero."""
    norms = np.linalg.norm(J, axis=0)
    live = norms > BASE_RTOL * norms.max()
    return base_columns(np.where(live, J / np.where(live, norms, 1.0), 0.0), BASE_RTOL)


def _slice(blocks, name: str) -> slice:
    offset = 0
    for b in blocks:
        if b.name == name:
            return slice(offset, offset + b.size)
        offset += b.size
    raise KeyError(name)


def _passive(model: ArticulatedModel, forces, blocks, z, q, v):
    """Passive joint forces (n,) SX: freed force parameters from z, every other term of the
    model's JointDynamics fixed at its value (the laws of ``physics.effects``)."""
    out = []
    for i, j in enumerate(model.movable_joints):
        freed = {p.rsplit(".", 1)[1]: z[_slice(blocks, p)][0] * next(b for b in blocks if b.name == p).scale[0]
                 for p in forces if p.rsplit(".", 1)[0] == j.name}
        fixed = dataclasses.replace(j.dynamics, **{f: 0.0 for f in freed})
        total = fixed.passive_force(q[i], v[i])
        for field, value in freed.items():
            total = total + EFFECTS[_FORCE_FIELDS[field]].force(q[i], v[i], value)
        out.append(total)
    return ca.vertcat(*out)


def _labels(blocks) -> list[str]:
    out = []
    for b in blocks:
        out += [f"{b.name}[{l}]" for l in DYNAMIC_PARAMETER_NAMES] if b.name.endswith(".inertia") else [b.name]
    return out


def _identifiability_words(blocks, R: np.ndarray, base: np.ndarray, estimates: dict[str, Estimate]) -> list[str]:
    """Sentences on what the recording determines: base-parameter count, then every non-base
    parameter (no effect, or only in combination with named base parameters), then base
    parameters whose 95 % interval is wider than their value.  R: the weighted regressor or its
    triangular factor (same column norms and dependencies)."""
    labels = _labels(blocks)
    norms = np.linalg.norm(R, axis=0)
    Wn = R / np.maximum(norms, 1e-300)
    nz = len(labels)
    words = [f"the recording determines {base.size} of {nz} parameter directions (base parameters); "
             "the remaining directions are held at the prior (nominal values) by the weak prior"]
    dependent = np.setdiff1d(np.arange(nz), base)
    coef, *_ = np.linalg.lstsq(Wn[:, base], Wn[:, dependent], rcond=None) if dependent.size else (None,)
    for k, d in enumerate(dependent):
        if norms[d] <= BASE_RTOL * norms.max():
            words.append(f"{labels[d]} has no effect on the joint torques of this recording: it stays at its prior (nominal)")
            continue
        partners = [f"{labels[base[i]]} ({coef[i, k]:+.2f})" for i in np.argsort(-np.abs(coef[:, k]))[:4] if abs(coef[i, k]) > 0.05]
        words.append(f"{labels[d]} cannot be separated from {', '.join(partners)}: the data fix only their "
                     "combination, and the split between them follows the prior (nominal)")
    offset = 0
    for b in blocks:
        for i in range(b.size):
            if offset + i in base:
                e = estimates[b.name]
                half = (e.ci95_high[i] - e.ci95_low[i]) / 2
                if half > abs(e.value[i]) and half > 1e-6 * b.scale[i]:
                    words.append(f"{labels[offset + i]} is poorly determined: {e.value[i]:.4g} ± {half:.2g} {e.unit}")
        offset += b.size
    return words


__all__ = ["calibrate_inverse_dynamics", "dynamic_from_log_cholesky", "log_cholesky_from_dynamic", "motion_cutoff_hz",
           "pseudo_inertia", "filtered_states"]
