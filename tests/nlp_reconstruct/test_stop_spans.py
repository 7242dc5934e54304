"""Stop impacts in camera-rate joint trajectories (stops.stop_spans, nlp.reconstruction.stop_free)
against motions integrated independently (scipy) or written in closed form, whose impact times
are known."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from kinemaforge_opt.nlp.reconstruction import stop_free
from kinemaforge_opt.stops import stop_spans

# A laptop lid (0.83 kg, centre of mass 0.114 m from the hinge, 0.0144 kg m² about it) between a
# closed stop at 0 and an open stop at 2.37 rad (past vertical), pushed open by a torque that
# falls linearly from PUSH to 0 over 0.8 s; gravity closes it below π/2 and opens it beyond.
M, L, I_HINGE, OPEN = 0.83, 0.114, 0.0144, 2.37


def lid(push: float, dt: float, duration: float = 3.0) -> tuple[np.ndarray, np.ndarray, float]:
    """Frames t (T,) [s], q (T, 1) [rad] of the lid, and the time [s] it lands on a stop (it rests
    there: an inelastic stop)."""
    def f(t, x):
        tau = push * max(0.0, 1 - t / 0.8)
        return [x[1], (tau - M * 9.81 * L * np.cos(x[0])) / I_HINGE]

    def on_stop(t, x):
        return min(x[0] + 1e-9 if t > 0.05 else 1.0, OPEN - x[0])
    on_stop.terminal, on_stop.direction = True, -1
    sol = solve_ivp(f, (0, duration), [0.0, 0.0], events=on_stop, max_step=1e-3, dense_output=True)
    t_hit = float(sol.t_events[0][0])
    rest = float(np.clip(sol.sol(t_hit)[0], 0.0, OPEN))
    t = np.arange(0.0, duration + 1e-9, dt)
    q = np.where(t < t_hit, sol.sol(np.minimum(t, t_hit))[0], rest)
    return t, q[:, None], t_hit


@pytest.mark.parametrize("dt", [0.1, 0.158, 0.275])
@pytest.mark.parametrize("push", [1.28, 1.3])
def test_a_lid_that_falls_over_onto_its_open_stop_is_an_impact(push, dt):
    """The lid slows near vertical, then gravity accelerates it onto the open stop: the speed
    changes before the impact are as large as a smooth stop's, but it arrives faster than it
    leaves (it rests).  The span starts at most two frames before the impact and runs to the end."""
    t, q, t_hit = lid(push, dt)
    assert q[-1, 0] == pytest.approx(OPEN)
    spans = stop_spans(t, q)
    assert len(spans) == 1
    a, b = spans[0]
    assert t[a] <= t_hit <= t[a + 2] and b == t.size - 1


@pytest.mark.parametrize("dt", [0.158, 0.275])
def test_a_lid_that_turns_at_the_top_and_slams_shut_has_one_impact_at_the_slam(dt):
    """Pushed too weakly to pass vertical, the lid turns (a smooth turn at the end of its range:
    no impact) and falls shut onto the closed stop, its start (an impact)."""
    t, q, t_hit = lid(1.24, dt)
    assert q[-1, 0] == pytest.approx(0.0) and q.max() > 0.9
    spans = stop_spans(t, q)
    assert len(spans) == 1
    a, b = spans[0]
    assert t[a] <= t_hit <= t[a + 2] and b == t.size - 1


@pytest.mark.parametrize("dt,coast_s", [(0.1, 0.5), (0.158, 1.0), (0.275, 2.0), (0.5, 2.0)])
def test_a_drawer_that_friction_brings_to_rest_has_no_impact(dt, coast_s):
    """A drawer pushed for 0.5 s at 1 m/s², then slowed by Coulomb friction at a constant rate to
    rest in ``coast_s`` at the far end of its range (closed form).  A coast of fewer than ~4
    frame steps right after the push shows no deceleration before its last steps, and its frames
    are those of a drawer running into a stop: not separable at that frame rate."""
    t = np.arange(0.0, 3.0 + 1e-9, dt)
    v1 = 0.5
    decel = v1 / coast_s
    tc = np.clip(t - 0.5, 0.0, coast_s)
    q = 0.5 * np.minimum(t, 0.5) ** 2 + v1 * tc - 0.5 * decel * tc**2
    assert stop_spans(t, q[:, None]) == []


def test_two_doors_each_hitting_its_stop_leave_the_time_between_the_impacts_in():
    """Door A swings at 1 rad/s from 0.2 s into its stop at 1.0 rad, door B from 3.0 s; each then
    rests.  Both impacts are found, and the grid intervals between A's stay and B's impact stay
    free (B's push is there)."""
    t = np.arange(0.0, 6.0 + 1e-9, 0.25)
    qa = np.clip(t - 0.2, 0.0, 1.0)
    qb = np.clip(t - 3.0, 0.0, 1.0)
    spans = stop_spans(t, np.column_stack([qa, qb]))
    assert len(spans) == 2
    (a0, b0), (a1, b1) = spans
    assert t[a0] <= 1.2 <= t[a0 + 2] and t[a1] <= 4.0 <= t[a1 + 2] and b0 == b1 == t.size - 1
    grid = np.arange(0.0, 6.0 + 1e-9, 0.05)
    free = stop_free(t, np.column_stack([qa, qb]), grid)
    mid = (grid[:-1] + grid[1:]) / 2
    assert free[mid < t[a0]].all() and not free[mid > t[a1]].any()


@pytest.mark.parametrize("dt", [0.4, 0.475])
def test_a_drawer_braked_before_its_stop_that_rebounds_slowly_is_an_impact(dt):
    """A drawer pulled to 0.3 m/s, braked by the hand to 0.11 m/s by 0.85 s, coasts into its open
    stop at 0.2425 m (at 1.7 s) and rebounds at 0.015 m/s (closed form).  At these frame rates
    its speed fell before the stop by about as much as at it, so the drop does not single out
    the impact; turning at the end of its range and leaving it slower than it came does.  The
    span holds the impact."""
    t = np.arange(0.0, 9.0 + 1e-9, dt)
    tf = np.linspace(0.0, 9.0, 90001)
    a = np.where(tf < 0.45, 0.3 / 0.45, np.where(tf < 0.85, -(0.3 - 0.11) / 0.4, 0.0))
    v = np.concatenate([[0.0], np.cumsum((a[1:] + a[:-1]) / 2 * np.diff(tf))])
    x = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 * np.diff(tf))])
    hit = int(np.argmax(x >= 0.2425))
    x[hit:] = 0.2425 - 0.015 * (tf[hit:] - tf[hit])
    q = np.interp(t, tf, x)[:, None]
    spans = stop_spans(t, q)
    assert len(spans) == 1
    a0, b0 = spans[0]
    assert t[a0] <= tf[hit] <= t[b0]
