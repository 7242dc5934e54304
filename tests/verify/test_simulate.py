"""Drake free responses against closed-form solutions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from verify_models import G, pendulum, slider

from kinemaforge_opt.errors import DataError
from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.model import ArticulatedModel, Inertial, Joint, JointDynamics, JointLimits, Link
from kinemaforge_opt.model.pinocchio import build_pin_model
from kinemaforge_opt.verify import build_plant, energy_residual, mechanical_energy, simulate


def _period(t, q):
    up = t[1:][(q[:-1] < 0) & (q[1:] >= 0)]
    return float(np.mean(np.diff(up)))


@pytest.mark.parametrize("discrete, rtol", [(False, 2e-4), (True, 2e-3)])
def test_pendulum_small_angle_period(discrete, rtol):
    L = 0.5
    tr = simulate(pendulum(L), [0.02], [0.0], 6.0, dt_out=1e-3, discrete=discrete)
    assert _period(tr.t, tr.q[:, 0]) == pytest.approx(2 * np.pi * np.sqrt(L / G), rel=rtol)


@pytest.mark.parametrize("discrete, atol", [(False, 1e-6), (True, 2e-3)])
def test_damped_slider_decays_exponentially(discrete, atol):
    m, b, v0 = 2.0, 3.0, 1.0
    tr = simulate(slider(m, damping=b), [0.0], [v0], 3.0, dt_out=0.01, discrete=discrete)
    decay = np.exp(-b * tr.t / m)
    np.testing.assert_allclose(tr.v[:, 0], v0 * decay, atol=atol)
    np.testing.assert_allclose(tr.q[:, 0], v0 * m / b * (1 - decay), atol=atol)


def test_spring_rests_at_rest_plus_gravity_sag():
    m, k, rest = 2.0, 400.0, 0.3
    model = slider(m, axis=(0, 0, 1), damping=40.0, spring_stiffness=k, spring_rest=rest)
    tr = simulate(model, [rest], [0.0], 3.0, dt_out=0.1, discrete=True)
    assert tr.q[-1, 0] == pytest.approx(rest - m * G / k, abs=1e-6)


def test_armature_adds_to_the_oscillating_inertia():
    m, a, k = 2.0, 0.5, 80.0
    tr = simulate(slider(m, armature=a, spring_stiffness=k), [0.1], [0.0], 4.0, dt_out=1e-3, discrete=False)
    assert _period(tr.t, tr.q[:, 0]) == pytest.approx(2 * np.pi * np.sqrt((m + a) / k), rel=1e-3)


@pytest.mark.parametrize("discrete", [False, True])
def test_coulomb_friction_stops_slider_at_analytic_distance(discrete):
    m, f, v0 = 2.0, 3.0, 1.5
    tr = simulate(slider(m, coulomb=f), [0.0], [v0], 1.5, dt_out=0.01, discrete=discrete)
    assert tr.q[-1, 0] == pytest.approx(v0**2 / (2 * f / m), abs=2e-3)
    assert abs(tr.v[-1, 0]) < 1e-6


@pytest.mark.parametrize("discrete, atol", [(False, 1e-6), (True, 2e-3)])
def test_a_constant_bias_accelerates_the_slider_uniformly(discrete, atol):
    # Drake's joints hold no constant force: it enters as an applied force, x = v0 t + c t² / (2m)
    m, c, v0 = 2.0, -1.2, 0.5
    tr = simulate(slider(m, bias=c), [0.0], [v0], 1.0, dt_out=0.01, discrete=discrete)
    np.testing.assert_allclose(tr.q[:, 0], v0 * tr.t + c * tr.t**2 / (2 * m), atol=atol)


@pytest.mark.parametrize("discrete, atol", [(False, 1e-6), (True, 2e-3)])
def test_quadratic_drag_slows_the_slider_hyperbolically(discrete, atol):
    # m v' = -d v|v| from v0 > 0: v = v0 / (1 + d v0 t / m), x = (m/d) ln(1 + d v0 t / m)
    m, d, v0 = 2.0, 4.0, 1.5
    tr = simulate(slider(m, drag=d), [0.0], [v0], 2.0, dt_out=0.01, discrete=discrete)
    np.testing.assert_allclose(tr.v[:, 0], v0 / (1 + d * v0 * tr.t / m), atol=atol)
    np.testing.assert_allclose(tr.q[:, 0], m / d * np.log1p(d * v0 * tr.t / m), atol=atol)


def test_a_found_limit_stop_reflects_the_slider_like_a_spring():
    # beyond the stop at 0.1 m a 2000 N/m one-sided spring: the slider arriving at v0 turns back
    # after half a period pi sqrt(m/k) and leaves at -v0 (no damping); the stop's 0.5-mm rounding
    # shifts the contact slightly, hence the tolerances
    m, k, stop, v0 = 2.0, 2000.0, 0.1, 0.5
    model = slider(m, limit_stop=stop, limit_stiffness=k, limit_side=1.0)
    tr = simulate(model, [0.0], [v0], 0.6, dt_out=1e-4, discrete=False)
    assert tr.q[:, 0].max() == pytest.approx(stop + v0 * np.sqrt(m / k), abs=1e-3)
    assert tr.v[-1, 0] == pytest.approx(-v0, rel=1e-3)
    inside = tr.q[:, 0] > stop
    assert tr.t[inside][-1] - tr.t[inside][0] == pytest.approx(np.pi * np.sqrt(m / k), rel=0.05)


def test_a_damped_stop_returns_the_slider_slower_as_hunt_crossley_says():
    # with the contact damper the stop's force is x·(k + c·v) for a penetration x (Hunt–Crossley,
    # linear) while the slider moves in, and k·x on its way out (no adhesion).  In: m v dv/(k + c v)
    # = -x dx from v0 to rest at the deepest x_m, so x_m² = 2 m (G(v0) - G(0)) with G(v) = v/c -
    # (k/c²) ln(k + c v); out, elastic: the slider leaves at -x_m sqrt(k/m)
    m, k, c, stop, v0 = 2.0, 2000.0, 2000.0, 0.1, 0.5
    model = slider(m, limit_stop=stop, limit_stiffness=k, limit_damping=c, limit_side=1.0)
    tr = simulate(model, [0.0], [v0], 0.6, dt_out=1e-4, discrete=False)

    def G(v):
        return v / c - k / c**2 * np.log(k + c * v)

    x_m = np.sqrt(2 * m * (G(v0) - G(0.0)))
    v_out = -x_m * np.sqrt(k / m)
    assert -0.95 * v0 < v_out < -0.5 * v0  # a real loss, not the elastic -v0
    assert tr.v[-1, 0] == pytest.approx(v_out, rel=0.01)
    assert tr.q[:, 0].max() == pytest.approx(stop + x_m, abs=1e-3)  # the 0.5-mm rounding


def test_a_damped_stop_does_not_hold_a_slider_that_leaves_it():
    # 2 mm inside the stop and leaving at 0.5 m/s: the linear Hunt–Crossley force x·(k + c·v)
    # would pull it back with 20 N (adhesion); the damper acts only on the way in, so the slider
    # leaves at its speed, pushed by the spring's 0.5·k·x² = 0.4 mJ at most
    m, k, c, stop = 2.0, 200.0, 20000.0, 0.1
    model = slider(m, limit_stop=stop, limit_stiffness=k, limit_damping=c, limit_side=1.0)
    tr = simulate(model, [stop + 0.002], [-0.5], 0.05, dt_out=1e-3, discrete=False)
    assert tr.v[-1, 0] == pytest.approx(-0.5, rel=0.01)


def test_start_just_past_a_limit_is_no_kick():
    # a measured q0 a noise-width (0.7 mrad) below a fitted lower limit, at rest, no force on a
    # horizontal slider: it must stay at rest (Drake's stiff limit constraint used to kick it)
    model = slider(2.0, limits=JointLimits(0.0007, 1.0))
    tr = simulate(model, [0.0], [0.0], 0.5, dt_out=0.01, discrete=True)
    np.testing.assert_allclose(tr.q[:, 0], 0.0007, atol=1e-6)
    np.testing.assert_allclose(tr.v[:, 0], 0.0, atol=1e-6)


def test_energy_is_conserved_without_damping():
    tr = simulate(pendulum(0.5), [1.2], [0.0], 10.0, dt_out=0.01, discrete=False)
    swing = np.ptp(tr.energy - mechanical_energy(pendulum(0.5), tr.q, np.zeros_like(tr.v)))
    assert np.ptp(tr.energy) < 1e-6 * swing
    rec = Recording(tr.t, tr.joint_names, tr.q, tr.v)
    assert energy_residual(pendulum(0.5), rec) < 1e-3


def test_energy_residual_balances_damping_work():
    model = pendulum(0.5, damping=0.2)
    tr = simulate(model, [1.0], [0.0], 5.0, dt_out=0.002, discrete=False)
    rec = Recording(tr.t, tr.joint_names, tr.q, tr.v)
    assert energy_residual(model, rec) < 1e-3
    assert energy_residual(pendulum(0.5, damping=0.0), rec) > 0.5


def test_energy_residual_books_the_work_of_bias_and_drag():
    # a slider pushed by a constant force against quadratic drag: E changes by the work of both
    model = slider(2.0, bias=1.5, drag=3.0)
    tr = simulate(model, [0.0], [2.0], 3.0, dt_out=0.002, discrete=False)
    rec = Recording(tr.t, tr.joint_names, tr.q, tr.v)
    assert energy_residual(model, rec) < 1e-3
    assert energy_residual(slider(2.0, drag=3.0), rec) > 0.1


def test_plant_matches_pinocchio_on_a_tree_with_every_joint_kind():
    rng = np.random.default_rng(3)
    kinds = ("revolute", "prismatic", "helical", "continuous", "fixed")
    links, joints = [Link("base")], []
    for i, kind in enumerate(kinds):
        R = pin.exp3(rng.normal(size=3))
        links.append(Link(f"l{i}", Inertial(1.0 + i, rng.normal(size=3) * 0.1, R @ np.diag([0.05, 0.06, 0.08]) @ R.T)))
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.3
        joints.append(Joint(f"j{i}", kind, links[i].name, f"l{i}", T_parent_joint=T, axis=rng.normal(size=3),
                            pitch=0.05 if kind == "helical" else 0.0,
                            dynamics=JointDynamics(armature=0.01 * i, spring_stiffness=2.0 if kind != "helical" else 0.0,
                                                   spring_rest=0.1)))
    model = ArticulatedModel("tree", tuple(links), tuple(joints))
    plant = build_plant(model, discrete=False).plant
    ctx = plant.CreateDefaultContext()
    pm = build_pin_model(model)
    data = pm.createData()
    q0 = np.zeros(model.nq)
    E_ref = None
    for _ in range(3):
        q, v = rng.normal(size=model.nq), rng.normal(size=model.nq)
        plant.SetPositions(ctx, q)
        plant.SetVelocities(ctx, v)
        np.testing.assert_allclose(plant.CalcMassMatrix(ctx), pin.crba(pm, data, q), atol=1e-9)
        E_drake = plant.CalcKineticEnergy(ctx) + plant.CalcPotentialEnergy(ctx)
        E_ours = mechanical_energy(model, [q], [v])[0]
        if E_ref is None:
            E_ref = E_drake - E_ours
        assert E_drake - E_ours == pytest.approx(E_ref, abs=1e-9)
    del q0


def test_bad_initial_state_is_named():
    with pytest.raises(DataError, match="q0 must have shape"):
        simulate(pendulum(), [0.0, 1.0], [0.0], 1.0)


@pytest.mark.parametrize("discrete", [False, True])
def test_a_recorded_ramp_force_delivers_its_impulse(discrete):
    # m v' = a − b t, recorded at 100 Hz: v = v0 + (a t − b t²/2) / m.  The discrete plant holds
    # its force input over each 1 ms step; held at its step-start value the ramp gave
    # b·dt·t/(2m) too much speed (2.5e-3 m/s after 1 s), held at its step mean it is exact.
    m, a, b, v0 = 1.0, 5.0, 5.0, 0.0
    t = np.arange(0.0, 1.0 + 1e-9, 0.01)
    push = Recording(t, ("x",), np.zeros((t.size, 1)), tau=(a - b * t)[:, None])
    tr = simulate(slider(m), [0.0], [v0], 1.0, tau=push, dt_out=0.01, discrete=discrete)
    np.testing.assert_allclose(tr.v[:, 0], v0 + (a * tr.t - b * tr.t**2 / 2) / m, atol=1e-5)


class _CountingSimulator:
    """Drake's Simulator, recording the latest time it was advanced to."""

    latest = 0.0

    def __init__(self, diagram):
        from pydrake.systems.analysis import Simulator

        self._sim = Simulator(diagram)

    def __getattr__(self, name):
        return getattr(self._sim, name)

    def AdvanceTo(self, t):
        _CountingSimulator.latest = max(_CountingSimulator.latest, t)
        return self._sim.AdvanceTo(t)


@pytest.fixture
def counting_simulator(monkeypatch):
    """The replays of :mod:`kinemaforge_opt.verify.simulate` on a :class:`_CountingSimulator`."""
    import importlib

    monkeypatch.setattr(importlib.import_module("kinemaforge_opt.verify.simulate"), "Simulator", _CountingSimulator)
    _CountingSimulator.latest = 0.0
    return _CountingSimulator


def test_a_replay_at_rest_on_its_stop_is_not_stepped_to_the_horizon(counting_simulator):
    # a pendulum released at 0.5 rad above its stop at 0.3 rad falls onto it and stays: gravity
    # (4.9 N·m·sin q) holds it there, exactly at the stop and at rest, to the 50-s horizon.  Once
    # at rest (and past its last force sample: here none) the replay stops stepping.
    model = pendulum(0.5)
    hinge = dataclasses.replace(model.joints[0], limits=JointLimits(0.3, 1.0))
    model = dataclasses.replace(model, joints=(hinge,))
    tr = simulate(model, [0.5], [0.0], 50.0, dt_out=0.1, discrete=True)
    held = tr.t > 2.0
    np.testing.assert_allclose(tr.q[held, 0], 0.3, atol=1e-3)
    np.testing.assert_allclose(tr.v[held, 0], 0.0, atol=1e-9)
    assert counting_simulator.latest < 10.0


def test_a_settling_pendulum_is_stepped_to_the_horizon(counting_simulator):
    # released at 0.2 rad with light damping it swings for tens of seconds: no output state is
    # at rest, so it is stepped the whole way, and still matches the damped small-angle decay
    m, length, b = 1.0, 0.5, 0.02
    tr = simulate(pendulum(length, m, damping=b), [0.2], [0.0], 20.0, dt_out=0.05, discrete=True)
    assert counting_simulator.latest == pytest.approx(20.0)
    envelope = 0.2 * np.exp(-b / (2 * m * length**2) * tr.t)
    assert np.abs(tr.q[-40:, 0]).max() == pytest.approx(envelope[-1], rel=0.1)
