"""The collocation grid holds the times where the recorded force switches on or off, so a push
that ends between two grid points is integrated whole.  Truth: a drawer under a known force,
its motion written in closed form (constant mass, force linear in time)."""

from __future__ import annotations

import numpy as np

from kinemaforge_opt.io.sequence import Wrenches
from kinemaforge_opt.nlp import reconstruction
from kinemaforge_opt.nlp.reconstruction import ScrewOptions, ScrewState, _grid, build_screw_problem, force_breaks

from .worlds import BOX, door_model, exact_data

AXIS = np.array([0.0, -1.0, 0.0])  # the drawer slides out along its face normal
ORIGIN = np.array([0.3, 0.2, 0.1])
MASS, F0, RATE = 3.0, 6.0, 12.0  # kg (door_model's slab); the force F0 − RATE·t [N] pushes, then brakes
T_LAST = 96 / 120  # [s] the last wrench sample with force (120 Hz)
FRAMES = np.arange(0.0, 2.4, 0.475)  # camera frames as in the protocol cases


def test_grid_holds_the_breaks_and_keeps_every_frame():
    grid, cols = _grid(FRAMES[:4], 0.1, np.array([0.804, 0.951, 1.2]))
    np.testing.assert_allclose(grid[cols], FRAMES[:4])
    assert np.any(np.isclose(grid, 0.804)) and np.any(np.isclose(grid, 1.2))
    assert not np.any(np.isclose(grid, 0.951))  # 1 ms after a frame: no 1-ms interval
    assert np.diff(grid).max() <= 0.1 + 1e-12


TW = np.arange(0, 289) / 120  # wrench samples [s]
FW = np.where(TW <= T_LAST + 1e-9, F0 - RATE * TW, 0.0)  # [N] along the axis


def _slide(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form position [m] and speed [m/s] of the drawer from rest under the first-order hold
    of the samples (FW at TW): on each sample interval the force is linear, so v is quadratic and
    q cubic in the time since the sample."""
    dt = np.diff(TW)
    slope = np.diff(FW) / dt
    v_k = np.r_[0.0, np.cumsum(FW[:-1] * dt + slope * dt**2 / 2)] / MASS
    q_k = np.r_[0.0, np.cumsum(v_k[:-1] * dt + (FW[:-1] * dt**2 / 2 + slope * dt**3 / 6) / MASS)]
    k = np.clip(np.searchsorted(TW, t, side="right") - 1, 0, TW.size - 2)
    s = t - TW[k]
    v = v_k[k] + (FW[k] * s + slope[k] * s**2 / 2) / MASS
    q = q_k[k] + v_k[k] * s + (FW[k] * s**2 / 2 + slope[k] * s**3 / 6) / MASS
    return q, v


def _drawer_data():
    model = door_model(AXIS, ORIGIN, kind="prismatic")
    assert model.link("door").inertial.mass == MASS
    grip = ORIGIN + np.array([BOX[0] / 2 + 0.01, -BOX[1] / 2, 0.0]) + np.outer(_slide(TW)[0], AXIS)
    data = exact_data(model, model, FRAMES, _slide(FRAMES)[0], _slide(FRAMES)[0],
                      wrenches=Wrenches(TW, grip, np.outer(FW, AXIS)))
    pushed = np.where(TW <= T_LAST + 1e-9, "door", "").astype(object)
    return model, type(data)(**{**data.__dict__, "pushed_link": pushed})


def _defects(model, data, grid) -> np.ndarray:
    """The normalised dynamics defects (2, G − 1) of the exact motion on ``grid``, true mass."""
    q, v = _slide(grid)
    j = model.joint("hinge")
    state = ScrewState(axes=j.axis[None, :], origins=j.T_parent_joint[:3, 3][None, :], pitches=np.zeros(1),
                       t=grid, q=q[:, None], v=v[:, None], damping=np.zeros(1), coulomb=np.zeros(1))
    options = ScrewOptions(vis=False, energy="off", fit_dynamics=False, substep_s=0.1, stop_impacts=False)
    sp = build_screw_problem(data, options, state, None, dense=True)
    assert np.allclose(sp.state.t, grid)
    return np.asarray(sp.defects(*[sp.problem.initial(n) for n in sp.problem.terms["variables"]]))


def test_a_push_ending_between_grid_points_is_integrated_whole(monkeypatch):
    """The brake's last sample is at 0.8 s, the next (none) 8 ms later, both inside the
    0.76-0.855 s interval of the plain grid.  On the grid holding both times the exact motion has
    no defect (the force is linear on every interval, the motion cubic: Hermite-Simpson is exact);
    on the plain grid that interval's defect stands out."""
    model, data = _drawer_data()
    np.testing.assert_allclose(force_breaks(data), [T_LAST, T_LAST + 1 / 120])
    grid, _ = _grid(FRAMES, 0.1, force_breaks(data))
    assert np.abs(_defects(model, data, grid)).max() < 1e-6
    monkeypatch.setattr(reconstruction, "force_breaks", lambda d: np.zeros(0))
    plain, _ = _grid(FRAMES, 0.1)
    D = _defects(model, data, plain)
    worst = int(np.argmax(np.abs(D[1])))
    assert plain[worst] < T_LAST < plain[worst + 1]
    assert np.abs(D[1, worst]) > 100 * np.abs(np.delete(D[1], worst)).max()
