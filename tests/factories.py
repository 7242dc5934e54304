"""Shared problem factories for the tests: random kinematic trees with every joint kind."""

from __future__ import annotations

import numpy as np

from kinemaforge_opt.model import ArticulatedModel, Inertial, Joint, JointDynamics, JointLimits, Link
from kinemaforge_opt.spatial import exp_so3, make_transform

ALL_KINDS = ("revolute", "prismatic", "helical", "continuous", "fixed")


def random_inertial(rng: np.random.Generator) -> Inertial:
    """A physically consistent random inertia (kg, m, kg m^2)."""
    R = exp_so3(rng.normal(size=3))
    principal = rng.uniform(0.01, 0.2, size=3)
    principal[2] = min(principal[2], principal[0] + principal[1] - 1e-3)  # triangle inequality
    return Inertial(rng.uniform(0.3, 3.0), rng.normal(size=3) * 0.1, R @ np.diag(principal) @ R.T)


def random_tree(rng: np.random.Generator, n_joints: int = 7, kinds=ALL_KINDS) -> ArticulatedModel:
    """A random tree: each new link hangs off a random earlier link, joint kinds cycle through
    ``kinds`` (shuffled), random placements, axes, pitches, armatures and limits."""
    links = [Link("base")]
    joints = []
    order = list(rng.permutation(np.resize(np.array(kinds), n_joints)))
    for i, kind in enumerate(order):
        links.append(Link(f"link{i}", random_inertial(rng)))
        parent = links[int(rng.integers(0, i + 1))].name
        limits = None if kind in ("continuous", "fixed") else JointLimits(-2.0, 2.0, 50.0, 5.0)
        joints.append(
            Joint(
                name=f"joint{i}",
                type=str(kind),
                parent=parent,
                child=f"link{i}",
                T_parent_joint=make_transform(exp_so3(rng.normal(size=3)), rng.normal(size=3) * 0.3),
                axis=rng.normal(size=3),
                pitch=float(rng.uniform(0.01, 0.1)) if kind == "helical" else 0.0,
                limits=limits,
                dynamics=JointDynamics()
                if kind == "fixed"
                else JointDynamics(
                    damping=float(rng.uniform(0, 1)),
                    coulomb=float(rng.uniform(0, 1)),
                    armature=float(rng.uniform(0, 0.05)),
                ),
            )
        )
    return ArticulatedModel("random_tree", tuple(links), tuple(joints))


def shared_data_dir():
    """The project's shared real recordings: ``../shared/data`` beside the repository
    (override with KINEMAFORGE_SHARED_DATA)."""
    import os
    from pathlib import Path

    env = os.environ.get("KINEMAFORGE_SHARED_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "data"
