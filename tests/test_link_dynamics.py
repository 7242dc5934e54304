"""Per-link inverse dynamics and forward dynamics of ``model.pinocchio`` against the textbook
pendulum and against the whole model's RNEA."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.model import ArticulatedModel, Inertial, Joint, Link
from kinemaforge_opt.model.pinocchio import forward_dynamics, inverse_dynamics, link_inverse_dynamics
from kinemaforge_opt.synth.objects import make_object

G = 9.81


def _rod_pendulum(mass: float, length: float) -> ArticulatedModel:
    """A uniform thin rod hanging from a horizontal hinge (x axis) at its end."""
    rod = Inertial(mass, np.array([0.0, 0.0, -length / 2]), mass * np.diag([length**2 / 12, length**2 / 12, 0.0]))
    hinge = Joint("hinge", "continuous", "base", "rod", np.eye(4), np.array([1.0, 0.0, 0.0]))
    return ArticulatedModel("pendulum", (Link("base"), Link("rod", rod)), (hinge,))


def test_a_rod_pendulum_takes_its_textbook_torque():
    """τ = (m l²/3) a + m g (l/2) sin q for a uniform rod of mass m, length l about its end."""
    m, length = 0.7, 0.5
    model = _rod_pendulum(m, length)
    q = np.array([[0.0], [0.4], [1.2], [-2.0]])
    v = np.array([[0.0], [1.0], [-3.0], [0.5]])
    a = np.array([[2.0], [0.0], [1.5], [-4.0]])
    tau = m * length**2 / 3 * a + m * G * length / 2 * np.sin(q)
    rod, base = link_inverse_dynamics(model, ["rod", "base"], q, v, a)
    assert rod == pytest.approx(tau, rel=1e-9, abs=1e-12)
    assert base == pytest.approx(np.zeros_like(q))
    assert forward_dynamics(model, q, v, tau) == pytest.approx(a, rel=1e-9, abs=1e-9)


def test_the_links_shares_add_up_to_the_whole_model():
    """On a two-door refrigerator the links' shares sum to the RNEA of the model (less the
    armature, a joint's own inertia that no link holds)."""
    model = make_object("refrigerator", 0).model
    rng = np.random.default_rng(0)
    q, v, a = rng.uniform(0.0, 1.0, (5, model.nq)), rng.normal(size=(5, model.nq)), rng.normal(size=(5, model.nq))
    armature = np.array([j.dynamics.armature for j in model.movable_joints])
    total = link_inverse_dynamics(model, model.link_names, q, v, a).sum(axis=0)
    assert total + armature * a == pytest.approx(inverse_dynamics(model, q, v, a), rel=1e-9, abs=1e-9)
