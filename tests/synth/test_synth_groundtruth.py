"""MuJoCo ground truth checked against analytic mechanics computed from the model alone."""

import mujoco
import numpy as np
import pytest

from kinemaforge_opt.synth.effects import ConcealedEffect as E
from kinemaforge_opt.synth.effects import true_model
from kinemaforge_opt.synth.groundtruth import HandPlan, axes_world, mjcf_string, simulate
from kinemaforge_opt.synth.objects import make_object

G = 9.81


@pytest.fixture(scope="module")
def door():
    return make_object("cabinet", 0)  # one door on a vertical hinge: no gravity torque


@pytest.fixture(scope="module")
def drawer():
    return make_object("drawer", 0)  # one drawer on a horizontal slide


def axis_inertia(obj, joint):
    """Moment of inertia of the child link about the joint axis (parallel-axis theorem) [kg m²]."""
    j = obj.model.joint(joint)
    inert = obj.model.link(j.child).inertial
    c, m, a = inert.com, inert.mass, j.axis
    I_o = inert.inertia + m * (c @ c * np.eye(3) - np.outer(c, c))
    return float(a @ I_o @ a)


def free_phase(ep, plan, margin=0.05):
    return ep.t >= plan.push_s + margin


def accel(ep):
    """Central-difference acceleration at interior samples and the matching (t, q, v)."""
    dt = ep.t[1] - ep.t[0]
    a = (ep.v[2:, 0] - ep.v[:-2, 0]) / (2 * dt)
    return ep.t[1:-1], ep.q[1:-1, 0], ep.v[1:-1, 0], a


def test_mjcf_uses_radians_and_inertia_matches_parallel_axis(door):
    effects = (E("inertia_error", "door_joint", 1.4),)
    xml = mjcf_string(true_model(door.model, effects))
    assert '<compiler angle="radian"' in xml
    mj = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, data)
    M = np.zeros((mj.nv, mj.nv))
    mujoco.mj_fullM(mj, data, M)
    assert M[0, 0] == pytest.approx(1.4 * axis_inertia(door, "door_joint"), rel=1e-9)


def test_damped_door_decays_exponentially(door):
    b, plan = 3.0, HandPlan(goals=(0.3,), push_s=0.5, free_s=1.5)
    ep = simulate(door.model, door.handles, (E("viscous_damping", "door_joint", b),), plan)
    I = axis_inertia(door, "door_joint")
    m = free_phase(ep, plan)
    t0, v0 = ep.t[m][0], ep.v[m][0, 0]
    assert v0 > 0.2 and ep.q[:, 0].max() < door.model.joint("door_joint").limits.upper - 0.1
    expected = v0 * np.exp(-(b / I) * (ep.t[m] - t0))
    np.testing.assert_allclose(ep.v[m, 0], expected, atol=0.01 * v0)


def test_coulomb_door_decelerates_at_f_over_I(door):
    f, plan = 0.4, HandPlan(goals=(0.3,), push_s=0.5, free_s=1.5)
    ep = simulate(door.model, door.handles, (E("coulomb_friction", "door_joint", f),), plan)
    t, q, v, a = accel(ep)
    sliding = (t > plan.push_s + 0.05) & (v > 0.05)
    assert sliding.sum() > 10
    assert np.median(a[sliding]) == pytest.approx(-f / axis_inertia(door, "door_joint"), rel=0.05)


def test_concealed_spring_settles_at_its_rest_position(door):
    plan = HandPlan(goals=(0.5,), push_s=0.5, free_s=8.0)
    effects = (E("spring", "door_joint", 3.0, (("rest", 0.3),)), E("viscous_damping", "door_joint", 4.0))  # about critical
    ep = simulate(door.model, door.handles, effects, plan)
    assert ep.q[-1, 0] == pytest.approx(0.3, abs=0.005)
    assert abs(ep.v[-1, 0]) < 1e-3


def test_concealed_spring_oscillates_with_the_analytic_period(door):
    """Undamped door on a spring: period 2π sqrt(I/k), I about the (vertical) hinge axis."""
    k = 30.0
    plan = HandPlan(goals=(0.5,), push_s=0.5, free_s=4.0)
    ep = simulate(door.model, door.handles, (E("spring", "door_joint", k, (("rest", 0.6),)),), plan, record_hz=600)
    free = free_phase(ep, plan)
    t, x = ep.t[free], ep.q[free, 0] - 0.6
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    crossings = t[up] - x[up] * (t[up + 1] - t[up]) / (x[up + 1] - x[up])  # linear interpolation
    assert len(crossings) >= 2
    period = float(np.mean(np.diff(crossings)))
    assert period == pytest.approx(2 * np.pi * np.sqrt(axis_inertia(door, "door_joint") / k), rel=0.01)


@pytest.mark.parametrize(
    "effect, law",
    [
        (E("quadratic_drag", "drawer_0_joint", 30.0), lambda q, v, m: -30.0 * v * abs(v) / m),
        (E("constant_bias", "drawer_0_joint", -2.0), lambda q, v, m: np.full_like(v, -2.0 / m)),
        (E("stribeck_friction", "drawer_0_joint", 3.0, (("v_stribeck", 0.05),)),
         lambda q, v, m: -3.0 * np.exp(-(v / 0.05) ** 2) * np.sign(v) / m),
    ],
    ids=["quadratic_drag", "constant_bias", "stribeck_friction"],
)
def test_drawer_force_effects_follow_their_law(drawer, effect, law):
    plan = HandPlan(goals=(0.4,), push_s=0.5, free_s=1.0)
    ep = simulate(drawer.model, drawer.handles, (effect,), plan)
    mass = drawer.model.link("drawer_0").inertial.mass
    upper = drawer.model.joint("drawer_0_joint").limits.upper
    t, q, v, a = accel(ep)
    ok = (t > plan.push_s + 0.02) & (np.abs(v) > 0.01) & (q > 0.01) & (q < upper - 0.01)
    assert ok.sum() > 10
    np.testing.assert_allclose(a[ok], law(q[ok], v[ok], mass), atol=0.03 * np.abs(law(q[ok], v[ok], mass)).max() + 1e-3)


def test_tilted_drawer_axis_feels_gravity_and_moves_along_the_true_axis(drawer):
    alpha = 0.03
    effects = (E("axis_tilt", "drawer_0_joint", alpha, (("azimuth", 0.0),)),)
    axis = axes_world(true_model(drawer.model, effects))["drawer_0_joint"]
    nominal = drawer.model.joint("drawer_0_joint").axis
    assert np.degrees(np.arccos(axis @ nominal)) == pytest.approx(np.degrees(alpha), rel=1e-9)
    plan = HandPlan(goals=(0.4,), push_s=0.5, free_s=1.0)
    ep = simulate(drawer.model, drawer.handles, effects, plan)
    t, q, v, a = accel(ep)
    free = (t > plan.push_s + 0.02) & (q > 0.01)
    np.testing.assert_allclose(a[free], G * (axis @ [0, 0, -1]), rtol=0.02)
    k = ep.link_names.index("drawer_0")
    p = ep.Ts_world_link[:, k, :3, 3]
    np.testing.assert_allclose(p - p[0], np.outer(ep.q[:, 0] - ep.q[0, 0], axis), atol=1e-9)


def test_limit_contact_stops_the_door_near_the_stop(door):
    plan = HandPlan(goals=(0.5,), push_s=0.6, free_s=1.5)
    null = simulate(door.model, door.handles, (), plan)
    stop = 1.2
    ep = simulate(door.model, door.handles, (E("limit_contact", "door_joint", stop, (("stiffness", 200.0), ("side", "upper"))),), plan)
    assert null.q[:, 0].max() > stop + 0.3
    assert stop < ep.q[:, 0].max() < stop + 0.1


def test_recorded_hand_force_is_the_generalised_force(door, drawer):
    plan = HandPlan(goals=(0.5,), push_s=0.5, free_s=0.5)
    ep = simulate(drawer.model, drawer.handles, (), plan)
    axis = drawer.model.joint("drawer_0_joint").axis
    np.testing.assert_allclose(ep.tau[:, 0], ep.force_world @ axis, atol=1e-9)
    # Samples average the force over their period: zero from one period after the release.
    period = ep.t[1] - ep.t[0]
    assert np.all(ep.force_world[ep.t >= plan.push_s + period] == 0) and np.abs(ep.tau[ep.t < plan.push_s]).max() > 1
    ep = simulate(door.model, door.handles, (), plan)
    hinge = door.model.joint("door_joint").T_parent_joint[:3, 3]
    moment = np.cross(ep.grip_world - hinge, ep.force_world) @ door.model.joint("door_joint").axis
    # Force and torque are averaged over the sample period while the grip point is sampled: the
    # lever arm moves little within one period.
    np.testing.assert_allclose(ep.tau[:, 0], moment, rtol=2e-2, atol=1e-2)


def test_multi_joint_object_moves_each_joint_in_turn():
    obj = make_object("cabinet_multi", 0)
    plan = HandPlan(goals=(0.5,), push_s=0.5, free_s=0.5)
    ep = simulate(obj.model, obj.handles, (), plan)
    first = ep.t < plan.stroke_s
    assert np.abs(ep.q[first, 1]).max() < 1e-6 and ep.q[first, 0].max() > 0.3
    assert ep.q[~first, 1].max() > 0.05
