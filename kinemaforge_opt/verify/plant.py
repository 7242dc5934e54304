"""Drake MultibodyPlant built directly from an :class:`ArticulatedModel` (no URDF round trip).

Mapping (SI units, q order = ``model.joint_names``):

- the root link is Drake's world body; every other link is a rigid body with the link's
  inertia (zero spatial inertia for links without ``<inertial>``);
- a joint's frame on the parent is a fixed offset ``T_parent_joint`` on the parent body, its
  frame on the child is the child body frame (URDF convention);
- revolute/continuous -> ``RevoluteJoint``, prismatic -> ``PrismaticJoint``, helical ->
  ``ScrewJoint`` (our pitch is m/rad, Drake's is m/rev, so ``screw_pitch = 2π·pitch``),
  fixed -> ``WeldJoint``; position limits are set (only the discrete plant enforces them);
- viscous damping -> the joint's Drake damping (treated implicitly by the discrete solver);
- springs -> ``RevoluteSpring`` / ``PrismaticSpring`` (helical: not modelled by Drake, raises);
- armature -> a ``JointActuator`` with gear ratio 1 and rotor inertia = armature, i.e. Drake's
  reflected inertia, which adds to the joint's mass-matrix diagonal exactly like Pinocchio's
  ``model.armature``.  The actuation input is left unconnected (zero);
- Coulomb friction and the applied generalised force are *not* part of the plant: Drake ignores
  URDF ``<dynamics friction>`` (FACTS.md), so :mod:`.simulate` feeds them into the applied
  generalised force input port.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    PrismaticJoint,
    PrismaticSpring,
    RevoluteJoint,
    RevoluteSpring,
    RotationalInertia,
    ScrewJoint,
    SpatialInertia,
    WeldJoint,
)

from ..errors import ModelError
from ..model import ArticulatedModel, Inertial, Joint

DISCRETE_TIME_STEP_S = 1e-3
"""Time step of the discrete plant [s] (FACTS.md: 1 ms enforces joint limits)."""


@dataclass(frozen=True, eq=False)
class DrakePlant:
    """A finalised plant and the joints in q order (``joints[i]`` drives q[i], v[i])."""

    plant: MultibodyPlant
    joints: tuple


def _spatial_inertia(inertial: Inertial | None) -> SpatialInertia:
    if inertial is None or inertial.mass <= 0:
        return SpatialInertia.Zero()
    I = np.asarray(inertial.inertia)
    I_BBcm = RotationalInertia(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
    return SpatialInertia.MakeFromCentralInertia(inertial.mass, np.asarray(inertial.com), I_BBcm)


def _add_joint(plant: MultibodyPlant, j: Joint, parent, child):
    F = plant.AddFrame(
        FixedOffsetFrame(f"{j.name}_parent", parent.body_frame(), RigidTransform(np.asarray(j.T_parent_joint)))
    )
    M = child.body_frame()
    axis = np.asarray(j.axis)
    lo, hi = (-np.inf, np.inf) if j.limits is None or j.type == "continuous" else (j.limits.lower, j.limits.upper)
    b = j.dynamics.damping
    if j.type in ("revolute", "continuous"):
        return plant.AddJoint(RevoluteJoint(j.name, F, M, axis, lo, hi, b))
    if j.type == "prismatic":
        return plant.AddJoint(PrismaticJoint(j.name, F, M, axis, lo, hi, b))
    if j.type == "helical":
        dj = plant.AddJoint(ScrewJoint(j.name, F, M, axis, 2 * np.pi * j.pitch, b))
        if np.isfinite(lo) or np.isfinite(hi):
            dj.set_position_limits([lo], [hi])
        return dj
    return plant.AddJoint(WeldJoint(j.name, F, M, RigidTransform()))


def build_plant(model: ArticulatedModel, discrete: bool = True) -> DrakePlant:
    """A finalised MultibodyPlant of ``model``; ``discrete`` uses a 1 ms step (limits enforced),
    otherwise a continuous plant (limits ignored, FACTS.md).  Raises :class:`ModelError` naming the
    joint for content Drake cannot represent."""
    model.check_dynamics()
    plant = MultibodyPlant(DISCRETE_TIME_STEP_S if discrete else 0.0)
    plant.mutable_gravity_field().set_gravity_vector(np.asarray(model.gravity))
    bodies = {model.root.name: plant.world_body()}
    for link in model.links:
        if link.name != model.root.name:
            bodies[link.name] = plant.AddRigidBody(link.name, _spatial_inertia(link.inertial))
    joints = {}
    for j in model.joints:
        joints[j.name] = _add_joint(plant, j, bodies[j.parent], bodies[j.child])
    for j in model.movable_joints:
        d, dj = j.dynamics, joints[j.name]
        if d.spring_stiffness > 0:
            if j.type in ("revolute", "continuous"):
                plant.AddForceElement(RevoluteSpring(dj, d.spring_rest, d.spring_stiffness))
            elif j.type == "prismatic":
                plant.AddForceElement(PrismaticSpring(dj, d.spring_rest, d.spring_stiffness))
            else:
                raise ModelError(f"joint {j.name!r}: Drake has no spring force element for a helical joint")
        if d.armature > 0:
            actuator = plant.AddJointActuator(f"{j.name}_armature", dj)
            actuator.set_default_rotor_inertia(d.armature)
            actuator.set_default_gear_ratio(1.0)
    if discrete:
        # output ports from the current state rather than a sampled copy kept at each step:
        # the same values here (only the state and the joint forces fed back from it are read),
        # 10-25 % less time per step (the Table-1 replays, bitwise identical)
        plant.SetUseSampledOutputPorts(False)
    plant.Finalize()
    return DrakePlant(plant, tuple(joints[n] for n in model.joint_names))
