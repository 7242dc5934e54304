"""A small 3-joint arm with known inertias and joint dynamics (the MuJoCo truth of the tests)."""

import numpy as np
import pytest

from kinemaforge_opt.model import ArticulatedModel, Inertial, Joint, JointDynamics, JointLimits, Link
from kinemaforge_opt.spatial import make_transform, rpy_to_matrix


def _box(mass, size, com):
    x, y, z = size
    I = mass / 12 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])
    return Inertial(mass, np.asarray(com, float), I)


def small_arm(dynamics=True) -> ArticulatedModel:
    """Base-yaw + two pitch joints; links 0.3 m and 0.25 m; Panda-like limits."""
    dyn = [JointDynamics(1.2, 0.8, armature=0.10), JointDynamics(0.9, 0.6, armature=0.08),
           JointDynamics(0.4, 0.3, armature=0.03)] if dynamics else [JointDynamics()] * 3
    lim = JointLimits(-2.5, 2.5, 80.0, 2.0)
    links = (
        Link("base"),
        Link("l1", _box(3.0, (0.08, 0.08, 0.2), (0.0, 0.01, 0.1))),
        Link("l2", _box(2.0, (0.06, 0.06, 0.3), (0.01, 0.0, 0.15))),
        Link("l3", _box(1.2, (0.05, 0.05, 0.25), (0.0, -0.01, 0.12))),
    )
    joints = (
        Joint("j1", "revolute", "base", "l1", make_transform(None, [0, 0, 0.1]), [0, 0, 1], limits=lim, dynamics=dyn[0]),
        Joint("j2", "revolute", "l1", "l2", make_transform(rpy_to_matrix([0.0, 0.0, 0.3]), [0, 0, 0.2]), [0, 1, 0],
              limits=lim, dynamics=dyn[1]),
        Joint("j3", "revolute", "l2", "l3", make_transform(None, [0, 0, 0.3]), [0, 1, 0], limits=lim, dynamics=dyn[2]),
    )
    return ArticulatedModel("small_arm", links, joints)


@pytest.fixture(scope="session")
def arm3() -> ArticulatedModel:
    return small_arm()
