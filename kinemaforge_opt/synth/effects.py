"""Concealed physical effects: present in the ground-truth simulation, absent from the nominal
model.  Names and the meaning of ``value`` follow the DESIGN.md effect table.

Forces act on the joint coordinate q (rad or m) with velocity v:

=====================  ==========================================================  =================
type                   generalised force added (or model change)                    params
=====================  ==========================================================  =================
viscous_damping        -value·v                                                     –
coulomb_friction       -value·sign(v)  (MuJoCo frictionloss)                        –
stribeck_friction      -value·exp(-(v/v_stribeck)²)·tanh(v/smoothing)               v_stribeck
spring                 -value·(q - rest)                                            rest
constant_bias          +value                                                       –
axis_tilt              true axis = nominal axis tilted by value [rad]               azimuth (opt.)
inertia_error          child link mass and inertia × value                          –
quadratic_drag         -value·v·|v|                                                 –
limit_contact          -stiffness·(q - value) beyond the stop (one-sided)           stiffness, side
=====================  ==========================================================  =================
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError, UnknownNameError
from ..model import ArticulatedModel
from ..spatial import exp_so3, normalize

EFFECT_TYPES: tuple[str, ...] = (
    "viscous_damping",
    "coulomb_friction",
    "stribeck_friction",
    "spring",
    "constant_bias",
    "axis_tilt",
    "inertia_error",
    "quadratic_drag",
    "limit_contact",
)

_REQUIRED_PARAMS = {"stribeck_friction": ("v_stribeck",), "spring": ("rest",), "limit_contact": ("stiffness", "side")}
_NONNEGATIVE = ("viscous_damping", "coulomb_friction", "stribeck_friction", "spring", "axis_tilt", "quadratic_drag")


@dataclass(frozen=True)
class ConcealedEffect:
    """One concealed effect on one joint.

    type: one of :data:`EFFECT_TYPES`.  joint: the movable joint it acts on.  value: see the
    module table (SI units).  params: extra named parameters as ``(name, value)`` pairs, e.g.
    ``(("rest", 0.3),)`` for a spring; ``limit_contact`` needs ``stiffness`` (N·m/rad or N/m) and
    ``side`` ("upper": the stop blocks q > value, "lower": q < value); ``axis_tilt`` accepts
    ``azimuth`` [rad], the direction of the tilt about the nominal axis.
    """

    type: str
    joint: str
    value: float
    params: tuple[tuple[str, float | str], ...] = ()

    def __post_init__(self):
        if self.type not in EFFECT_TYPES:
            raise UnknownNameError("effect type", self.type, EFFECT_TYPES)
        if not np.isfinite(self.value):
            raise ModelError(f"effect {self.type} on {self.joint!r}: value must be finite, got {self.value}")
        if self.type in _NONNEGATIVE and self.value < 0:
            raise ModelError(f"effect {self.type} on {self.joint!r}: value must be >= 0, got {self.value}")
        if self.type == "inertia_error" and not self.value > 0:
            raise ModelError(f"effect inertia_error on {self.joint!r}: ratio must be > 0, got {self.value}")
        names = dict(self.params)
        for p in _REQUIRED_PARAMS.get(self.type, ()):
            if p not in names:
                raise ModelError(f"effect {self.type} on {self.joint!r} needs parameter {p!r}")
        if self.type == "limit_contact" and names["side"] not in ("upper", "lower"):
            raise ModelError(f"effect limit_contact on {self.joint!r}: side must be 'upper' or 'lower', got {names['side']!r}")
        if self.type == "stribeck_friction" and not float(names["v_stribeck"]) > 0:
            raise ModelError(f"effect stribeck_friction on {self.joint!r}: v_stribeck must be > 0")

    def param(self, name: str):
        """The value of parameter ``name``."""
        names = dict(self.params)
        if name not in names:
            raise UnknownNameError(f"parameter of effect {self.type}", name, names)
        return names[name]


def check_effects(model: ArticulatedModel, effects) -> None:
    """Raise naming the effect if it targets a joint the model does not move, or repeats a type."""
    seen = set()
    for e in effects:
        model.joint_index(e.joint)
        if (e.type, e.joint) in seen:
            raise ModelError(f"effect {e.type} is given twice for joint {e.joint!r}")
        seen.add((e.type, e.joint))


def tilted_axis(axis: np.ndarray, angle: float, azimuth: float) -> np.ndarray:
    """Unit ``axis`` (3,) tilted by ``angle`` [rad] towards the perpendicular direction at
    ``azimuth`` [rad] (measured about ``axis`` from the perpendicular closest to world x/y)."""
    a = normalize(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u0 = normalize(np.cross(a, helper))
    u = exp_so3(a * azimuth) @ u0
    return normalize(np.cos(angle) * a + np.sin(angle) * u)


def unit_of(effect_type: str, joint_type: str) -> str:
    """The unit of ``value`` for an effect on a revolute (rad) or prismatic (m) joint."""
    rot = joint_type != "prismatic"
    return {
        "viscous_damping": "N*m*s/rad" if rot else "N*s/m",
        "coulomb_friction": "N*m" if rot else "N",
        "stribeck_friction": "N*m" if rot else "N",
        "spring": "N*m/rad" if rot else "N/m",
        "constant_bias": "N*m" if rot else "N",
        "axis_tilt": "rad",
        "inertia_error": "1",
        "quadratic_drag": "N*m*s^2/rad^2" if rot else "N*s^2/m^2",
        "limit_contact": "rad" if rot else "m",
    }[effect_type]


MODEL_EFFECTS = ("viscous_damping", "coulomb_friction", "spring", "axis_tilt", "inertia_error")
"""Effects an :class:`ArticulatedModel` (and URDF) can hold; the rest are forces computed per step."""


def true_model(model: ArticulatedModel, effects) -> ArticulatedModel:
    """``model`` with the :data:`MODEL_EFFECTS` among ``effects`` applied: damping and Coulomb
    friction added, the spring set, the joint axis tilted (in the joint frame) and the child
    link's mass and inertia scaled (for a single-link subtree this scales the joint-space
    inertia and gravity load by the same ratio)."""
    effects = tuple(effects)
    check_effects(model, effects)
    for e in effects:
        if e.type not in MODEL_EFFECTS:
            continue
        j = model.joint(e.joint)
        d = j.dynamics
        if e.type == "viscous_damping":
            model = model.with_joint(j.name, dynamics=dataclasses.replace(d, damping=d.damping + e.value))
        elif e.type == "coulomb_friction":
            model = model.with_joint(j.name, dynamics=dataclasses.replace(d, coulomb=d.coulomb + e.value))
        elif e.type == "spring":
            if d.spring_stiffness > 0:
                raise ModelError(f"joint {j.name!r} already has a nominal spring; a concealed spring would replace it")
            model = model.with_joint(j.name, dynamics=dataclasses.replace(
                d, spring_stiffness=e.value, spring_rest=float(e.param("rest"))))
        elif e.type == "axis_tilt":
            azimuth = float(dict(e.params).get("azimuth", 0.0))
            model = model.with_joint(j.name, axis=tilted_axis(j.axis, e.value, azimuth))
        else:
            inertial = model.link(j.child).inertial
            if inertial is None:
                raise ModelError(f"inertia_error on joint {j.name!r}: link {j.child!r} has no inertial")
            model = model.with_link(j.child, inertial=dataclasses.replace(
                inertial, mass=inertial.mass * e.value, inertia=inertial.inertia * e.value))
    return model
