"""Problem parameters and the SolverCache: a problem rebuilt around new data solves with the
solver built for the first build, and gets the answer a solver built for it would give."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from kinemaforge_opt.errors import KinemaforgeError
from kinemaforge_opt.nlp.problem import Problem, SolverCache


def _line_fit(t: np.ndarray, y: np.ndarray, slope_bounds=(-np.inf, np.inf)) -> Problem:
    """Least squares y ≈ a·t + b with the samples (t, y) as parameters and a weight 1/N."""
    p = Problem("line_fit")
    a = p.variable("slope", 1, *slope_bounds)
    b = p.variable("intercept", 1)
    ts, ys = p.parameter("t", t), p.parameter("y", y)
    p.add_cost("residual", ca.sumsqr(a * ts + b - ys), weight=p.parameter("scale", 1.0 / t.size))
    return p


def _analytic(t, y):
    return np.polyfit(t, y, 1)


def test_a_rebuilt_problem_solves_with_the_first_solver_and_gets_its_own_answer():
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 1.0, 20)
    cache = SolverCache()
    for slope in (2.0, -1.0, 0.5):
        y = slope * t + 0.3 + rng.normal(0, 0.01, t.size)
        res = cache.solve(_line_fit(t, y), key=("line_fit",))
        a, b = _analytic(t, y)
        assert res.success
        np.testing.assert_allclose([res.values["slope"][0], res.values["intercept"][0]], [a, b], atol=1e-8)
        # the reported cost is read at this build's parameters
        assert res.costs["residual"] == pytest.approx(np.mean((a * t + b - y) ** 2), rel=1e-6)
    assert len(cache) == 1


def test_bounds_are_the_rebuilt_problems_own():
    t = np.linspace(0.0, 1.0, 10)
    cache = SolverCache()
    cache.solve(_line_fit(t, 2.0 * t), key=("line_fit",))
    res = cache.solve(_line_fit(t, 2.0 * t, slope_bounds=(-np.inf, 1.0)), key=("line_fit",))
    assert res.values["slope"][0] == pytest.approx(1.0, abs=1e-7) and len(cache) == 1


def test_another_structure_key_or_option_gets_its_own_solver():
    t = np.linspace(0.0, 1.0, 10)
    cache = SolverCache()
    cache.solve(_line_fit(t, t), key=("line_fit",))
    cache.solve(_line_fit(t[:5], t[:5]), key=("line_fit",))  # other parameter shapes
    cache.solve(_line_fit(t, t), key=("other constants",))
    cache.solve(_line_fit(t, t), key=("line_fit",), options={"ipopt.mu_strategy": "adaptive"})
    assert len(cache) == 4


def test_a_compiled_problem_refuses_a_problem_of_another_structure():
    t = np.linspace(0.0, 1.0, 10)
    compiled = _line_fit(t, t).compile()
    with pytest.raises(KinemaforgeError, match="'line_fit': its structure differs"):
        compiled.solve(source=_line_fit(t[:5], t[:5]))


def test_an_option_that_is_not_a_plain_value_cannot_key_a_solver():
    t = np.linspace(0.0, 1.0, 10)
    x = ca.MX.sym("x")
    with pytest.raises(KinemaforgeError, match="solver option 'hess_lag' holds a Function"):
        SolverCache().solve(_line_fit(t, t), key=(), options={"hess_lag": ca.Function("h", [x], [x])})


def test_parameters_are_declared_once_and_reported():
    p = _line_fit(np.arange(3.0), np.arange(3.0))
    with pytest.raises(KinemaforgeError, match="'t' declared twice"):
        p.parameter("t", [1.0])
    assert list(p.parameters) == ["t", "y", "scale"]
    np.testing.assert_array_equal(p.parameters["y"], [0.0, 1.0, 2.0])


def test_an_iteration_hook_sees_a_problem_with_parameters():
    t = np.linspace(0.0, 1.0, 10)
    seen = []
    res = _line_fit(t, 3.0 * t).solve(on_iteration=lambda k, f: seen.append(f))
    assert res.success and seen and seen[-1] == pytest.approx(0.0, abs=1e-12)
