"""URDF read and write for :class:`ArticulatedModel`.  The only module that imports yourdfpy.

What URDF cannot hold (helical pitch, spring stiffness and rest position, armature) is kept in
``<kinemaforge:joint>`` elements in the ``kinemaforge`` XML namespace inside each ``<joint>``;
Coulomb friction goes in the standard ``<dynamics friction>`` attribute.  Plain URDF consumers
(Pinocchio, Drake, yourdfpy) ignore the namespaced element and still load the file; a helical
joint is written as ``type="revolute"`` for them, with its pitch in the extension.
Mesh paths are written relative to the URDF's folder.
"""

from __future__ import annotations

import io as _io
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import yourdfpy

from ..errors import InputFileError, ModelError
from ..io.atomic import write_text_atomic
from ..spatial import make_transform, matrix_to_rpy
from .articulated import (
    ArticulatedModel,
    Geometry,
    Inertial,
    Joint,
    JointDynamics,
    JointLimits,
    Link,
)

KF_NS = "https://kinemaforge.dev/urdf/1"
ET.register_namespace("kinemaforge", KF_NS)
_SUPPORTED = ("revolute", "continuous", "prismatic", "fixed")
# JointDynamics fields that standard URDF cannot hold (damping and friction it can).
_EXTENSION_DYNAMICS = ("spring_stiffness", "spring_rest", "armature", "stribeck", "v_stribeck", "bias", "drag",
                       "limit_stop", "limit_stiffness", "limit_damping", "limit_side")


def read_urdf(path: str | os.PathLike) -> ArticulatedModel:
    """Load a URDF file.  Raises :class:`InputFileError` naming the file for missing or malformed
    files and :class:`ModelError` naming the joint or link for unsupported content."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"URDF file {str(path)!r} does not exist")
    text = path.read_text(encoding="utf-8", errors="replace")
    return parse_urdf(text, source=str(path))


def parse_urdf(text: str, source: str = "<string>") -> ArticulatedModel:
    """Parse URDF XML text; ``source`` names the file in error messages."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise InputFileError(f"{source}: malformed XML ({e})") from None
    if root.tag != "robot":
        raise InputFileError(f"{source}: root element must be <robot>, got <{root.tag}>")
    extensions = _read_extensions(root, source)
    for je in root.findall("joint"):
        jt = je.get("type")
        if jt not in _SUPPORTED:
            raise ModelError(
                f"{source}: joint {je.get('name')!r} has unsupported type {jt!r}; "
                f"supported: {', '.join(_SUPPORTED)} (helical via the kinemaforge extension)"
            )
    try:
        urdf = yourdfpy.URDF.load(
            _io.StringIO(text),
            build_scene_graph=False,
            load_meshes=False,
            filename_handler=yourdfpy.filename_handler_null,
        )
    except Exception as e:  # yourdfpy raises several unrelated types for bad content
        raise InputFileError(f"{source}: not a valid URDF ({type(e).__name__}: {e})") from None
    robot = urdf.robot

    links = tuple(_link_from_urdf(l) for l in robot.links)
    joints = []
    for j in robot.joints:
        ext = extensions.get(j.name, {})
        jtype = "helical" if ext.get("type") == "helical" else j.type
        dyn = j.dynamics
        try:
            dynamics = JointDynamics(
                damping=_f(dyn.damping if dyn else None),
                coulomb=_f(dyn.friction if dyn else None),
                **{k: _f(ext.get(k)) for k in _EXTENSION_DYNAMICS if k in ext},
            )
        except ModelError as e:  # name the file and joint the bad value belongs to
            raise ModelError(f"{source}: joint {j.name!r}: {e}") from None
        limits = None
        if j.limit is not None and jtype != "fixed":
            lim = j.limit
            unbounded = jtype == "continuous"
            limits = JointLimits(
                lower=-np.inf if unbounded or lim.lower is None else float(lim.lower),
                upper=np.inf if unbounded or lim.upper is None else float(lim.upper),
                effort=np.inf if lim.effort is None else float(lim.effort),
                velocity=np.inf if lim.velocity is None else float(lim.velocity),
            )
        axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, dtype=float)
        try:
            joints.append(
                Joint(
                    name=j.name,
                    type=jtype,
                    parent=j.parent,
                    child=j.child,
                    T_parent_joint=np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=float),
                    axis=axis,
                    pitch=_f(ext.get("pitch")) if jtype == "helical" else 0.0,
                    limits=limits,
                    dynamics=dynamics,
                )
            )
        except ModelError as e:
            raise ModelError(f"{source}: {e}") from None
    gravity = np.asarray(extensions.get("__robot__", {}).get("gravity", [0.0, 0.0, -9.81]), dtype=float)
    try:
        return ArticulatedModel(name=robot.name, links=links, joints=tuple(joints), gravity=gravity)
    except ModelError as e:
        raise type(e)(f"{source}: {e}") from None


def write_urdf(model: ArticulatedModel, path: str | os.PathLike) -> Path:
    """Write ``model`` to ``path`` atomically; mesh filenames are written as stored (relative)."""
    path = Path(path)
    write_text_atomic(path, urdf_string(model))
    return path


def urdf_string(model: ArticulatedModel) -> str:
    """The URDF XML text of ``model`` (with the kinemaforge extension where needed)."""
    robot = ET.Element("robot", {"name": model.name})
    if not np.allclose(model.gravity, [0.0, 0.0, -9.81]):
        ET.SubElement(robot, f"{{{KF_NS}}}robot", {"gravity": _vec(model.gravity)})
    for link in model.links:
        le = ET.SubElement(robot, "link", {"name": link.name})
        if link.inertial is not None:
            _write_inertial(le, link.inertial)
        for tag, geoms in (("visual", link.visuals), ("collision", link.collisions)):
            for g in geoms:
                _write_geometry(ET.SubElement(le, tag), g)
    for j in model.joints:
        urdf_type = "revolute" if j.type == "helical" else j.type
        je = ET.SubElement(robot, "joint", {"name": j.name, "type": urdf_type})
        _write_origin(je, j.T_parent_joint)
        ET.SubElement(je, "parent", {"link": j.parent})
        ET.SubElement(je, "child", {"link": j.child})
        if j.type != "fixed":
            ET.SubElement(je, "axis", {"xyz": _vec(j.axis)})
            lim = j.limits or JointLimits()
            if urdf_type in ("revolute", "prismatic") or j.limits is not None:
                attrs = {"effort": _num(lim.effort, 1e6), "velocity": _num(lim.velocity, 1e6)}
                if urdf_type != "continuous":
                    attrs.update(lower=_num(lim.lower, -1e6), upper=_num(lim.upper, 1e6))
                ET.SubElement(je, "limit", attrs)
            d = j.dynamics
            if d.damping or d.coulomb:
                ET.SubElement(je, "dynamics", {"damping": repr(d.damping), "friction": repr(d.coulomb)})
            ext = {}
            if j.type == "helical":
                ext.update(type="helical", pitch=repr(j.pitch))
            default = JointDynamics()
            ext.update(
                {k: repr(getattr(d, k)) for k in _EXTENSION_DYNAMICS if getattr(d, k) != getattr(default, k)}
            )
            if ext:
                ET.SubElement(je, f"{{{KF_NS}}}joint", ext)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


# --- helpers --------------------------------------------------------------------------------


def _f(value) -> float:
    """yourdfpy returns <dynamics> values as strings (FACTS.md): cast, None -> 0."""
    return 0.0 if value is None else float(value)


def _num(x: float, inf_as: float) -> str:
    return repr(float(inf_as if not np.isfinite(x) else x))


def _vec(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def _write_origin(parent: ET.Element, T: np.ndarray) -> None:
    if not np.allclose(T, np.eye(4), atol=0.0):
        ET.SubElement(parent, "origin", {"xyz": _vec(T[:3, 3]), "rpy": _vec(matrix_to_rpy(T[:3, :3]))})


def _write_inertial(le: ET.Element, inertial: Inertial) -> None:
    ie = ET.SubElement(le, "inertial")
    _write_origin(ie, make_transform(None, inertial.com))
    ET.SubElement(ie, "mass", {"value": repr(inertial.mass)})
    I = inertial.inertia
    ET.SubElement(
        ie,
        "inertia",
        {k: repr(float(v)) for k, v in zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
                                           (I[0, 0], I[0, 1], I[0, 2], I[1, 1], I[1, 2], I[2, 2]))},
    )


def _write_geometry(parent: ET.Element, g: Geometry) -> None:
    _write_origin(parent, g.T_link_geometry)
    ge = ET.SubElement(parent, "geometry")
    if g.kind == "mesh":
        attrs = {"filename": g.filename}
        if g.scale != (1.0, 1.0, 1.0):
            attrs["scale"] = _vec(g.scale)
        ET.SubElement(ge, "mesh", attrs)
    elif g.kind == "box":
        ET.SubElement(ge, "box", {"size": _vec(g.size)})
    elif g.kind == "cylinder":
        ET.SubElement(ge, "cylinder", {"radius": repr(g.size[0]), "length": repr(g.size[1])})
    else:
        ET.SubElement(ge, "sphere", {"radius": repr(g.size[0])})
    if g.rgba is not None and parent.tag == "visual":
        me = ET.SubElement(parent, "material", {"name": "rgba_" + "_".join(f"{c:.3f}" for c in g.rgba)})
        ET.SubElement(me, "color", {"rgba": _vec(g.rgba)})


def _read_extensions(root: ET.Element, source: str) -> dict:
    out: dict = {}
    for je in root.findall("joint"):
        ext = je.find(f"{{{KF_NS}}}joint")
        if ext is not None:
            out[je.get("name")] = dict(ext.attrib)
    re_ = root.find(f"{{{KF_NS}}}robot")
    if re_ is not None and re_.get("gravity"):
        try:
            out["__robot__"] = {"gravity": [float(x) for x in re_.get("gravity").split()]}
        except ValueError:
            raise InputFileError(f"{source}: kinemaforge:robot gravity must be three numbers") from None
    return out


def _geometry_from_urdf(v) -> Geometry | None:
    T = np.eye(4) if v.origin is None else np.asarray(v.origin, dtype=float)
    g = v.geometry
    rgba = None
    mat = getattr(v, "material", None)
    if mat is not None and mat.color is not None:
        rgba = tuple(float(c) for c in mat.color.rgba)
    if g.mesh is not None:
        s = g.mesh.scale
        scale = (1.0, 1.0, 1.0) if s is None else tuple(np.broadcast_to(np.asarray(s, float), (3,)))
        return Geometry("mesh", T, filename=g.mesh.filename, scale=scale, rgba=rgba)
    if g.box is not None:
        return Geometry("box", T, size=tuple(g.box.size), rgba=rgba)
    if g.cylinder is not None:
        return Geometry("cylinder", T, size=(g.cylinder.radius, g.cylinder.length), rgba=rgba)
    if g.sphere is not None:
        return Geometry("sphere", T, size=(g.sphere.radius,), rgba=rgba)
    return None


def _link_from_urdf(l) -> Link:
    inertial = None
    if l.inertial is not None and l.inertial.mass is not None:
        T = np.eye(4) if l.inertial.origin is None else np.asarray(l.inertial.origin, dtype=float)
        R = T[:3, :3]
        I = np.zeros((3, 3)) if l.inertial.inertia is None else np.asarray(l.inertial.inertia, dtype=float)
        inertial = Inertial(float(l.inertial.mass), T[:3, 3], R @ I @ R.T)
    visuals = tuple(g for g in (_geometry_from_urdf(v) for v in l.visuals) if g is not None)
    collisions = tuple(g for g in (_geometry_from_urdf(c) for c in l.collisions) if g is not None)
    return Link(l.name, inertial, visuals, collisions)


__all__ = ["read_urdf", "parse_urdf", "write_urdf", "urdf_string", "KF_NS"]
