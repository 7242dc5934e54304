"""Minimal ArticulatedModel -> MJCF converter for serial and tree arms (the MuJoCo "real robot").

Bodies carry only inertia (no geometry, contacts disabled); each movable joint gets a motor
actuator (gear 1, force range = the URDF effort limit) so that ``data.actuator_force`` is the
torque actually applied.  JointDynamics map to MuJoCo as damping -> ``damping``, coulomb ->
``frictionloss``, armature -> ``armature``, spring -> ``stiffness``/``springref``.
Angles in radians (``<compiler angle="radian"/>``), SI units.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from ..errors import ModelError
from ..model import ArticulatedModel


def _vec(v) -> str:
    return " ".join(repr(float(x)) for x in np.ravel(v))


def _place(el: ET.Element, T: np.ndarray) -> None:
    """Set ``pos`` and ``xyaxes`` (first two columns of the rotation) of a body element."""
    el.set("pos", _vec(T[:3, 3]))
    el.set("xyaxes", _vec(np.concatenate([T[:3, 0], T[:3, 1]])))


def model_to_mjcf(model: ArticulatedModel, timestep: float = 1e-3) -> str:
    """MJCF text of ``model``: same joint names and q order as ``model.joint_names``.

    timestep: simulation step [s].  Raises :class:`ModelError` naming the joint for helical joints
    (no MuJoCo equivalent) and naming the link for inertias MuJoCo would reject."""
    root = ET.Element("mujoco", {"model": model.name})
    ET.SubElement(root, "compiler", {"angle": "radian", "inertiafromgeom": "false", "autolimits": "true"})
    opt = ET.SubElement(root, "option", {"timestep": repr(float(timestep)), "gravity": _vec(model.gravity)})
    ET.SubElement(opt, "flag", {"contact": "disable"})
    world = ET.SubElement(root, "worldbody")
    actuators = ET.SubElement(root, "actuator")
    bodies = {model.root.name: world}
    _add_inertial(bodies[model.root.name], model, model.root.name, is_world=True)
    for j in model.joints:
        body = ET.SubElement(bodies[j.parent], "body", {"name": j.child})
        _place(body, j.T_parent_joint)
        bodies[j.child] = body
        _add_inertial(body, model, j.child)
        if not j.is_movable:
            continue
        if j.type == "helical":
            raise ModelError(f"joint {j.name!r} is helical; the MJCF converter supports revolute and prismatic")
        d = j.dynamics
        attrs = {
            "name": j.name,
            "type": "slide" if j.type == "prismatic" else "hinge",
            "axis": _vec(j.axis),
            "damping": repr(d.damping),
            "frictionloss": repr(d.coulomb),
            "armature": repr(d.armature),
            "stiffness": repr(d.spring_stiffness),
            "springref": repr(d.spring_rest),
        }
        lim = j.limits
        if lim is not None and np.isfinite(lim.lower) and np.isfinite(lim.upper):
            attrs["range"] = _vec([lim.lower, lim.upper])
        ET.SubElement(body, "joint", attrs)
        act = {"name": j.name, "joint": j.name, "gear": "1"}
        if lim is not None and np.isfinite(lim.effort):
            act["forcerange"] = _vec([-lim.effort, lim.effort])
        ET.SubElement(actuators, "motor", act)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode")


def _add_inertial(body: ET.Element, model: ArticulatedModel, link_name: str, is_world: bool = False) -> None:
    inertial = model.link(link_name).inertial
    if is_world or inertial is None or inertial.mass <= 0:
        return
    if not inertial.is_physically_consistent(tol=1e-9):
        raise ModelError(f"link {link_name!r}: inertia violates positivity or the triangle inequality")
    I = inertial.inertia
    ET.SubElement(
        body,
        "inertial",
        {
            "pos": _vec(inertial.com),
            "mass": repr(inertial.mass),
            "fullinertia": _vec([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]),
        },
    )
