"""One collocation fit for every hypothesis of a recording.

Forward selection tests many hypotheses (nominal model + a set of effects) on the same
recording.  :class:`HypothesisFit` builds the joint-space collocation fit once with the
parameters of *every* candidate effect present; a hypothesis is tested by an IPOPT problem in
which the parameters of the effects it leaves out are numeric constants at their nominal values.
At its nominal value every effect parameter switches its effect off (zero coefficient, unit
inertia ratio, nominal axis), so a fixed-out effect is exactly absent, and CasADi's constant
folding removes its terms from the per-interval derivatives: a hypothesis with one or two free
effects evaluates its Hessian in a tenth of the instructions of one with every parameter
symbolic (and a fixed axis costs nothing).  One problem is built per distinct set of free
parameters, on first use, and reused by every later solve of that set (a few milliseconds to
build; a set recurs across rounds and starts).

The fit uses no energy term (``energy="off"``): the collocation defects already impose the
dynamics, and the windowed energy penalty couples every sample of a window in the Hessian.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..nlp.joint_space import build_joint_space_fit, collocation_grid, grid_locks
from .effects import EFFECTS

# CPU budget of one hypothesis solve: this many derivative evaluations (timed at build), at least
# 1 s — the floor decides on the search grid, whose evaluations take 0.4-5 ms.  A fit that spends
# more is usually in a restoration phase or ill-conditioned (a Stribeck speed near zero), but
# converging fits can come close: 150-166 iterations in 0.95-1.06 s on 2026-11-29's machine
# (a drawer's damping), so where the search's path passes such a fit, its findings depend on
# the machine's speed (diagnose's ``cpu_cap_s``).
CPU_CAP_EVALUATIONS = 100
# IPOPT's return status of a solve stopped by that budget.
CPU_CAP_STATUS = "Maximum_CpuTime_Exceeded"


def effect_parameters(model: ArticulatedModel, joint: str, effect: str) -> list[str]:
    """The parameter names freed to test ``effect`` on ``joint`` (first = reported value)."""
    if effect == "inertia_error":
        return [f"{model.joint(joint).child}.inertia_ratio"]
    return [f"{joint}.{p}" for p in EFFECTS[effect].params]


@dataclass(frozen=True)
class Trial:
    """One solved hypothesis.  free: its free parameter names.  values: physical value of every
    parameter block of the shared fit (fixed ones at nominal).  q_fit: (T, n) fitted positions
    at the samples.  X: (2n, G) collocation states, z: scaled parameters (warm start)."""

    free: tuple[str, ...]
    values: dict[str, np.ndarray]
    q_fit: np.ndarray
    X: np.ndarray
    z: dict[str, np.ndarray]
    success: bool
    status: str
    iterations: int
    solve_time_s: float
    bounds: dict = None  # physical (lower, upper) overrides the solve used


def _sparsity(nrow: int, ncol: int, rows: np.ndarray, cols: np.ndarray) -> "ca.Sparsity":
    """The CasADi pattern of distinct entries (rows, cols) already in column-major order."""
    import casadi as ca

    return ca.Sparsity(nrow, ncol, np.searchsorted(cols, np.arange(ncol + 1)).tolist(), rows.tolist())


class _StructuredNLP:
    """The collocation fit of a :class:`~kinemaforge_opt.nlp.joint_space.JointSpaceFit` as an
    IPOPT problem whose constraint Jacobian and Lagrangian Hessian are assembled from per-interval
    derivatives (symbolic, small) evaluated by ``map`` and scattered into the sparse global
    matrices, instead of differentiating the whole mapped graph: the build cost no longer grows
    with the number of samples, and each evaluation is one vectorised call.

    Decision vector w = (vec(X), z): X (2n, G) collocation states column-major, z the scaled
    parameters of the blocks named in ``free`` in ``fit.blocks`` order; every other block is a
    constant at its nominal value.  Constraints: the kept Hermite–Simpson defects (interval
    order), then |axis|² - 1 per free-axis block.  Objective: the noise-normalised squared output
    error at the samples, averaged over samples (as ``output_q``)."""

    def __init__(self, fit, free: tuple[str, ...], max_iter: int, tol: float = 1e-6, print_level: int = 0,
                 max_cpu_s: float | None = None):
        import casadi as ca

        rec = fit.recording
        n = fit.model.nq
        nx = 2 * n
        m = fit.substeps
        t_grid = collocation_grid(rec.t, m)
        G = t_grid.size
        T = rec.t.size
        self.n, self.nx, self.G, self.m = n, nx, G, m
        free_blocks = [b for b in fit.blocks if b.name in free]
        self.blocks = tuple(free_blocks)
        offs, o = {}, 0
        for b in free_blocks:
            offs[b.name] = o
            o += b.size
        nz = o
        self.z_offsets = offs
        self.nz = nz
        nw = nx * G + nz

        # theta and phi as (linear) functions of z; a fixed block is its nominal value (a
        # constant, folded away where it switches an effect off)
        zs = ca.SX.sym("z", nz)
        byname = {b.name: b for b in fit.blocks}

        def physical(name: str):
            b = byname[name]
            return zs[offs[name]: offs[name] + b.size] * b.scale if name in offs else ca.SX(ca.DM(b.nominal))

        theta_parts = []
        for name in fit.theta_names:
            if name in byname:
                theta_parts.append(physical(name))
            else:  # tied to an inertia ratio
                theta_parts.append(physical(name + "_ratio")[0] * fit.dynamics.parameter(name).nominal)
        theta = ca.vertcat(*theta_parts) if theta_parts else ca.SX(0, 1)
        phi_parts = []
        for i in range(len(fit.phi_layout)):
            if i in fit.phi_free:
                name, k = fit.phi_free[i]
                phi_parts.append(physical(name)[k])
            else:
                phi_parts.append(ca.SX(fit.phi_fixed[i]))
        phi = ca.vertcat(*phi_parts) if phi_parts else ca.SX(0, 1)

        xk, xk1 = ca.SX.sym("xk", nx), ca.SX.sym("xk1", nx)
        uk, uk1, h, lk = ca.SX.sym("uk", n), ca.SX.sym("uk1", n), ca.SX.sym("h"), ca.SX.sym("lock", n)
        lam = ca.SX.sym("lam", nx)
        d = fit.defect(xk, xk1, uk, uk1, h, theta, phi, lk)[0]
        wk = ca.vertcat(xk, xk1, zs)
        nb = 2 * nx + nz
        J = ca.densify(ca.jacobian(d, wk))
        H = ca.densify(ca.hessian(ca.dot(lam, d), wk)[0])
        f_d = ca.Function("d", [xk, xk1, uk, uk1, h, zs, lk], [d])
        f_j = ca.Function("j", [xk, xk1, uk, uk1, h, zs, lk], [J])
        f_h = ca.Function("h", [xk, xk1, uk, uk1, h, zs, lk, lam], [H])
        self.sizes = (f_d.n_instructions(), f_j.n_instructions(), f_h.n_instructions())

        U = np.array([np.interp(t_grid, rec.t, c) for c in rec.tau.T]) if rec.tau is not None else np.zeros((n, G))
        Hs = np.diff(t_grid)
        cut = set(range(G - 1)) - set(range(G - 1))
        if len(fit.segment_starts) > 1:
            cut = {c - 1 for c in fit.segment_starts[1:]}
        kept = np.array([k for k in range(G - 1) if k not in cut], dtype=int)
        K = kept.size

        w = ca.MX.sym("w", nw)
        X = ca.reshape(w[: nx * G], nx, G)
        z = w[nx * G:]
        Xa, Xb = X[:, kept.tolist()], X[:, (kept + 1).tolist()]
        Ua, Ub, Hh, Lock = U[:, kept], U[:, kept + 1], Hs[kept][None, :], grid_locks(rec, m)[:, kept]
        D = f_d.map(K)(Xa, Xb, Ua, Ub, Hh, z, Lock)
        axis_blocks = [b for b in free_blocks if b.name.endswith(".axis")]
        g_parts = [ca.vec(D)]
        for b in axis_blocks:
            za = z[offs[b.name]: offs[b.name] + 3]
            g_parts.append(ca.sumsqr(za) - 1.0)
        g = ca.vertcat(*g_parts)
        ng = nx * K + len(axis_blocks)
        self.ng = ng
        self.axis_rows = {b.name: nx * K + i for i, b in enumerate(axis_blocks)}

        sigma = fit.sigma_q
        sample_cols = np.arange(0, G, m)
        Qs = X[:n, sample_cols.tolist()]
        f = ca.sumsqr((Qs - rec.q.T) / sigma[:, None]) / T

        # --- Jacobian of g: per kept interval a dense (nx, nb) block ---------------------------
        # global columns of w_k = (x_k, x_k+1, z) per kept interval: (K, nb)
        wcols = np.concatenate([nx * kept[:, None] + np.arange(2 * nx)[None, :],
                                np.broadcast_to(nx * G + np.arange(nz), (K, nz))], axis=1).astype(int)
        # entry (r, c) of block i, column-major (r fastest): row nx i + r, column wcols[i, c]
        jr = np.broadcast_to(nx * np.arange(K)[:, None, None] + np.arange(nx)[None, None, :], (K, nb, nx)).ravel()
        jc = np.broadcast_to(wcols[:, :, None], (K, nb, nx)).ravel()
        Jall = ca.vec(f_j.map(K)(Xa, Xb, Ua, Ub, Hh, z, Lock))  # (nx*nb*K,) column-major per block
        extra_r, extra_c, extra_v = [], [], []
        for b in axis_blocks:
            r = self.axis_rows[b.name]
            for i in range(3):
                extra_r.append(r)
                extra_c.append(nx * G + offs[b.name] + i)
                extra_v.append(2 * z[offs[b.name] + i])
        jr = np.concatenate([jr, np.array(extra_r, int)])
        jc = np.concatenate([jc, np.array(extra_c, int)])
        jv = ca.vertcat(Jall, *extra_v) if extra_v else Jall
        order = np.lexsort((jr, jc))
        sp_j = _sparsity(ng, nw, jr[order], jc[order])
        jac = ca.MX(sp_j, jv[order.tolist()])

        # --- Hessian of the Lagrangian, upper triangle, duplicates summed ----------------------
        lam_f = ca.MX.sym("lam_f")
        lam_g = ca.MX.sym("lam_g", ng)
        Lk = ca.reshape(lam_g[: nx * K], nx, K)
        Hall = ca.vec(f_h.map(K)(Xa, Xb, Ua, Ub, Hh, z, Lock, Lk))  # (nb*nb*K,)
        # entry (a, b) of block k, column-major (a fastest): row wcols[k, a], column wcols[k, b]
        hr = np.broadcast_to(wcols[:, None, :], (K, nb, nb)).ravel()
        hc = np.broadcast_to(wcols[:, :, None], (K, nb, nb)).ravel()
        vals = [Hall]
        # objective: 2/(sigma^2 T) on the sampled q entries
        obj_idx = (nx * sample_cols[:, None] + np.arange(n)[None, :]).ravel()
        obj_w = np.tile(2.0 / (sigma**2 * T), sample_cols.size)
        hr = np.concatenate([hr, obj_idx])
        hc = np.concatenate([hc, obj_idx])
        vals.append(lam_f * ca.DM(obj_w))
        for b in axis_blocks:
            idx = nx * G + offs[b.name] + np.arange(3)
            hr = np.concatenate([hr, idx])
            hc = np.concatenate([hc, idx])
            vals.append(2 * lam_g[self.axis_rows[b.name]] * ca.DM.ones(3))
        hv = ca.vertcat(*vals)
        upper = hr <= hc
        hr, hc = hr[upper], hc[upper]
        src = np.flatnonzero(upper)
        key = hc.astype(np.int64) * nw + hr
        uniq, inv = np.unique(key, return_inverse=True)
        import scipy.sparse as sps

        S = sps.csc_matrix((np.ones(src.size), (inv, src)), shape=(uniq.size, hv.numel()))
        S_dm = ca.DM(ca.Sparsity(S.shape[0], S.shape[1], S.indptr.tolist(), S.indices.tolist()), S.data)
        sp_h = _sparsity(nw, nw, uniq % nw, uniq // nw)
        hess = ca.MX(sp_h, ca.mtimes(S_dm, hv))

        p = ca.MX.sym("p", 0)
        jac_fn = ca.Function("nlp_jac_g", [w, p], [g, jac], ["x", "p"], ["g", "jac_g_x"])
        hess_fn = ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [hess], ["x", "p", "lam_f", "lam_g"],
                              ["triu_hess_gamma_x_x"])
        # Bound the CPU time of a solve by min(max_iter, CPU_CAP_EVALUATIONS) iterations of typical cost (one Hessian and
        # one Jacobian evaluation, timed here, the bulk of an iteration): a hypothesis that
        # sends IPOPT into a long restoration phase is abandoned (not converged) instead of
        # costing minutes.
        if max_cpu_s is None:
            import time as _time

            w_probe = np.zeros(nw)
            t0 = _time.process_time()
            hess_fn(w_probe, [], 1.0, np.zeros(ng))
            jac_fn(w_probe, [])
            t_eval = _time.process_time() - t0
            max_cpu_s = max(1.0, min(max_iter, CPU_CAP_EVALUATIONS) * t_eval)
        self.max_cpu_s = float(max_cpu_s)
        opts = {"ipopt.max_iter": max_iter, "ipopt.tol": tol, "ipopt.print_level": print_level, "print_time": False,
                "ipopt.sb": "yes", "jac_g": jac_fn, "hess_lag": hess_fn}
        if np.isfinite(self.max_cpu_s):
            opts["ipopt.max_cpu_time"] = self.max_cpu_s
        self.solver = ca.nlpsol("hypotheses", "ipopt", {"x": w, "f": f, "g": g}, opts)
        self.fit = fit


class HypothesisFit:
    """The shared fit of ``recording`` for the (joint, effect) pairs in ``hypotheses``.

    Build once (``__init__``), then :meth:`solve` any subset of their parameters (the IPOPT
    problem of a subset is built on its first solve: :meth:`nlp_for`).
    limit_stops: per joint (side, initial stop) for ``limit_contact``, sigma_q (n,) the encoder
    noise and friction_eps (n,) the smooth-sign width [rad/s or m/s] (defaults: from the
    recording; see :func:`kinemaforge_opt.nlp.joint_space.build_joint_space_fit`).  max_cpu_s: IPOPT
    CPU-time cap of a solve [s] (default: per subset, ``CPU_CAP_EVALUATIONS`` evaluations of its
    derivatives, timed at its build, at least 1 s; ``math.inf``: none, max_iter alone bounds it).
    """

    def __init__(self, model: ArticulatedModel, recording: Recording, hypotheses: list[tuple[str, str]],
                 segment_s: float | None = None, limit_stops: dict | None = None, max_iter: int = 100,
                 sigma_q: np.ndarray | None = None, friction_eps: np.ndarray | None = None,
                 max_cpu_s: float | None = None):
        names: list[str] = []
        for joint, effect in hypotheses:
            for n in effect_parameters(model, joint, effect):
                if n not in names:
                    names.append(n)
        self.model = model
        self.names = tuple(names)
        self.fit = build_joint_space_fit(model, recording, self.names, energy="off", segment_s=segment_s,
                                         limit_stops=limit_stops, sigma_q=sigma_q, friction_eps=friction_eps)
        self.blocks = {b.name: b for b in self.fit.blocks}
        self.max_iter, self.max_cpu_s = max_iter, max_cpu_s
        self._nlps: dict[tuple[str, ...], _StructuredNLP] = {}
        self.recording = self.fit.recording
        rec = self.recording
        n = model.nq
        v0 = np.gradient(rec.q, rec.t, axis=0) if rec.v is None else rec.v
        t_grid = collocation_grid(rec.t, self.fit.substeps)
        self.x_init = np.vstack([np.array([np.interp(t_grid, rec.t, c) for c in rec.q.T]),
                                 np.array([np.interp(t_grid, rec.t, c) for c in v0.T])])
        self.t_grid = t_grid

    def states_from(self, t_src: np.ndarray, X_src: np.ndarray) -> np.ndarray:
        """(2n, G) states on this fit's grid from states ``X_src`` (2n, S) at times ``t_src`` (S,)
        [s] of another fit of the same motion (e.g. on a coarser grid): q by cubic Hermite
        interpolation with v as its derivative (the collocation polynomial), v linearly;
        extrapolated at the ends."""
        from scipy.interpolate import CubicHermiteSpline

        n = self.model.nq
        q = CubicHermiteSpline(t_src, X_src[:n].T, X_src[n:].T, axis=0, extrapolate=True)(self.t_grid).T
        v = np.array([np.interp(self.t_grid, t_src, c) for c in X_src[n:]])
        return np.vstack([q, v])

    def nlp_for(self, free: list[str] | tuple[str, ...]) -> _StructuredNLP:
        """The IPOPT problem with the blocks ``free`` as variables (every other block fixed at its
        nominal value), built on first use."""
        key = tuple(n for n in self.blocks if n in free)
        if key not in self._nlps:
            # the nominal fit (states only) is what every hypothesis is measured against: never capped
            cap = self.max_cpu_s if key else math.inf
            self._nlps[key] = _StructuredNLP(self.fit, key, self.max_iter, max_cpu_s=cap)
        return self._nlps[key]

    def nominal_z(self, name: str) -> np.ndarray:
        b = self.blocks[name]
        return b.nominal / b.scale

    def solve(self, free: list[str] | tuple[str, ...], start: Trial | None = None,
              init: dict[str, np.ndarray] | None = None, states_from_data: bool = False,
              bounds: dict[str, tuple[float, float]] | None = None, x0: np.ndarray | None = None) -> Trial:
        """Fit the hypothesis whose free parameters are ``free`` (the others fixed at nominal),
        starting from ``start`` (its states and shared parameters) and physical ``init`` values.
        states_from_data: start the states from the recording instead of ``start``'s trajectory
        (for effects that act only where the recording went but the parent's fit did not).
        bounds: physical (lower, upper) replacing a free block's bounds.  x0: (2n, G) starting
        states on this fit's collocation grid (e.g. a coarser fit's trajectory interpolated);
        overrides ``start`` and ``states_from_data``."""
        free = tuple(free)
        unknown = [n for n in free if n not in self.blocks]
        if unknown:
            raise KeyError(f"parameters {unknown} are not in the shared fit; it holds {list(self.blocks)}")
        import time

        nlp = self.nlp_for(free)
        nxG = nlp.nx * nlp.G
        X0 = start.X if start is not None and not states_from_data else self.x_init
        if x0 is not None:
            X0 = np.asarray(x0, float).reshape(nlp.nx, nlp.G)
        w0 = np.concatenate([X0.ravel(order="F"), np.zeros(nlp.nz)])
        lbw = np.concatenate([np.full(nxG, -np.inf), np.zeros(nlp.nz)])
        ubw = np.concatenate([np.full(nxG, np.inf), np.zeros(nlp.nz)])
        lbg, ubg = np.zeros(nlp.ng), np.zeros(nlp.ng)
        for b in nlp.blocks:
            name = b.name
            sl = slice(nxG + nlp.z_offsets[name], nxG + nlp.z_offsets[name] + b.size)
            z0 = start.z[name] if start is not None and name in start.free else self.nominal_z(name)
            if init and name in init:
                z0 = np.asarray(init[name], float) / b.scale
            w0[sl] = z0
            lo, hi = (bounds or {}).get(name, (b.lower, b.upper))
            lbw[sl], ubw[sl] = np.asarray(lo, float) / b.scale, np.asarray(hi, float) / b.scale
            w0[sl] = np.clip(w0[sl], lbw[sl], ubw[sl])
        t0 = time.perf_counter()
        sol = nlp.solver(x0=w0, lbx=lbw, ubx=ubw, lbg=lbg, ubg=ubg)
        elapsed = time.perf_counter() - t0
        stats = nlp.solver.stats()
        wopt = sol["x"].full().ravel()
        X = wopt[:nxG].reshape(nlp.nx, nlp.G, order="F")
        n = self.model.nq
        m = self.fit.substeps
        values, z = {}, {}
        for name, b in self.blocks.items():
            zb = wopt[nxG + nlp.z_offsets[name]: nxG + nlp.z_offsets[name] + b.size] if name in nlp.z_offsets \
                else self.nominal_z(name)
            z[name] = zb
            v = np.clip(zb * b.scale, b.lower, b.upper)
            if name.endswith(".axis"):
                v = v / np.linalg.norm(v)
            values[name] = v
        return Trial(free, values, X[:n, ::m].T.copy(), X, z, bool(stats.get("success", False)),
                     str(stats.get("return_status", "")), int(stats.get("iter_count", -1)), elapsed, dict(bounds or {}))
