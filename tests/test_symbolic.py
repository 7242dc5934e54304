"""The bridge's functions equal numeric Pinocchio; theta Jacobians equal finite differences."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from factories import random_tree
from kinemaforge_opt.errors import MissingDynamicsError, UnknownNameError
from kinemaforge_opt.model import ArticulatedModel, Joint, Link, urdf_string
from kinemaforge_opt.model.pinocchio import build_pin_model, joint_space_inertia
from kinemaforge_opt.nlp.joint_space import locked_accelerations
from kinemaforge_opt.symbolic import available_parameters, build_dynamics

SEEDS = range(6)


def _full_M(M):
    return np.triu(M) + np.triu(M, 1).T


def _compare(model, dyn, pm, rng, trials=3):
    pd = pm.createData()
    for _ in range(trials):
        q, v, tau = rng.normal(size=(3, model.nq))
        th = dyn.theta0
        a = pin.aba(pm, pd, q, v, tau)
        np.testing.assert_allclose(dyn.aba(q, v, tau, th).full().ravel(), a, atol=1e-9, rtol=0)
        np.testing.assert_allclose(dyn.rnea(q, v, a, th).full().ravel(), pin.rnea(pm, pd, q, v, a), atol=1e-9)
        np.testing.assert_allclose(dyn.crba(q, th).full(), _full_M(pin.crba(pm, pd, q)), atol=1e-9)
        assert float(dyn.kinetic_energy(q, v, th)) == pytest.approx(pin.computeKineticEnergy(pm, pd, q, v), abs=1e-9)
        assert float(dyn.potential_energy(q, th)) == pytest.approx(pin.computePotentialEnergy(pm, pd, q), abs=1e-9)
        pin.framesForwardKinematics(pm, pd, q)
        Ts = dyn.poses(q)
        for k, name in enumerate(dyn.link_names):
            np.testing.assert_allclose(Ts[k], pd.oMf[pm.getFrameId(name)].homogeneous, atol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_bridge_matches_numeric_pinocchio_on_random_trees(seed):
    rng = np.random.default_rng(seed)
    model = random_tree(rng, n_joints=int(rng.integers(1, 8)))
    free = [n for n in available_parameters(model) if rng.uniform() < 0.3]
    dyn = build_dynamics(model, free=free)
    _compare(model, dyn, build_pin_model(model), rng)


@pytest.mark.parametrize("seed", SEEDS)
def test_bridge_matches_pinocchio_urdf_parser(seed, tmp_path):
    """Independent reference: Pinocchio's own URDF parser on the URDF we write (standard joint
    kinds only: the parser maps continuous joints to cos/sin coordinates and knows no helical)."""
    rng = np.random.default_rng(100 + seed)
    model = random_tree(rng, n_joints=7, kinds=("revolute", "prismatic", "fixed"))
    path = tmp_path / "m.urdf"
    path.write_text(urdf_string(model))
    pm = pin.buildModelFromUrdf(str(path))
    for j in model.movable_joints:  # armature lives in our URDF extension, unknown to the parser
        pm.armature[pm.joints[pm.getJointId(j.name)].idx_v] = j.dynamics.armature
    pd = pm.createData()
    dyn = build_dynamics(model)
    # Map our q order (model.joint_names) to the parser's.
    idx = [pm.joints[pm.getJointId(n)].idx_q for n in model.joint_names]
    for _ in range(3):
        q, v, tau = rng.normal(size=(3, model.nq))
        qp, vp, tp = (np.zeros(pm.nq) for _ in range(3))
        qp[idx], vp[idx], tp[idx] = q, v, tau
        a_ref = pin.aba(pm, pd, qp, vp, tp)[idx]
        np.testing.assert_allclose(dyn.aba(q, v, tau, dyn.theta0).full().ravel(), a_ref, atol=1e-9)
        # CRBA needs each subtree's joints numbered consecutively (the parser numbers depth
        # first); the model's joint order must be so too, or M loses its couplings.
        M_ref = _full_M(pin.crba(pm, pd, qp))[np.ix_(idx, idx)]
        np.testing.assert_allclose(dyn.crba(q, dyn.theta0).full(), M_ref, atol=1e-9)
        np.testing.assert_allclose(joint_space_inertia(model, q), M_ref, atol=1e-9)
        assert float(dyn.kinetic_energy(q, v, dyn.theta0)) == pytest.approx(
            pin.computeKineticEnergy(pm, pd, qp, vp), abs=1e-9
        )
        assert float(dyn.potential_energy(q, dyn.theta0)) == pytest.approx(
            pin.computePotentialEnergy(pm, pd, qp), abs=1e-9
        )


@pytest.mark.parametrize("seed", range(4))
def test_locked_accelerations_equal_pinocchios_reduced_model(seed, tmp_path):
    """Joints held still by their stops (``locked_accelerations``) against Pinocchio's own model
    with those joints welded at their positions (``buildReducedModel`` on the parsed URDF): the
    free joints' accelerations agree whether the held joint is a parent, a child or a sibling of
    the moving ones, and the held joints' are zero."""
    rng = np.random.default_rng(300 + seed)
    model = random_tree(rng, n_joints=5, kinds=("revolute", "prismatic"))
    path = tmp_path / "m.urdf"
    path.write_text(urdf_string(model))
    pm = pin.buildModelFromUrdf(str(path))
    for j in model.movable_joints:
        pm.armature[pm.joints[pm.getJointId(j.name)].idx_v] = j.dynamics.armature
    idx = [pm.joints[pm.getJointId(n)].idx_q for n in model.joint_names]
    dyn = build_dynamics(model)
    for _ in range(3):
        lock = (rng.uniform(size=model.nq) < 0.4).astype(float)
        lock[int(rng.integers(model.nq))] = 0.0  # something moves
        q, v, tau = rng.normal(size=(3, model.nq))
        v[lock > 0] = 0.0  # a held joint stands still
        a = np.asarray(locked_accelerations(dyn, ca.DM(q), ca.DM(v), ca.DM(tau), dyn.theta0, ca.DM(lock))).ravel()
        q_full = np.zeros(pm.nq)
        q_full[idx] = q
        held_ids = [pm.getJointId(n) for n, l in zip(model.joint_names, lock) if l > 0]
        reduced = pin.buildReducedModel(pm, held_ids, q_full)
        free = [n for n, l in zip(model.joint_names, lock) if l == 0]
        ridx = [reduced.joints[reduced.getJointId(n)].idx_q for n in free]
        qr, vr, tr = (np.zeros(reduced.nq) for _ in range(3))
        k_free = [model.joint_names.index(n) for n in free]
        qr[ridx], vr[ridx], tr[ridx] = q[k_free], v[k_free], tau[k_free]
        a_ref = pin.aba(reduced, reduced.createData(), qr, vr, tr)[ridx]
        np.testing.assert_allclose(a[k_free], a_ref, atol=1e-8)
        np.testing.assert_allclose(a[lock > 0], 0.0, atol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_theta_jacobians_match_central_differences(seed):
    rng = np.random.default_rng(200 + seed)
    model = random_tree(rng, n_joints=4)
    free = list(available_parameters(model))
    dyn = build_dynamics(model, free=free)
    q, v, tau = rng.normal(size=(3, model.nq))
    th = ca.SX.sym("th", dyn.theta0.size)
    funcs = {
        "aba": dyn.aba(q, v, tau, th),
        "kinetic_energy": dyn.kinetic_energy(q, v, th),
        "potential_energy": dyn.potential_energy(q, th),
        "link_poses": ca.vec(dyn.link_poses(q, th)),
    }
    for name, expr in funcs.items():
        f = ca.Function(name, [th], [expr])
        J = ca.Function("J", [th], [ca.jacobian(expr, th)])(dyn.theta0).full()
        h = 1e-6
        J_fd = np.zeros_like(J)
        for k in range(th.size1()):
            e = np.zeros(th.size1())
            e[k] = h
            J_fd[:, k] = (f(dyn.theta0 + e).full().ravel() - f(dyn.theta0 - e).full().ravel()) / (2 * h)
        scale = np.maximum(np.abs(J), 1.0)
        assert np.max(np.abs(J - J_fd) / scale) < 1e-6, name


def test_theta_changes_dynamics_like_the_edited_model():
    """Setting theta = edited values must equal building the edited model outright."""
    rng = np.random.default_rng(7)
    model = random_tree(rng, n_joints=5, kinds=("revolute", "prismatic", "helical"))
    j = model.joints[0]
    dyn = build_dynamics(model, free=[f"{j.name}.axis", f"{j.child}.inertia"])
    new_axis = rng.normal(size=3)
    inertial = model.link(j.child).inertial
    from kinemaforge_opt.model import Inertial

    new_inertial = Inertial(inertial.mass * 1.7, inertial.com + 0.05, inertial.inertia * 1.3)
    theta = np.concatenate([new_axis, new_inertial.dynamic_parameters()])
    edited = model.with_joint(j.name, axis=new_axis).with_link(j.child, inertial=new_inertial)
    pm = build_pin_model(edited)
    q, v, tau = rng.normal(size=(3, model.nq))
    np.testing.assert_allclose(dyn.aba(q, v, tau, theta).full().ravel(), pin.aba(pm, pm.createData(), q, v, tau), atol=1e-9)


def test_unknown_parameter_name_lists_the_valid_ones():
    model = random_tree(np.random.default_rng(1), n_joints=2, kinds=("revolute",))
    with pytest.raises(UnknownNameError, match=r"free parameter 'joint0\.axes' does not exist; available: .*'joint0\.axis'"):
        build_dynamics(model, free=["joint0.axes"])


def test_massless_moving_link_is_named():
    model = ArticulatedModel(
        "m", (Link("base"), Link("door")), (Joint("hinge", "revolute", "base", "door", axis=[0, 0, 1]),)
    )
    with pytest.raises(MissingDynamicsError, match=r"joint 'hinge' moves link 'door'.*<inertial>"):
        build_dynamics(model)
