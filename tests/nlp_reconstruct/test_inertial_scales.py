"""Gravity moment and inertia about the axis fitted separately, and joint friction the recording
cannot determine left out.  Truth: the generator's models, trajectories integrated independently
(scipy ``solve_ivp`` on pinocchio's numeric ABA, :mod:`.worlds`); mass properties checked with
pinocchio's own parallel-axis algebra."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from kinemaforge_opt.errors import ModelError
from kinemaforge_opt.nlp.inertial_scales import scaled_inertial, scaled_parameters
from kinemaforge_opt.nlp.reconstruction import ScrewOptions, refine_screws
from kinemaforge_opt.spatial import normalize

from .worlds import BOX, box_inertial, door_model, exact_data, pushed_trajectory, two_door_data, two_doors

FINE = 1.0 / 30.0
ORIGIN = np.array([0.3, 0.2, 0.1])
UP_Y = (0.0, -9.81, 0.0)  # gravity along the slab's face normal: the door is a lid on a level hinge


def _moment_and_axis_inertia(model, link="door", joint="hinge"):
    """|m c⊥| [kg m] and the inertia about the joint axis [kg m²], from pinocchio's spatial inertia
    about the link origin (on the axis)."""
    inert = model.link(link).inertial
    a = normalize(model.joint(joint).axis)
    I_origin = pin.Inertia(inert.mass, inert.com, inert.inertia).matrix()[3:, 3:]
    c = inert.com
    return inert.mass * np.linalg.norm(c - (c @ a) * a), float(a @ I_origin @ a)


def test_scaled_body_has_the_scaled_moment_and_axis_inertia():
    inert = box_inertial(2.0, [0.3, 0.05, 0.5], [0.16, 0.01, 0.02])
    axis = normalize([0.1, 0.0, 1.0])
    body = scaled_inertial(inert, axis, 1.3, 1.2)
    m0, c0 = inert.mass, inert.com
    np.testing.assert_allclose(body.mass * body.com, 1.3 * m0 * c0, rtol=1e-12)
    I_axis = lambda i: axis @ pin.Inertia(i.mass, i.com, i.inertia).matrix()[3:, 3:] @ axis  # noqa: E731
    assert I_axis(body) == pytest.approx(1.2 * I_axis(inert), rel=1e-12)
    assert np.all(np.linalg.eigvalsh(body.inertia) > 0)  # a physical body
    # the NLP's linear parameter map is pinocchio's dynamic parameters of that body
    pi = pin.Inertia(body.mass, body.com, body.inertia).toDynamicParameters()
    np.testing.assert_allclose(scaled_parameters(inert, axis, 1.3, 1.2), pi, rtol=1e-10, atol=1e-14)
    # the link frame moved by `shift`, the body left where it was: pinocchio's parameters of the
    # same body about the moved origin
    shift = np.array([0.01, -0.02, 0.005])
    moved = pin.Inertia(body.mass, body.com - shift, body.inertia).toDynamicParameters()
    np.testing.assert_allclose(scaled_parameters(inert, axis, 1.3, 1.2, shift), moved, rtol=1e-10, atol=1e-14)
    # a lighter axis inertia than the heavier point mass alone allows is no body
    with pytest.raises(ModelError, match="inertia_ratio 0.8 with mass_ratio 1.3 .* expected > 0"):
        scaled_inertial(inert, axis, 1.3, 0.8)


def test_lid_gravity_moment_and_axis_inertia_are_recovered_separately():
    """A 3 kg lid (m·c 0.63 kg m, I_a 0.173 kg m², damping 0.2) pushed just past its weight (16.5 N
    at the edge: 6.8 vs 6.2 N·m) for 0.6 s, then swinging free; its "mesh" is a lighter, shorter
    slab with its centre of mass 10 % closer to the hinge (m·c 0.38, I_a 0.093: no single scale
    fits both).  The data determine both, and the damping."""
    true = door_model([0.0, 0.0, 1.0], ORIGIN, damping=0.2, gravity=UP_Y)
    com = np.array([BOX[0] / 2 + 0.01, 0.0, 0.0])
    init = door_model([0.0, 0.0, 1.0], ORIGIN, gravity=UP_Y, inertial=box_inertial(2.0, [0.36, 0.04, 0.3], 0.9 * com))
    t, q, _, w = pushed_trajectory(true, 2.0, 120, 0.6, 16.5)
    idx = np.arange(0, t.size, 12)
    data = exact_data(true, init, t[idx], q[idx], q[idx] + np.random.default_rng(1).normal(0, 0.02, idx.size), wrenches=w)
    r = refine_screws(data, ScrewOptions(energy="soft", substep_s=FINE))
    mc_true, Ia_true = _moment_and_axis_inertia(true)
    mc, Ia = _moment_and_axis_inertia(r.model)
    assert mc == pytest.approx(mc_true, rel=0.03)  # 0.620 vs 0.630 when written
    assert Ia == pytest.approx(Ia_true, rel=0.03)  # 0.171 vs 0.173
    assert r.model.joint("hinge").dynamics.damping == pytest.approx(0.2, rel=0.1)
    assert {"mass_ratio:door", "inertia_ratio:door", "damping:hinge"} <= set(r.identified)
    assert r.model.joint("hinge").dynamics.coulomb == 0.0  # none in the truth, none written


def test_friction_of_a_joint_that_stays_still_is_not_identified_nor_written():
    """Two doors; door a (damping 0.5) is pushed 1 N for 0.5 s, door b has no force and no
    friction and stays where it is, seen with 3 mrad of tracking jitter.  The nominal model has no
    friction on either."""
    axis, origin_b = np.array([0.0, 0.0, 1.0]), ORIGIN + [0.0, 1.0, 0.0]
    true = two_doors(axis, ORIGIN, origin_b, damping_a=0.5)
    t, q, _, w = pushed_trajectory(door_model(axis, ORIGIN, damping=0.5), 1.5, 120, 0.5, 1.0)
    idx = np.arange(0, t.size, 12)
    rng = np.random.default_rng(7)
    Q = np.column_stack([q[idx], rng.normal(0.0, 0.003, idx.size)])
    data = two_door_data(true, two_doors(axis, ORIGIN, origin_b, damping_a=0.0), t[idx], Q,
                         Q + rng.normal(0, 0.02, Q.shape), w, point_sigma=0.001)
    # the plumb refit (gravity_aligned) re-solves everything and tests nothing here
    r = refine_screws(data, ScrewOptions(energy="soft", substep_s=FINE, gravity_aligned=False))
    still = r.model.joint("hinge_b").dynamics
    assert still.damping == 0.0 and still.coulomb == 0.0
    for name in ("damping:hinge_b", "coulomb:hinge_b", "mass_ratio:door_b", "inertia_ratio:door_b"):
        assert name in r.fitted and name not in r.identified
    assert r.model.joint("hinge_a").dynamics.damping == pytest.approx(0.5, rel=0.05)
    assert "damping:hinge_a" in r.identified
    assert any("not identified" in n and "hinge_b" in n for n in r.notes)
