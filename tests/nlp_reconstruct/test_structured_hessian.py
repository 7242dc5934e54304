"""The screw NLP's assembled Lagrangian Hessian against casadi's own exact Hessian of the whole
problem graph (automatic differentiation of the flat objective and constraints)."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from kinemaforge_opt.errors import KinemaforgeError
from kinemaforge_opt.nlp.reconstruction import ScrewOptions, build_screw_problem, correspondences, initial_state

from .test_screw_nlp import pushed_door


@pytest.fixture(scope="module")
def data():
    """The pushed door simulated at 60 Hz, frames at 10 Hz."""
    return pushed_door(60, 6)[1]


@pytest.mark.parametrize("energy,impact,unseen", [("soft", None, 0), ("hard", None, 0), ("off", None, 0),
                                                  ("soft", (0.8, np.inf), 0), ("hard", (0.8, np.inf), 0),
                                                  ("soft", (0.3, 0.6), 0), ("soft", None, 3)])
def test_assembled_hessian_equals_the_exact_hessian_of_the_lagrangian(data, energy, impact, unseen, monkeypatch):
    """With ``impact`` (start, end) [s], a stop span is declared there: its intervals and the
    energy windows that touch it leave the objective (masked in both Hessians), the states only
    it touches are held.  With ``unseen`` frames, the door is not seen at the first ones: the
    dynamics start after them and the ``unseen_hold`` cost holds its q there.  The inertia
    prior is on in every case."""
    import kinemaforge_opt.nlp.reconstruction as reco

    if unseen:
        data = dataclasses.replace(data, observed={link: [None] * unseen + obs[unseen:] for link, obs in data.observed.items()},
                                   sightlines=None if data.sightlines is None else
                                   {link: [None] * unseen + s[unseen:] for link, s in data.sightlines.items()})
    if impact:
        def span(times, q):
            return [(int(np.searchsorted(times, impact[0])), int(min(np.searchsorted(times, impact[1]), times.size - 1)))]
        monkeypatch.setattr(reco, "stop_spans", span)
    opts = ScrewOptions(energy=energy, energy_window_s=0.5)  # 3 windows of 5 intervals
    state = initial_state(data)
    sp = build_screw_problem(data, opts, state, correspondences(data, state, 50), dense=True)
    assert "inertia_prior" in sp.problem.terms["costs"]
    assert ("unseen_hold" in sp.problem.terms["costs"]) == bool(unseen)
    prob = sp.problem
    names = prob.terms["variables"]
    x = ca.vertcat(*[ca.vec(prob._vars[n].symbol) for n in names])
    f = sum(prob._costs.values(), ca.MX(0))
    g = ca.vertcat(*[c[0] for c in prob._constraints.values()])
    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", g.numel())
    reference = ca.Function("H", [x, lam_f, lam_g], [ca.hessian(lam_f * f + ca.dot(lam_g, g), x)[0]])
    rng = np.random.default_rng(2)
    for _ in range(2):  # away from the initial guess, random multipliers
        x0 = np.concatenate([prob._vars[n].init for n in names]) + rng.normal(0, 0.05, x.numel())
        lg = rng.normal(0, 1, g.numel())
        A = reference(x0, 0.7, lg).full()
        B = sp.hess_lag(x0, [], 0.7, lg).full()
        assert not np.tril(B, -1).any()
        full = np.triu(B) + np.triu(B, 1).T
        assert np.abs(A).max() > 1.0
        np.testing.assert_allclose(full, A, atol=1e-9 * np.abs(A).max())


def test_hessian_option_is_checked_with_a_message():
    with pytest.raises(KinemaforgeError, match="hessian must be one of .*'exact'.*got 'newton'"):
        ScrewOptions(hessian="newton")
