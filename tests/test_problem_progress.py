"""``Problem.solve(on_iteration=...)``: IPOPT reports each iteration (a progress bar's feed)."""

from __future__ import annotations

import pytest

from kinemaforge_opt.nlp.problem import Problem


def test_every_ipopt_iteration_is_reported_with_its_objective():
    """Rosenbrock from (-1.2, 1): the first report is the start's objective, 24.2 by hand; one
    report per iteration after it (IPOPT's own count) and the last one is the optimum's."""
    p = Problem("rosenbrock")
    x = p.variable("x", 2, init=[-1.2, 1.0])
    p.add_cost("rosenbrock", (1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2)
    p.add_constraint("disc", x[0] ** 2 + x[1] ** 2, 0.0, 4.0)
    seen: list[tuple[int, float]] = []
    r = p.solve(on_iteration=lambda k, f: seen.append((k, f)))
    assert r.success
    assert [k for k, _ in seen] == list(range(r.iterations + 1))
    assert seen[0][1] == pytest.approx(24.2)
    assert seen[-1][1] == pytest.approx(r.objective, abs=1e-12)
    assert r.values["x"] == pytest.approx([1.0, 1.0], abs=1e-6)
