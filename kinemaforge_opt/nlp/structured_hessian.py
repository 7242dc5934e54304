"""The Hessian of the screw NLP's Lagrangian assembled from per-block derivatives.

Differentiating the whole mapped graph twice (casadi's default exact Hessian of the expanded
problem) costs seconds of build on a two-door cabinet, and the squared energy windows make it
worse: each window couples all its intervals.  Every term of the dense screw NLP is a sum over
small blocks, so its Hessian is assembled here from small symbolic derivatives evaluated by
``map`` and scattered into the sparse global matrix (as :mod:`kinemaforge_opt.physics.search`
does for its fits) — build cost independent of the number of steps:

- ``vis`` per part and observed step: f(q_t, z) → Hessian over (q_t, z);
- ``dyn`` per interval: d_k(x_k, x_k+1, z) and the work W_k of the applied and passive forces
  → Hessian of λ_f d_k + μ_k W_k over (x_k, x_k+1, z);
- energy per window i: rel_i = (E(x_b) − E(x_a) − Σ_k W_k) / e_scale.  Soft: the cost
  c Σ rel_i² has the Hessian 2c (∇rel_i ∇rel_iᵀ + rel_i ∇²rel_i): the outer products from the
  per-interval and per-edge gradients (a sparse (windows, variables) matrix Jᵀ J), the second
  part through μ_k and the per-edge weights ν_e.  Hard: the constraint's multipliers enter
  through μ_k and ν_e only;
- ``unit_axis`` constraints: 2λ I on the axis; ``gauge`` is linear.

z is the vector of every parameter variable of the problem (axes, origins, pitches, inertia
ratios, damping, Coulomb); θ and φ of the bridge are linear functions of it.  The exact
Hessian is what this computes (checked against casadi's in the tests), not an approximation.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sps

from ..parallel import workers


@dataclass(frozen=True, eq=False)
class DenseTerms:
    """What :func:`lagrangian_hessian` needs from the dense screw problem.

    problem: the :class:`~.problem.Problem` (its declaration order fixes the decision vector).
    n: joints.  G: grid points.  theta_phi: Function (parameter variables in declaration order,
    one input each) -> (θ, φ), linear.  point, interval, energy: the per-grid-point right-hand
    side, per-interval Hermite–Simpson and energy Functions of the builder.
    wrench_grid: (P, F, S) at the grid points; wrench_mid: the same at interval midpoints.
    h: (G − 1,) step lengths [s].  vis: list of (Function (q, θ, H) -> cost, frame columns (T,),
    H blocks (13, 13 T)).  cost_weight: the objective's weight on every cost (1 / n_vis).
    energy: "soft", "hard" or "off".  edges: window edge columns.  e_scale: energy scale [J].
    energy_coef: the soft weight (energy_weight / energy_sigma²).  axis_vars: names of the unit
    axis variables with their constraint names.  dyn_mask: (G − 1,) 0/1 weight of each interval's
    defect cost (None = all 1).  energy_mask: (windows,) 0/1 weight of each soft window residual.
    prior: Function of the parameter variables (as theta_phi) -> a cost added with cost_weight.
    hold: (indices into vec(q) (n, G), weights) of a cost ½ Σ w (q − target)² added with
    cost_weight (``unseen_hold``), or None.
    """

    problem: object
    n: int
    G: int
    theta_phi: ca.Function
    point: ca.Function
    interval: ca.Function
    energy_fn: ca.Function | None
    wrench_grid: tuple
    wrench_mid: tuple
    h: np.ndarray
    vis: list
    cost_weight: float
    energy: str
    edges: list
    e_scale: float
    energy_coef: float
    axis_vars: list
    gauss_newton: bool = False
    dyn_mask: np.ndarray | None = None
    energy_mask: np.ndarray | None = None
    prior: ca.Function | None = None
    hold: tuple[np.ndarray, np.ndarray] | None = None


def _scatter(nr: int, nc: int, rows: np.ndarray, cols: np.ndarray, vals: ca.MX) -> ca.MX:
    """Sparse (nr, nc) MX with entries vals[i] at (rows[i], cols[i]), duplicates summed."""
    key = cols.astype(np.int64) * nr + rows
    uniq, inv = np.unique(key, return_inverse=True)  # sorted column-major = CCS order
    S = sps.csc_matrix((np.ones(key.size), (inv, np.arange(key.size))), shape=(uniq.size, key.size))
    S_dm = ca.DM(ca.Sparsity(S.shape[0], S.shape[1], S.indptr.tolist(), S.indices.tolist()), S.data)
    sp = ca.Sparsity.triplet(nr, nc, (uniq % nr).tolist(), (uniq // nr).tolist())
    return ca.MX(sp, ca.mtimes(S_dm, vals))


def _block_entries(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For K dense (nb, nb) blocks on the global indices idx (K, nb), stored column-major one
    after another: global (rows, cols) of the upper-triangle entries and their positions."""
    K, nb = idx.shape
    r = np.tile(np.arange(nb), nb)  # column-major inside a block
    c = np.repeat(np.arange(nb), nb)
    rows = idx[:, r].ravel()
    cols = idx[:, c].ravel()
    pos = np.arange(K * nb * nb)
    keep = rows <= cols
    return rows[keep], cols[keep], pos[keep]


def lagrangian_hessian(t: DenseTerms) -> ca.Function:
    """casadi Function (x, p, lam_f, lam_g) -> upper triangle of ∇²(λ_f f + λ_gᵀ g), for
    nlpsol's ``hess_lag`` option."""
    prob = t.problem
    vs, gs = prob.layout()
    nw, ng = prob.sizes["variables"], prob.sizes["constraints"]
    n, G = t.n, t.G
    nx = 2 * n
    pnames = [name for name in prob.terms["variables"] if name != "x"]
    zidx = np.concatenate([np.arange(vs[p].start, vs[p].stop) for p in pnames]).astype(int)
    nz = zidx.size
    xoff = vs["x"].start

    # --- per-block SX functions ------------------------------------------------------------
    zs = ca.SX.sym("z", nz)
    parts, i = [], 0
    for p in pnames:
        size = vs[p].stop - vs[p].start
        parts.append(zs[i:i + size])
        i += size
    theta_phi = t.theta_phi.expand()
    theta, phi = theta_phi(*parts)

    xk, xk1 = ca.SX.sym("xk", nx), ca.SX.sym("xk1", nx)
    nsel = t.wrench_grid[2].shape[0]
    pk, fk, sk = ca.SX.sym("pk", 3), ca.SX.sym("fk", 3), ca.SX.sym("sk", nsel)
    pk1, fk1, sk1 = ca.SX.sym("pk1", 3), ca.SX.sym("fk1", 3), ca.SX.sym("sk1", nsel)
    pm, fm, sm = ca.SX.sym("pm", 3), ca.SX.sym("fm", 3), ca.SX.sym("sm", nsel)
    h, lf, mu = ca.SX.sym("h"), ca.SX.sym("lf"), ca.SX.sym("mu")
    r0, w0 = t.point(xk, pk, fk, sk, theta, phi)
    r1, w1 = t.point(xk1, pk1, fk1, sk1, theta, phi)
    d, W, dn = t.interval(xk, xk1, r0, r1, w0, w1, pm, fm, sm, h, theta, phi)
    wk = ca.vertcat(xk, xk1, zs)
    gW = ca.densify(ca.jacobian(W, wk))
    if t.gauss_newton:
        # ρ(r) = √(1 + r²) − 1 per normalised defect: Jᵀ diag(ρ''(r)) J, and no curvature of W
        Jd = ca.densify(ca.jacobian(dn, wk))
        Hk = lf * ca.mtimes(Jd.T, Jd * ca.repmat((1 + dn**2) ** -1.5, 1, Jd.shape[1]))
    else:
        Hk = ca.densify(ca.hessian(lf * d + mu * W, wk)[0])
    wrench_args = [pk, fk, sk, pk1, fk1, sk1, pm, fm, sm, h]
    f_int = ca.Function("dyn_hess", [xk, xk1, zs, *wrench_args, lf, mu], [Hk, gW])
    f_work = ca.Function("work", [xk, xk1, zs, *wrench_args], [W])

    # --- the MX Hessian function ---------------------------------------------------------------
    w = ca.MX.sym("x", nw)
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", ng)
    X = ca.reshape(w[xoff:xoff + nx * G], nx, G)
    z = w[zidx.tolist()]
    lfw = lam_f * t.cost_weight
    P, F, S = t.wrench_grid
    Pm, Fm, Sm = t.wrench_mid
    K = G - 1
    wr = [P[:, :-1], F[:, :-1], S[:, :-1], P[:, 1:], F[:, 1:], S[:, 1:], Pm, Fm, Sm, t.h[None, :]]
    xcol = lambda c: xoff + nx * c + np.arange(nx)  # noqa: E731

    rows, cols, vals = [], [], []

    def add_blocks(idx, hv):
        r, c, pos = _block_entries(idx)
        rows.append(r)
        cols.append(c)
        vals.append(ca.vec(hv)[pos.tolist()])

    # energy multipliers per interval (mu) and per window edge (nu)
    mu_k = ca.MX.zeros(1, K)
    extra = []
    if t.energy != "off":
        edges = t.edges
        nwin = len(edges) - 1
        sx = ca.SX.sym("x", nx)
        nu = ca.SX.sym("nu")
        Esx = t.energy_fn(sx, theta)
        we = ca.vertcat(sx, zs)
        f_e = ca.Function("energy_hess", [sx, zs, nu],
                          [ca.densify(ca.hessian(nu * Esx, we)[0]), ca.densify(ca.jacobian(Esx, we))])
        win_of = np.searchsorted(np.asarray(edges), np.arange(K), side="right") - 1
        if t.energy == "soft":
            Wk = f_work.map(K)(X[:, :-1], X[:, 1:], z, *wr)
            E = ca.Function("energy_edges", [sx, zs], [Esx]).map(len(edges))(X[:, edges], z)
            sums = ca.vertcat(*[ca.sum2(Wk[:, a:b]) for a, b in zip(edges[:-1], edges[1:])])
            rel = (E[1:].T - E[:-1].T - sums) / t.e_scale
            if t.energy_mask is not None:
                rel = rel * ca.DM(np.asarray(t.energy_mask, float))
            coef = lfw * 2 * t.energy_coef * rel / t.e_scale  # (nwin, 1)
        else:
            coef = lam_g[gs["energy"]] / t.e_scale
        mu_k = -coef[win_of.tolist()].T
        nu_e = ca.horzcat(-coef[0], *[coef[e - 1] - coef[e] for e in range(1, nwin)], coef[nwin - 1])
        He, gE = f_e.map(len(edges))(X[:, edges], z, nu_e)
        idx_e = np.array([np.concatenate([xcol(c), zidx]) for c in edges])
        if not t.gauss_newton:
            add_blocks(idx_e, He)
    lf_k = lfw if t.dyn_mask is None else lfw * ca.DM(np.asarray(t.dyn_mask, float)[None, :])
    # the interval blocks are most of the Hessian's cost (the ABA's second derivatives): on threads
    Hd, gW_all = f_int.map(K, "thread", workers())(X[:, :-1], X[:, 1:], z, *wr, lf_k, mu_k)
    idx_d = np.array([np.concatenate([xcol(k), xcol(k + 1), zidx]) for k in range(K)])
    add_blocks(idx_d, Hd)
    if t.energy == "soft":
        # outer products: J (nwin, nw) of the window residuals (times e_scale)
        nb_d, nb_e = idx_d.shape[1], idx_e.shape[1]
        jr = [np.repeat(win_of, nb_d)]
        jc = [idx_d.ravel()]
        jv = [-ca.vec(gW_all)]
        for e in range(len(edges)):
            if e > 0:
                jr.append(np.full(nb_e, e - 1))
                jc.append(idx_e[e])
                jv.append(ca.vec(gE[:, e * nb_e:(e + 1) * nb_e]))
            if e < nwin:
                jr.append(np.full(nb_e, e))
                jc.append(idx_e[e])
                jv.append(-ca.vec(gE[:, e * nb_e:(e + 1) * nb_e]))
        J = _scatter(nwin, nw, np.concatenate(jr), np.concatenate(jc), ca.vertcat(*jv))
        if t.energy_mask is not None:
            J = ca.mtimes(ca.diag(ca.DM(np.asarray(t.energy_mask, float))), J)
        extra.append(ca.triu(lfw * 2 * t.energy_coef / t.e_scale**2 * ca.mtimes(J.T, J)))

    # vis blocks
    for fn, frame_cols, Hs in t.vis:
        qv = ca.SX.sym("q", n)
        Hsym = ca.SX.sym("H", 13, 13)
        fh = ca.Function("vis_hess", [qv, zs, Hsym],
                         [ca.densify(ca.hessian(fn(qv, theta, Hsym), ca.vertcat(qv, zs))[0])])
        Hv = fh.map(len(frame_cols))(X[:n, list(map(int, frame_cols))], z, Hs)
        idx_v = np.array([np.concatenate([xoff + nx * int(c) + np.arange(n), zidx]) for c in frame_cols])
        add_blocks(idx_v, lfw * Hv)

    # parameter prior
    if t.prior is not None:
        fp = ca.Function("prior_hess", [zs], [ca.densify(ca.hessian(t.prior.expand()(*parts), zs)[0])])
        add_blocks(zidx[None, :], lfw * fp(z))

    # the unseen hold: diagonal, on q entries (row k, column c of q is row k of X's column c)
    if t.hold is not None:
        idx, weight = t.hold
        ix = xoff + nx * (idx // n) + idx % n
        rows.append(ix)
        cols.append(ix)
        vals.append(lfw * ca.DM(weight))

    # unit-axis constraints
    for var, con in t.axis_vars:
        ia = np.arange(vs[var].start, vs[var].stop)
        rows.append(ia)
        cols.append(ia)
        vals.append(2 * lam_g[gs[con].start] * ca.DM.ones(3))
    H = _scatter(nw, nw, np.concatenate(rows), np.concatenate(cols), ca.vertcat(*vals))
    for e in extra:
        H = H + e
    p = ca.MX.sym("p", 0)
    return ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [ca.triu(H)], ["x", "p", "lam_f", "lam_g"],
                       ["triu_hess_gamma_x_x"])
