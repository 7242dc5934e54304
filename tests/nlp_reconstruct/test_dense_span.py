"""What the dense screw problem covers and what a continuation resumes: the dynamics only where
every part is seen, and a stopped solve resumed on the same scales (the door of
:func:`.test_screw_nlp.pushed_door`, simulated with Pinocchio's ABA at 120 Hz)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kinemaforge_opt.nlp import reconstruction as reco
from kinemaforge_opt.nlp.reconstruction import (
    ScrewOptions,
    build_screw_problem,
    correspondences,
    initial_state,
    read_solution,
    refine_screws,
    seen_free,
)

from .test_screw_nlp import FINE, _errors, pushed_door


@pytest.fixture(scope="module")
def pushed():
    return pushed_door(120, 12)


def _unseen_first(data, steps: int):
    """``data`` with no part seen at its first ``steps`` frames."""
    hide = lambda seq: [None] * steps + list(seq[steps:])  # noqa: E731
    return dataclasses.replace(
        data, observed={link: hide(obs) for link, obs in data.observed.items()},
        sightlines=None if data.sightlines is None else {link: hide(s) for link, s in data.sightlines.items()})


def test_the_dynamics_cover_only_the_steps_where_every_part_is_seen(pushed):
    """The door is pushed from t = 0 and first seen at the fourth frame (0.3 s): the intervals
    before it leave the dynamics and energy terms, their states are held, and the fit still finds
    the simulated door's hinge and damping from what it saw."""
    true, data, _ = pushed
    late = _unseen_first(data, 3)
    grid = np.linspace(data.times[0], data.times[-1], 46)
    mid = (grid[:-1] + grid[1:]) / 2
    np.testing.assert_array_equal(seen_free(late, grid), (mid > data.times[3]).astype(float))
    np.testing.assert_array_equal(seen_free(data, grid), np.ones(mid.size))

    sp = build_screw_problem(late, ScrewOptions(substep_s=FINE), initial_state(late),
                             correspondences(late, initial_state(late), 50), dense=True)
    x = sp.problem._vars["x"]
    lower, upper = (np.reshape(b, (2, -1), order="F") for b in (x.lower, x.upper))  # (q, v) × grid
    before = sp.state.t < data.times[3] - 1e-9
    assert np.all(lower[:, before] == upper[:, before])  # held: no term sees them
    assert np.all(lower[:, ~before] < upper[:, ~before])

    r = refine_screws(late, ScrewOptions(energy="soft", substep_s=FINE))
    assert r.success
    axis_deg, origin_m = _errors(r.model)
    assert axis_deg < 0.3 and origin_m < 2e-3
    assert r.model.joint("hinge").dynamics.damping == pytest.approx(true.joint("hinge").dynamics.damping, rel=0.15)


def test_a_continuation_resumes_the_problem_it_continues(pushed):
    """A dense solve stopped after a few iterations, rebuilt from its last iterate with the
    stopped problem's normalisation, starts at the objective the stopped solve ended with (within
    1 %: the body is put back where its points are); rebuilt from the iterate alone, its scales
    and stop spans follow the iterate and the objective is 2.4× off here."""
    _, data, _ = pushed
    opts = ScrewOptions(substep_s=FINE)
    state = initial_state(data)
    corr = correspondences(data, state, 50)
    sp = build_screw_problem(data, opts, state, corr, dense=True)
    for iterations in (4, 8):
        stopped = sp.problem.solve(max_iter=iterations, options=reco._solver_options(opts, True, sp.hess_lag))
        assert not stopped.success
        iterate = read_solution(sp, stopped)
        resumed = build_screw_problem(data, opts, iterate, corr, True, normalisation=sp.normalisation)
        rebuilt = build_screw_problem(data, opts, iterate, corr, True)
        start = resumed.problem.solve(max_iter=0).objective
        assert start == pytest.approx(stopped.objective, rel=0.01)
        assert abs(rebuilt.problem.solve(max_iter=0).objective / stopped.objective - 1.0) > 0.5
