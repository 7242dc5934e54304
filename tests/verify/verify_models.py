"""Small models with closed-form behaviour, built in code (SI units)."""

from __future__ import annotations

import numpy as np

from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.model import ArticulatedModel, Inertial, Joint, JointDynamics, JointLimits, Link

G = 9.81


def pendulum(length=0.5, mass=1.0, damping=0.0) -> ArticulatedModel:
    """A point mass ``length`` below a hinge about world y."""
    rod = Link("rod", Inertial(mass, [0.0, 0.0, -length], np.zeros((3, 3))))
    hinge = Joint("hinge", "revolute", "base", "rod", axis=[0, 1, 0], dynamics=JointDynamics(damping=damping))
    return ArticulatedModel("pendulum", (Link("base"), rod), (hinge,))


def slider(mass=2.0, axis=(1.0, 0.0, 0.0), limits=None, **dynamics) -> ArticulatedModel:
    """A box of ``mass`` kg on a prismatic joint along ``axis`` (world frame)."""
    cart = Link("cart", Inertial(mass, [0.05, 0.0, 0.0], np.diag([0.01, 0.02, 0.02])))
    x = Joint("x", "prismatic", "base", "cart", axis=axis, limits=limits, dynamics=JointDynamics(**dynamics))
    return ArticulatedModel("slider", (Link("base"), cart), (x,))


def oscillator_recording(m, k, b, rest, x0, duration, rate=100.0, tau=0.0) -> Recording:
    """Exact under-damped response of m x'' = -b x' - k (x - rest) + tau from x0 at rest."""
    t = np.arange(0.0, duration, 1.0 / rate)
    w0, z = np.sqrt(k / m), b / (2 * np.sqrt(k * m))
    wd, s = w0 * np.sqrt(1 - z**2), z * w0
    x_eq = rest + tau / k
    a = x0 - x_eq
    x = x_eq + a * np.exp(-s * t) * (np.cos(wd * t) + s / wd * np.sin(wd * t))
    v = -a * np.exp(-s * t) * (w0**2 / wd) * np.sin(wd * t)
    return Recording(t, ("x",), x[:, None], v[:, None], np.full((t.size, 1), tau))


def cabinet() -> ArticulatedModel:
    """A drawer (prismatic, spring, friction, armature, limits) carrying a door on a tilted hinge."""
    drawer = Link("drawer", Inertial(2.0, [0.1, 0.0, 0.0], np.diag([0.02, 0.03, 0.03])))
    door = Link("door", Inertial(1.0, [0.2, 0.0, 0.3], np.diag([0.05, 0.05, 0.01])))
    T = np.eye(4)
    T[:3, 3] = [0.3, 0.1, 0.0]
    joints = (
        Joint("slide", "prismatic", "base", "drawer", axis=[1, 0, 0], limits=JointLimits(-1.0, 1.0),
              dynamics=JointDynamics(damping=1.0, coulomb=0.2, spring_stiffness=50.0, spring_rest=0.1, armature=0.1)),
        Joint("hinge", "revolute", "drawer", "door", T_parent_joint=T, axis=[0, 0.2, 1],
              limits=JointLimits(-1.5, 1.5), dynamics=JointDynamics(damping=0.3)),
    )
    return ArticulatedModel("cabinet", (Link("base"), drawer, door), joints)
