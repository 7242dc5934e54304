"""Numeric Pinocchio model from an :class:`ArticulatedModel`.

Layout (shared with the symbolic bridge): one Pinocchio joint per movable joint, in the model's
(depth-first) order; continuous joints are 1-DoF revolute (q is the angle, not cos/sin); links
attached by fixed joints are merged into the body of the joint they ride on; every link gets a
BODY frame named after it, so ``data.oMf[model.getFrameId(name)]`` is ``T_world_link``.
Joint damping, friction and springs are not part of a ``pin.Model`` (apply them as forces);
armature is (``model.armature``).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .articulated import ArticulatedModel

#: Names of a body's ten dynamic parameters in Pinocchio's order (``Inertia.toDynamicParameters``):
#: mass, first moment m·c, inertia about the body origin (lower triangle, row by row).
DYNAMIC_PARAMETER_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")


def _joint_model(joint):
    a = np.asarray(joint.axis, dtype=float)
    if joint.type in ("revolute", "continuous"):
        return pin.JointModelRevoluteUnaligned(a)
    if joint.type == "prismatic":
        return pin.JointModelPrismaticUnaligned(a)
    return pin.JointModelHelicalUnaligned(a, joint.pitch)


def build_pin_model(model: ArticulatedModel, check_dynamics: bool = True) -> pin.Model:
    """A numeric ``pin.Model`` with the same q/v order as ``model.joint_names``.

    Raises :class:`~kinemaforge_opt.errors.MissingDynamicsError` when ``check_dynamics`` and a
    movable joint moves no mass."""
    if check_dynamics:
        model.check_dynamics()
    pm = pin.Model()
    pm.name = model.name
    pm.gravity = pin.Motion(np.asarray(model.gravity, dtype=float), np.zeros(3))
    # For every link: the Pinocchio joint it rides on and its placement in that joint's frame.
    ride: dict[str, tuple[int, pin.SE3]] = {model.root.name: (0, pin.SE3.Identity())}
    frame_of: dict[str, int] = {}
    frame_of[model.root.name] = pm.addFrame(
        pin.Frame(model.root.name, 0, 0, pin.SE3.Identity(), pin.FrameType.BODY)
    )
    for j in model.joints:
        parent_jid, T_pjoint_parentlink = ride[j.parent]
        T_pjoint_joint = T_pjoint_parentlink * pin.SE3(j.T_parent_joint)
        if j.type == "fixed":
            ride[j.child] = (parent_jid, T_pjoint_joint)
        else:
            jid = pm.addJoint(parent_jid, _joint_model(j), T_pjoint_joint, j.name)
            pm.armature[pm.joints[jid].idx_v] = j.dynamics.armature
            if j.limits is not None:
                pm.lowerPositionLimit[pm.joints[jid].idx_q] = j.limits.lower
                pm.upperPositionLimit[pm.joints[jid].idx_q] = j.limits.upper
            ride[j.child] = (jid, pin.SE3.Identity())
        jid, T_joint_link = ride[j.child]
        frame_of[j.child] = pm.addFrame(
            pin.Frame(j.child, jid, frame_of[j.parent], T_joint_link, pin.FrameType.BODY)
        )
    for link in model.links:
        if link.inertial is None:
            continue
        jid, T_joint_link = ride[link.name]
        Y = pin.Inertia(link.inertial.mass, np.asarray(link.inertial.com), np.asarray(link.inertial.inertia))
        pm.appendBodyToJoint(jid, Y, T_joint_link)
    return pm


def inverse_dynamics(model: ArticulatedModel, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Rigid-body inverse dynamics M(q) a + h(q, v) (Pinocchio's RNEA) along the states ``q``,
    ``v``, ``a`` (T, n) -> (T, n) [N·m or N]; joint friction, damping and springs are not in it."""
    pm = build_pin_model(model)
    data = pm.createData()
    return np.array([pin.rnea(pm, data, qq, vv, aa) for qq, vv, aa in zip(q, v, a)])


def joint_space_inertia(model: ArticulatedModel, q: np.ndarray) -> np.ndarray:
    """The joint-space inertia matrix M(q) (n, n) [kg m² / kg] (Pinocchio's CRBA, symmetrised):
    M[k, k] is what joint k moves, the inertia of its subtree about its axis (or its mass along
    a translation)."""
    pm = build_pin_model(model)
    M = pin.crba(pm, pm.createData(), np.asarray(q, dtype=float))
    return np.triu(M) + np.triu(M, 1).T


def forward_dynamics(model: ArticulatedModel, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Rigid-body forward dynamics (Pinocchio's ABA, armature included) along the states ``q``,
    ``v`` (T, n) under the joint forces ``tau`` (T, n) [N·m or N] -> accelerations (T, n)
    [rad/s² or m/s²]; joint friction, damping and springs belong in ``tau``."""
    pm = build_pin_model(model)
    data = pm.createData()
    return np.array([pin.aba(pm, data, qq, vv, tt) for qq, vv, tt in zip(q, v, tau)])


def link_inverse_dynamics(model: ArticulatedModel, links, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """(L, T, n) per link of ``links`` (L names), the share of M(q) a + h(q, v) [N·m or N] that its
    inertia alone (mass, centre of mass and rotational inertia, gravity included) takes along the
    states ``q``, ``v``, ``a`` (T, n): Pinocchio's joint-torque regressor, evaluated once per
    sample, times the link's inertial parameters in the frame of the joint it rides on.  Zero for
    a link without inertia or fixed to the world."""
    pm = build_pin_model(model)
    data = pm.createData()
    thetas = np.zeros((len(links), 10 * (pm.njoints - 1)))
    for i, link in enumerate(links):
        inertial = model.link(link).inertial
        frame = pm.frames[pm.getFrameId(link)]
        if inertial is not None and frame.parentJoint > 0:
            Y = pin.Inertia(inertial.mass, np.asarray(inertial.com), np.asarray(inertial.inertia))
            thetas[i, 10 * (frame.parentJoint - 1): 10 * frame.parentJoint] = frame.placement.act(Y).toDynamicParameters()
    # (the binding returns a 1-D array for a one-joint model, hence the reshape)
    Y_t = np.array([np.reshape(pin.computeJointTorqueRegressor(pm, data, qq, vv, aa), (pm.nv, -1))
                    for qq, vv, aa in zip(q, v, a)])
    return np.einsum("tnp,lp->ltn", Y_t, thetas)
