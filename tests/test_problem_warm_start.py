"""A stopped IPOPT solve continued with its multipliers and barrier parameter (Problem.solve's
``warm``) starts where it stopped; restarted cold, IPOPT pushes the variables that sit on their
bounds back into the interior first (protocol_drawer_1@s1's dense stage: cold, a second 200
iterations without converging; warm, 46)."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from kinemaforge_opt.nlp.problem import Problem

N = 40
ADAPTIVE = {"ipopt.mu_strategy": "adaptive"}  # as the screw NLP's dense stages


def _chain(init: np.ndarray) -> Problem:
    """An extended Rosenbrock chain pulled below zero, x ≥ 0 on every other variable (those
    bounds are active at the optimum), from ``init``."""
    p = Problem("rosenbrock_chain")
    x = p.variable("x", N, lower=np.where(np.arange(N) % 2 == 0, 0.0, -np.inf), init=init)
    p.add_cost("rosenbrock", ca.sum1(100 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2))
    p.add_cost("pull", 10 * ca.sumsqr(x + 1))
    return p


def test_a_warm_continuation_starts_at_the_stopped_iterate_and_reaches_the_optimum():
    start = np.full(N, 2.0)
    full = _chain(start).solve(options=ADAPTIVE)
    assert full.success
    stopped = _chain(start).solve(max_iter=3 * full.iterations // 4, options=ADAPTIVE)
    assert not stopped.success and stopped.lam_x.shape == (N,) and 0 < stopped.final_mu < 1e-2
    warm = _chain(stopped.values["x"]).solve(options=ADAPTIVE, warm=stopped)
    cold = _chain(stopped.values["x"]).solve(options=ADAPTIVE)
    assert warm.success
    np.testing.assert_allclose(warm.values["x"], full.values["x"], atol=1e-6)
    first = lambda r: r.stats["iterations"]["obj"][0]  # noqa: E731 — the objective IPOPT starts from
    assert first(warm) == pytest.approx(stopped.objective, rel=1e-6)
    assert abs(first(cold) - stopped.objective) > 1e-3 * stopped.objective, "a cold start leaves the bounds"


def test_without_multipliers_there_is_no_warm_start():
    p = _chain(np.full(N, 2.0))
    stopped = p.solve(max_iter=3, options=ADAPTIVE)
    blank = dataclasses.replace(stopped, lam_x=None, lam_g=None)
    again = _chain(stopped.values["x"]).solve(options=ADAPTIVE, warm=blank)
    cold = _chain(stopped.values["x"]).solve(options=ADAPTIVE)
    assert again.iterations == cold.iterations and again.objective == cold.objective
