"""The articulated model: links, joints with a screw axis, limits, inertia, joint dynamics.

Everything is a frozen dataclass; arrays are stored read-only.  Frames follow URDF: each
joint has a frame placed at ``T_parent_joint`` in its parent link's frame; the child link's
frame coincides with the joint frame at q = 0.  SI units throughout.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..errors import MissingDynamicsError, ModelError, UnknownNameError

JointType = Literal["revolute", "continuous", "prismatic", "helical", "fixed"]
JOINT_TYPES: tuple[str, ...] = ("revolute", "continuous", "prismatic", "helical", "fixed")


def _frozen_array(value, shape: tuple[int, ...], what: str) -> np.ndarray:
    a = np.array(value, dtype=float)
    if a.shape != shape:
        raise ModelError(f"{what} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ModelError(f"{what} holds non-finite values: {a.tolist()}")
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Inertial:
    """Rigid-body inertia of a link, expressed in the link frame.

    mass: kg.  com: (3,) centre of mass in the link frame [m].
    inertia: (3, 3) rotational inertia about the centre of mass, link-frame axes [kg m^2].
    """

    mass: float
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inertia: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))

    def __post_init__(self):
        if not (np.isfinite(self.mass) and self.mass >= 0):
            raise ModelError(f"mass must be finite and >= 0, got {self.mass}")
        object.__setattr__(self, "mass", float(self.mass))
        object.__setattr__(self, "com", _frozen_array(self.com, (3,), "inertial com"))
        I = _frozen_array(self.inertia, (3, 3), "inertia matrix")
        if not np.allclose(I, I.T, atol=1e-12):
            raise ModelError(f"inertia matrix must be symmetric, got {I.tolist()}")
        object.__setattr__(self, "inertia", I)

    def dynamic_parameters(self) -> np.ndarray:
        """(10,) Pinocchio dynamic parameters about the link origin:
        [m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] (parallel-axis shifted)."""
        m, c = self.mass, self.com
        I_o = self.inertia + m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
        return np.array(
            [m, *(m * c), I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2], I_o[2, 2]]
        )

    @staticmethod
    def from_dynamic_parameters(pi: np.ndarray) -> "Inertial":
        """Inverse of :meth:`dynamic_parameters`."""
        pi = np.asarray(pi, dtype=float)
        m = pi[0]
        c = pi[1:4] / m if m > 0 else np.zeros(3)
        I_o = np.array([[pi[4], pi[5], pi[7]], [pi[5], pi[6], pi[8]], [pi[7], pi[8], pi[9]]])
        I_c = I_o - m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
        return Inertial(m, c, (I_c + I_c.T) / 2)

    def is_physically_consistent(self, tol: float = 1e-12) -> bool:
        """Positive mass, positive-definite inertia satisfying the triangle inequalities."""
        ev = np.linalg.eigvalsh(self.inertia)
        a, b, c = ev
        return bool(self.mass > 0 and a > -tol and a + b >= c - tol)


@dataclass(frozen=True, eq=False)
class Geometry:
    """A visual or collision shape of a link.

    kind: "mesh" (``filename`` relative to the URDF's folder, ``scale``), "box" (``size`` (3,)
    [m]), "cylinder" (``size`` = (radius, length)), "sphere" (``size`` = (radius,)).
    T_link_geometry: (4, 4) placement in the link frame.
    """

    kind: Literal["mesh", "box", "cylinder", "sphere"]
    T_link_geometry: np.ndarray = field(default_factory=lambda: np.eye(4))
    filename: str = ""
    size: tuple[float, ...] = ()
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    rgba: tuple[float, float, float, float] | None = None

    def __post_init__(self):
        if self.kind not in ("mesh", "box", "cylinder", "sphere"):
            raise ModelError(f"geometry kind must be mesh, box, cylinder or sphere, got {self.kind!r}")
        object.__setattr__(
            self, "T_link_geometry", _frozen_array(self.T_link_geometry, (4, 4), "T_link_geometry")
        )
        object.__setattr__(self, "size", tuple(float(s) for s in self.size))
        object.__setattr__(self, "scale", tuple(float(s) for s in self.scale))


@dataclass(frozen=True, eq=False)
class Link:
    """A rigid body.  ``inertial`` is None for a massless frame (allowed for the fixed root and
    for links whose subtree has mass elsewhere)."""

    name: str
    inertial: Inertial | None = None
    visuals: tuple[Geometry, ...] = ()
    collisions: tuple[Geometry, ...] = ()


@dataclass(frozen=True)
class JointLimits:
    """Position limits (rad or m), effort (N·m or N) and velocity (rad/s or m/s) bounds."""

    lower: float = -np.inf
    upper: float = np.inf
    effort: float = np.inf
    velocity: float = np.inf

    def __post_init__(self):
        if self.lower > self.upper:
            raise ModelError(f"joint limits: lower {self.lower} > upper {self.upper}")


@dataclass(frozen=True)
class JointDynamics:
    """Joint-level dynamics acting on the joint coordinate q (rad or m), SI units.

    Passive generalised force (see :mod:`kinemaforge_opt.physics.effects` for each term):
    -damping·v - coulomb·sign(v) - stribeck·exp(-(v/v_stribeck)²)·sign(v)
    - spring_stiffness·(q - spring_rest) + bias - drag·v·|v|
    - max(limit_side·(q - limit_stop), 0)·(limit_stiffness + limit_damping·max(limit_side·v, 0))·limit_side;
    armature adds to the joint-space inertia diagonal (kg·m² or kg).  The last term is a stop
    found by ``diagnose`` (limit contact): a one-sided spring, with a damper that grows with the
    penetration (Hunt–Crossley) and acts only while the part moves into the stop (it never pulls),
    beyond ``limit_stop`` [rad or m], above the motion (``limit_side`` +1) or below it (-1); off
    while ``limit_stiffness`` is 0.  (sign and max are smoothed as the effect library does.)
    """

    damping: float = 0.0
    coulomb: float = 0.0
    spring_stiffness: float = 0.0
    spring_rest: float = 0.0
    armature: float = 0.0
    stribeck: float = 0.0
    v_stribeck: float = 0.01
    bias: float = 0.0
    drag: float = 0.0
    limit_stop: float = 0.0
    limit_stiffness: float = 0.0
    limit_damping: float = 0.0
    limit_side: float = 1.0

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not np.isfinite(v):
                raise ModelError(f"joint dynamics {f.name} must be finite, got {v}")
            if f.name not in ("spring_rest", "bias", "limit_stop", "limit_side") and v < 0:
                raise ModelError(f"joint dynamics {f.name} must be >= 0, got {v}")
            object.__setattr__(self, f.name, float(v))
        if self.v_stribeck <= 0:
            raise ModelError(f"joint dynamics v_stribeck must be > 0, got {self.v_stribeck}")
        if self.limit_side not in (1.0, -1.0):
            raise ModelError(
                f"joint dynamics limit_side must be +1 (upper stop) or -1 (lower stop), got {self.limit_side}")

    def passive_force(self, q, v, without: frozenset = frozenset(), eps: float | None = None):
        """Generalised passive force at (q, v); numpy arrays, casadi or Drake symbols (smooth
        sign).  without: effect types (:mod:`kinemaforge_opt.physics.effects` names) left out;
        eps: smooth-sign width [rad/s or m/s] (default: the effect library's)."""
        from ..physics.effects import EFFECTS, dynamics_effects, effect_arguments

        total = 0 * v
        for t in dynamics_effects(self):
            if t in without:
                continue
            args, kwargs = effect_arguments(self, t)
            if eps is not None:
                kwargs["eps"] = eps
            total = total + EFFECTS[t].force(q, v, *args, **kwargs)
        return total


@dataclass(frozen=True, eq=False)
class Joint:
    """A joint between ``parent`` and ``child`` links.

    T_parent_joint: (4, 4) joint frame in the parent link frame (URDF <origin>).
    axis: (3,) unit screw axis in the joint frame (URDF <axis>); ignored for fixed joints.
    pitch: helical pitch [m/rad] (translation along the axis per radian); 0 unless helical.
    """

    name: str
    type: JointType
    parent: str
    child: str
    T_parent_joint: np.ndarray = field(default_factory=lambda: np.eye(4))
    axis: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    pitch: float = 0.0
    limits: JointLimits | None = None
    dynamics: JointDynamics = field(default_factory=JointDynamics)

    def __post_init__(self):
        if self.type not in JOINT_TYPES:
            raise ModelError(
                f"joint {self.name!r} has unknown type {self.type!r}; expected one of {', '.join(JOINT_TYPES)}"
            )
        T = _frozen_array(self.T_parent_joint, (4, 4), f"joint {self.name!r} origin")
        R = T[:3, :3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ModelError(f"joint {self.name!r} origin rotation is not a rotation matrix")
        object.__setattr__(self, "T_parent_joint", T)
        a = np.array(self.axis, dtype=float)
        n = np.linalg.norm(a)
        if a.shape != (3,) or not n > 1e-12:
            raise ModelError(f"joint {self.name!r} axis must be a non-zero 3-vector, got {a.tolist()}")
        if self.type == "fixed":  # a fixed joint has no axis; store a canonical one
            a, n = np.array([1.0, 0.0, 0.0]), 1.0
        object.__setattr__(self, "axis", _frozen_array(a / n, (3,), f"joint {self.name!r} axis"))
        object.__setattr__(self, "pitch", float(self.pitch))
        if self.type != "helical" and self.pitch != 0.0:
            raise ModelError(f"joint {self.name!r}: pitch is only meaningful for helical joints")

    @property
    def is_movable(self) -> bool:
        return self.type != "fixed"


@dataclass(frozen=True, eq=False)
class ArticulatedModel:
    """A fixed-base kinematic tree.  ``joints`` are stored depth first (parents first, each joint's
    subtree right after it).

    gravity: (3,) world-frame gravity [m/s^2]; the root link's frame is the world frame.
    """

    name: str
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))

    def __post_init__(self):
        object.__setattr__(self, "links", tuple(self.links))
        object.__setattr__(self, "gravity", _frozen_array(self.gravity, (3,), "gravity"))
        object.__setattr__(self, "joints", _topological_order(self.links, tuple(self.joints)))

    # --- lookup -----------------------------------------------------------------------------
    @property
    def root(self) -> Link:
        children = {j.child for j in self.joints}
        return next(l for l in self.links if l.name not in children)

    def link(self, name: str) -> Link:
        for l in self.links:
            if l.name == name:
                return l
        raise UnknownNameError("link", name, (l.name for l in self.links))

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise UnknownNameError("joint", name, (j.name for j in self.joints))

    @property
    def movable_joints(self) -> tuple[Joint, ...]:
        """Joints with one degree of freedom, in the order of q."""
        return tuple(j for j in self.joints if j.is_movable)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Names of the movable joints, in the order of q, v and tau."""
        return tuple(j.name for j in self.movable_joints)

    @property
    def link_names(self) -> tuple[str, ...]:
        """Root first, then each joint's child in the joints' (depth-first) order."""
        return (self.root.name,) + tuple(j.child for j in self.joints)

    @property
    def nq(self) -> int:
        return len(self.movable_joints)

    def passive_forces(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(T, n) the joints' own passive forces (:meth:`JointDynamics.passive_force`) [N·m or N]
        along the states ``q``, ``v`` (T, n)."""
        return np.stack([j.dynamics.passive_force(q[:, k], v[:, k]) for k, j in enumerate(self.movable_joints)],
                        axis=1)

    def joint_index(self, name: str) -> int:
        """Index of a movable joint in q."""
        names = self.joint_names
        if name not in names:
            raise UnknownNameError("movable joint", name, names)
        return names.index(name)

    def subtree_links(self, link_name: str) -> tuple[str, ...]:
        """``link_name`` and every link below it."""
        out, stack = [], [link_name]
        while stack:
            n = stack.pop()
            out.append(n)
            stack.extend(j.child for j in self.joints if j.parent == n)
        return tuple(out)

    def check_dynamics(self) -> None:
        """Raise :class:`MissingDynamicsError` naming the joint and link if a movable joint moves
        no mass (its subtree has no <inertial>), which would make the mass matrix singular."""
        for j in self.movable_joints:
            sub = self.subtree_links(j.child)
            if not any((l := self.link(n)).inertial is not None and l.inertial.mass > 0 for n in sub):
                raise MissingDynamicsError(
                    f"joint {j.name!r} moves link {j.child!r}, but no link in its subtree "
                    f"({', '.join(sub)}) has an <inertial> with positive mass; dynamics need one"
                )

    # --- edits (return new models) -----------------------------------------------------------
    def with_joint(self, name: str, **changes) -> "ArticulatedModel":
        """A copy with the fields of joint ``name`` replaced (e.g. ``dynamics=JointDynamics(...)``)."""
        self.joint(name)
        joints = tuple(dataclasses.replace(j, **changes) if j.name == name else j for j in self.joints)
        return dataclasses.replace(self, joints=joints)

    def with_link(self, name: str, **changes) -> "ArticulatedModel":
        """A copy with the fields of link ``name`` replaced (e.g. ``inertial=Inertial(...)``)."""
        self.link(name)
        links = tuple(dataclasses.replace(l, **changes) if l.name == name else l for l in self.links)
        return dataclasses.replace(self, links=links)


def _topological_order(links: tuple[Link, ...], joints: tuple[Joint, ...]) -> tuple[Joint, ...]:
    """Check the joints form one tree over ``links`` and return them depth first."""
    names = [l.name for l in links]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ModelError(f"duplicate link names: {', '.join(dup)}")
    jnames = [j.name for j in joints]
    if len(set(jnames)) != len(jnames):
        dup = sorted({n for n in jnames if jnames.count(n) > 1})
        raise ModelError(f"duplicate joint names: {', '.join(dup)}")
    known = set(names)
    parent_of: dict[str, str] = {}
    for j in joints:
        for role, ln in (("parent", j.parent), ("child", j.child)):
            if ln not in known:
                raise UnknownNameError(f"link ({role} of joint {j.name!r})", ln, known)
        if j.child in parent_of:
            raise ModelError(
                f"link {j.child!r} is the child of two joints ({parent_of[j.child]!r} and {j.name!r}); "
                "a kinematic tree gives every link one parent (closed loops are not supported)"
            )
        parent_of[j.child] = j.name
    roots = [n for n in names if n not in parent_of]
    if len(roots) != 1:
        if not roots:
            raise ModelError("the joints form a loop: every link has a parent, so there is no root link")
        raise ModelError(f"the model has {len(roots)} root links ({', '.join(roots)}); expected one tree")
    by_parent: dict[str, list[Joint]] = {}
    for j in joints:
        by_parent.setdefault(j.parent, []).append(j)
    # Depth first (each joint's subtree right after it, siblings in the given order), as
    # Pinocchio's URDF parser numbers them: its CRBA assumes every subtree's velocity indices
    # are consecutive (ABA and RNEA only need parents first), and a breadth-first order breaks
    # that on a tree with two branches.
    ordered, stack = [], list(reversed(by_parent.get(roots[0], [])))
    while stack:
        j = stack.pop()
        ordered.append(j)
        stack.extend(reversed(by_parent.get(j.child, [])))
    if len(ordered) != len(joints):
        stuck = sorted(set(jnames) - {j.name for j in ordered})
        raise ModelError(f"joints {', '.join(stuck)} form a loop not connected to root {roots[0]!r}")
    return tuple(ordered)
