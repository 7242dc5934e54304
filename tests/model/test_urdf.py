"""URDF round trip, loadability by other consumers, and errors that name the culprit."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from factories import random_inertial, random_tree
from kinemaforge_opt.errors import InputFileError, ModelError
from kinemaforge_opt.model import ArticulatedModel, Joint, JointDynamics, Link, parse_urdf, read_urdf, urdf_string, write_urdf


def _assert_same(a, b):
    assert a.link_names == b.link_names and a.joint_names == b.joint_names
    np.testing.assert_allclose(a.gravity, b.gravity, atol=0)
    for ja, jb in zip(a.joints, b.joints):
        assert (ja.name, ja.type, ja.parent, ja.child) == (jb.name, jb.type, jb.parent, jb.child)
        np.testing.assert_allclose(ja.T_parent_joint, jb.T_parent_joint, atol=1e-14)
        np.testing.assert_allclose(ja.axis, jb.axis, atol=1e-15)
        assert ja.pitch == jb.pitch
        assert ja.limits == jb.limits
        assert ja.dynamics == jb.dynamics
    for la, lb in zip(a.links, b.links):
        assert (la.inertial is None) == (lb.inertial is None)
        if la.inertial is not None:
            assert la.inertial.mass == lb.inertial.mass
            np.testing.assert_allclose(la.inertial.com, lb.inertial.com, atol=0)
            np.testing.assert_allclose(la.inertial.inertia, lb.inertial.inertia, atol=0)


@pytest.mark.parametrize("seed", range(4))
def test_round_trip_is_exact(seed, tmp_path):
    model = random_tree(np.random.default_rng(seed), n_joints=7)
    joint = model.movable_joints[0]
    model = model.with_joint(
        joint.name, dynamics=JointDynamics(damping=0.2, coulomb=0.3, spring_stiffness=1.5, spring_rest=-0.25, armature=0.01)
    )
    path = write_urdf(model, tmp_path / "m.urdf")
    once = read_urdf(path)
    _assert_same(model, once)
    twice = parse_urdf(urdf_string(once))
    _assert_same(once, twice)


def test_joint_order_is_pinocchios_depth_first(tmp_path):
    """Joints listed breadth first (door, drawer, then a handle on the door) are stored depth
    first, the order Pinocchio's URDF parser gives the same file: each subtree right after its
    joint, which Pinocchio's CRBA needs."""
    rng = np.random.default_rng(5)
    T = np.eye(4)
    joints = [Joint("door", "revolute", "base", "door_link", T, (0, 0, 1)),
              Joint("drawer", "prismatic", "base", "drawer_link", T, (1, 0, 0)),
              Joint("handle", "revolute", "door_link", "handle_link", T, (0, 1, 0))]
    links = [Link("base")] + [Link(n, random_inertial(rng)) for n in ("door_link", "drawer_link", "handle_link")]
    model = ArticulatedModel("breadth_first", tuple(links), tuple(joints))
    assert model.joint_names == ("door", "handle", "drawer")
    path = tmp_path / "m.urdf"
    write_urdf(model, path)
    pm = pin.buildModelFromUrdf(str(path))
    assert tuple(pm.names[1:]) == model.joint_names


def test_written_urdf_loads_in_pinocchio_and_drake(tmp_path):
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    model = random_tree(np.random.default_rng(3), n_joints=7)  # includes helical + continuous
    path = write_urdf(model, tmp_path / "m.urdf")
    pm = pin.buildModelFromUrdf(str(path))
    assert {pm.names[i] for i in range(1, pm.njoints)} == set(model.joint_names)
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(path))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base"))
    plant.Finalize()
    assert plant.num_velocities() == model.nq


def test_spring_and_coulomb_survive_in_plain_urdf_readers(tmp_path):
    """Coulomb friction is standard <dynamics friction>; plain readers see it."""
    model = random_tree(np.random.default_rng(5), n_joints=2, kinds=("revolute",))
    name = model.joint_names[0]
    model = model.with_joint(name, dynamics=JointDynamics(coulomb=0.3, damping=0.2, spring_stiffness=2.0))
    text = urdf_string(model)
    assert 'friction="0.3"' in text and 'damping="0.2"' in text and 'spring_stiffness="2.0"' in text


def _urdf(body: str) -> str:
    return f'<robot name="r"><link name="base"/>{body}</robot>'


BAD = [
    ("<robot name='r'><link name='base'></robot>", InputFileError, r"bad\.urdf: malformed XML"),
    (
        _urdf('<link name="a"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>'
              '<joint name="j" type="floating"><parent link="base"/><child link="a"/></joint>'),
        ModelError,
        r"joint 'j' has unsupported type 'floating'",
    ),
    (
        _urdf('<link name="a"/><link name="b"/>'
              '<joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>'
              '<joint name="j2" type="revolute"><parent link="b"/><child link="a"/><axis xyz="0 0 1"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>'),
        ModelError,
        r"loop",
    ),
    (
        _urdf('<link name="a"/><joint name="j" type="revolute"><parent link="base"/><child link="ghost"/><axis xyz="0 0 1"/>'
              '<limit lower="0" upper="1" effort="1" velocity="1"/></joint>'),
        KeyError,  # UnknownNameError is a KinemaforgeError and a KeyError
        r"link \(child of joint 'j'\) 'ghost' does not exist",
    ),
    (
        _urdf('<link name="a"/><joint name="j" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 0"/>'
              '<limit lower="0" upper="1" effort="1" velocity="1"/></joint>'),
        ModelError,
        r"joint 'j' axis must be a non-zero 3-vector",
    ),
    (
        '<robot name="r" xmlns:kinemaforge="https://kinemaforge.dev/urdf/1"><link name="base"/><link name="a"/>'
        '<joint name="j" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>'
        '<limit lower="0" upper="1" effort="1" velocity="1"/><kinemaforge:joint limit_side="0.5"/></joint></robot>',
        ModelError,
        r"bad\.urdf: joint 'j': joint dynamics limit_side must be \+1 \(upper stop\) or -1",
    ),
    (
        _urdf('<link name="a"/><joint name="j" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>'
              '<limit lower="0" upper="1" effort="1" velocity="1"/><dynamics damping="-0.2"/></joint>'),
        ModelError,
        r"bad\.urdf: joint 'j': joint dynamics damping must be >= 0",
    ),
]


@pytest.mark.parametrize("text,exc,pattern", BAD)
def test_bad_urdf_names_the_culprit(text, exc, pattern, tmp_path):
    path = tmp_path / "bad.urdf"
    path.write_text(text)
    with pytest.raises(exc, match=pattern) as info:
        read_urdf(path)
    assert "bad.urdf" in str(info.value) or "ghost" in str(info.value)


def test_missing_file_is_named(tmp_path):
    with pytest.raises(InputFileError, match=r"URDF file '.*nope\.urdf' does not exist"):
        read_urdf(tmp_path / "nope.urdf")


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    from kinemaforge_opt.io.atomic import atomic_path

    target = tmp_path / "model.urdf"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half-writ")
            raise RuntimeError("disk full")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["model.urdf"]
