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


def lid_lifted_off_its_stop(dynamics: dict, noise: float = 2e-3) -> tuple:
    """A laptop lid resting shut under its weight on its stop (MuJoCo's joint limit) until a hand
    (a PD law with gravity feed-forward, in the loop at 1 kHz) lifts it to 1.2 rad, lowers it to
    0.4, lifts it to 1.0 and puts it back, the lid's true joint dynamics ``dynamics``
    (JointDynamics fields): (the nominal model, a Recording of q at 30 Hz with ``noise`` [rad] and
    the hand's torque)."""
    from kinemaforge_opt.arm.mujoco_real import arm_from_model, run_controller
    from kinemaforge_opt.io.recording import Recording
    from kinemaforge_opt.synth.objects import make_object

    model = make_object("laptop", 0).model
    (joint,) = model.movable_joints
    arm = arm_from_model(model.with_joint(joint.name, dynamics=JointDynamics(**dynamics)))
    t = np.arange(0.0, 6.5 + 1e-9, arm.dt)
    q_ref = np.convolve(np.interp(t, [0, 0.6, 2.0, 3.2, 4.4, 5.6, 6.5], [0, 0, 1.2, 0.4, 1.0, 0, 0]),
                        np.ones(301) / 301, mode="same")
    v_ref = np.gradient(q_ref, t)

    def hand(tk, q, v, k):  # no touch before 0.6 s
        return np.array([0.0 if tk < 0.6 else 8.0 * (q_ref[k] - q[0]) + 0.4 * (v_ref[k] - v[0]) + 0.55 * np.cos(q_ref[k])])

    _, true = run_controller(arm, t, np.zeros(1), np.zeros(1), hand)
    every = int(round(1 / (30 * arm.dt)))
    q = true.q[::every] + np.random.default_rng(0).normal(0, noise, true.q[::every].shape)
    return model, Recording(t[::every], model.joint_names, q, tau=true.tau[::every])


def motion_about(rotvec=(0.0, 0.0, 0.0), t=(0.0, 0.0, 0.0), about=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(4, 4) world motion: rotation ``rotvec`` [rad] about the point ``about`` [m], then translation t [m]."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = np.asarray(about) - T[:3, :3] @ np.asarray(about) + np.asarray(t)
    return T


def scripted_tracker(poses: list[np.ndarray], voxel: float):
    """A :class:`~kinemaforge_opt.perception.track.Tracker` whose per-step solver returns the
    scripted world motion of each step (the ICP results; a NaN pose: none verifies), each fitting
    fully, to test :meth:`Tracker.track`'s handling of the poses alone; no growing.  ``voxel`` [m]."""
    from kinemaforge_opt.perception.track import Tracker

    class Scripted(Tracker):
        def __init__(self):
            self.poses, self.voxel, self.clouds = poses, voxel, [None] * len(poses)

        def solve_step(self, points, s, guesses):
            return (None, None) if np.isnan(self.poses[s]).any() else (self.poses[s], 1.0)

        def grow(self, ref, points, Ts):
            return points

        def grow_far(self, ref, points, Ts):
            return points

    return Scripted()
