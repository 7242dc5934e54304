"""A link's mass properties as the mesh's scaled by the two ratios a joint's motion determines.

A revolute (continuous, helical) joint's child moves under two inertial quantities: its first
moment m·c about the joint (the gravity torque is (m c) × g) and its inertia about the joint axis
I_a = aᵀ I_c a + m d² (d: distance of the centre of mass from the axis).  Scaling the mesh's mass
properties by one ratio ties them together, so an error in the mesh's m·c / I_a (a thick lid, a
centre of mass off by a few millimetres) cannot be fitted.  Here the ratios are separate:

- ``mass_ratio`` r_m scales the mass and the first moment (the centre of mass stays where the
  geometry puts it): m' = r_m m, m'c' = r_m m c;
- ``inertia_ratio`` r_a scales the inertia about the joint axis, I_a' = r_a I_a, through the
  rotational inertia about the centre of mass: I_c' = s_c I_c with
  s_c = (r_a I_a − r_m m d²) / (aᵀ I_c a).

Both enter the Pinocchio dynamic parameters (about the link origin, on the joint line) linearly:
π' = [r_m m, r_m m c, s_c I_c + r_m m S(c)], S(c) = |c|² 1 − c cᵀ.  When the NLP moves a joint
line, the link frame moves with it but the body stays where the points put it: c becomes c − δ
(δ the frame's displacement, fixed for a solve) and s_c keeps the value computed where the body
was measured.  π'
is a physical rigid body while s_c ≥ 0 (a scaled inertia about the centre of mass plus a point
mass): the NLP constrains s_c ≥ MIN_COM_SCALE (``com_inertia_floor``).

A prismatic joint's child (or a link without an axis of its own) keeps one ratio: its inertia
along a translation is its mass, and its rotational inertia stays proportional to it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import ModelError
from ..model import ArticulatedModel, Inertial

# Smallest scale of the mesh's inertia about the centre of mass: the same floor as the ratios'
# lower bound in the NLP (a body can be far lighter than its mesh, not massless).
MIN_COM_SCALE = 0.02
# A body whose own inertia about the axis is below this share of its inertia about the axis (a
# point mass on an arm) has no second ratio: s_c would multiply almost nothing.
MIN_OWN_SHARE = 1e-3


def link_axis(model: ArticulatedModel, link: str) -> np.ndarray | None:
    """Unit axis (3,) in the link frame of the rotation that ``link``'s own joint makes, or None
    when that joint is not revolute, continuous or helical (the link frame is the joint frame)."""
    parent = next((j for j in model.joints if j.child == link), None)
    if parent is None or parent.type not in ("revolute", "continuous", "helical"):
        return None
    return parent.axis / np.linalg.norm(parent.axis)


@dataclasses.dataclass(frozen=True)
class AxisInertia:
    """The mesh's inertial quantities along an axis a (link frame, unit): own = aᵀ I_c a
    [kg m²], arm = m d² [kg m²] (I_a = own + arm)."""

    own: float
    arm: float

    @property
    def total(self) -> float:
        return self.own + self.arm


def axis_inertia(inertial: Inertial, axis: np.ndarray) -> AxisInertia:
    """:class:`AxisInertia` of ``inertial`` about the line through the link origin along ``axis``."""
    c = inertial.com
    c_perp = c - (c @ axis) * axis
    return AxisInertia(float(axis @ inertial.inertia @ axis), float(inertial.mass * c_perp @ c_perp))


def has_axis_ratio(inertial: Inertial, axis: np.ndarray | None) -> bool:
    """Whether the link gets a separate inertia ratio (see the module doc)."""
    if axis is None or inertial.mass <= 0:
        return False
    ai = axis_inertia(inertial, axis)
    return ai.own > MIN_OWN_SHARE * ai.total


def com_scale(inertial: Inertial, axis: np.ndarray, mass_ratio, inertia_ratio):
    """s_c = (r_a I_a − r_m m d²) / (aᵀ I_c a), linear in the ratios (numbers or casadi symbols)."""
    ai = axis_inertia(inertial, axis)
    return (inertia_ratio * ai.total - mass_ratio * ai.arm) / ai.own


def scaled_parameters(inertial: Inertial, axis: np.ndarray | None, mass_ratio, inertia_ratio=None,
                      shift=None) -> list:
    """The 10 Pinocchio dynamic parameters [m, m c, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] (about the link
    origin) of the scaled body, as a list of expressions in the ratios (numbers or casadi symbols).
    Without an axis (or ``inertia_ratio`` None) every parameter scales with ``mass_ratio``.

    shift: (3,) displacement of the link frame since ``inertial`` was written [m, link axes], or
    None: the body stays where it is and its centre of mass sits at c − shift in the moved frame.
    The ratios' shares (s_c) stay those of ``inertial``."""
    m, c, Ic = inertial.mass, inertial.com, inertial.inertia
    s_c = mass_ratio if axis is None or inertia_ratio is None else com_scale(inertial, axis, mass_ratio, inertia_ratio)
    cs = [float(c[i]) - (0.0 if shift is None else shift[i]) for i in range(3)]
    c2 = cs[0] * cs[0] + cs[1] * cs[1] + cs[2] * cs[2]
    # point-mass inertia about the origin, m (|c|² 1 − c cᵀ), per entry
    S = lambda i, j: m * ((c2 if i == j else 0.0) - cs[i] * cs[j])  # noqa: E731
    idx = [(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)]
    return ([mass_ratio * m] + [mass_ratio * m * ci for ci in cs]
            + [s_c * float(Ic[i, j]) + mass_ratio * S(i, j) for i, j in idx])


def scaled_inertial(inertial: Inertial, axis: np.ndarray | None, mass_ratio: float,
                    inertia_ratio: float | None = None, reference: Inertial | None = None) -> Inertial:
    """The scaled body as an :class:`Inertial` (centre of mass unchanged).  reference: the body
    the ratios were fitted on, with ``axis`` in its frame (default ``inertial``); the rotational
    inertia scale s_c is computed on it, so the same ratios give the same body wherever its frame
    sits.  Ratios that leave no positive inertia about the centre of mass (s_c ≤ 0: the axis
    inertia below the point mass's) raise :class:`ModelError`."""
    if axis is None or inertia_ratio is None:
        return dataclasses.replace(inertial, mass=inertial.mass * mass_ratio, inertia=inertial.inertia * mass_ratio)
    s_c = float(com_scale(inertial if reference is None else reference, axis, mass_ratio, inertia_ratio))
    if s_c <= 0:
        raise ModelError(f"inertia_ratio {inertia_ratio:.4g} with mass_ratio {mass_ratio:.4g} leaves the body an "
                         f"inertia about its centre of mass scaled by {s_c:.4g}; expected > 0 (a physical body)")
    return dataclasses.replace(inertial, mass=inertial.mass * mass_ratio, inertia=inertial.inertia * s_c)
