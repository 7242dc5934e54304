"""The effect library: joint-level physics a nominal model may leave out.

Each effect is a generalised force on one joint coordinate, ``force(q, v, p)`` with q [rad or m],
v [rad/s or m/s] and its parameters ``p``, written so it accepts numpy arrays and casadi
symbols alike.  Names and the meaning of ``value`` follow DESIGN.md's effect table.
Effects that change the rigid-body model itself (``axis_tilt``, ``inertia_error``) carry no
force: the calibration frees the matching bridge parameters instead (see ``model_parameters``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import casadi as ca
import numpy as np

# Default width of the smooth sign tanh(v / eps) [rad/s or m/s].  The joint-space fit widens it
# to the velocity resolution of the recording (see nlp.joint_space.friction_smoothing): speeds
# below what the data can resolve carry no information about the shape of sign(v).
V_SMOOTH = 1e-3


def _is_symbolic(x) -> bool:
    return isinstance(x, (ca.SX, ca.MX, ca.DM))


def smooth_sign(v, eps: float = V_SMOOTH):
    """tanh(v / eps): a differentiable sign(v)."""
    if isinstance(v, float):  # a scalar: math.tanh, without numpy's per-call overhead
        return math.tanh(v / eps)
    return ca.tanh(v / eps) if _is_symbolic(v) else np.tanh(np.asarray(v) / eps)


def _exp(x):
    return ca.exp(x) if _is_symbolic(x) else np.exp(x)


def _abs(x):
    return ca.fabs(x) if _is_symbolic(x) else np.abs(x)


@dataclass(frozen=True)
class Effect:
    """A named, parameterised joint effect.

    type: the DESIGN.md name.  params: parameter names; ``params[0]`` is the reported ``value``.
    units: (rotary unit, linear unit) of the value.  lower: lower bounds per parameter (physical
    sign constraints).  force: generalised force (q, v, *params, eps=smooth-sign width) -> force.  conservative: True if
    the force derives from a potential (its work is not dissipated).
    model_parameters: bridge parameters freed instead of a force (axis tilt, inertia error).
    """

    type: str
    params: tuple[str, ...]
    units: tuple[str, str]
    lower: tuple[float, ...]
    force: Callable | None
    conservative: bool = False
    model_parameters: tuple[str, ...] = ()


def _viscous(q, v, b, eps=V_SMOOTH):
    return -b * v


def _coulomb(q, v, f, eps=V_SMOOTH):
    return -f * smooth_sign(v, eps)


def _stribeck(q, v, excess, v_s, eps=V_SMOOTH):
    # Excess static friction decaying with speed: -(f_s - f_c) exp(-(v/v_s)^2) sign(v).
    return -excess * _exp(-((v / v_s) ** 2)) * smooth_sign(v, eps)


def _spring(q, v, k, rest, eps=V_SMOOTH):
    return -k * (q - rest)


def _bias(q, v, c, eps=V_SMOOTH):
    return c + 0 * v


def _drag(q, v, d, eps=V_SMOOTH):
    return -d * v * _abs(v)


def _limit_contact(q, v, stop, k, c=0.0, eps=V_SMOOTH, side=1.0):
    # One-sided contact beyond the stop; side = +1 for an upper stop, -1 for a lower one.  Its
    # force is ramp·(k + c·side·v) (Hunt–Crossley: a spring, and a damper that grows with the
    # penetration, so the force starts at zero on contact; c = 0 is an elastic stop, a large c one
    # that stops a part dead).  The smooth ramp softplus(s·side·(q - stop)) / s approximates
    # max(side·(q - stop), 0) with a 0.5 mrad (or 0.5 mm) rounding.  The damper acts only while
    # the part moves into the stop (its speed there, side·v, smoothly clipped at 0 over eps): on
    # the way out it would pull, an adhesion no stop has (a drawer held shut by a spring, pushed
    # out, was held back by it).  (Clipping k + c·side·v at 0 instead, smoothed over eps of
    # speed, added c·eps/2 of stiffness at rest, which dwarfs k for a dead stop: no rigid stop
    # was found.)
    s = 2000.0
    x = s * side * (q - stop)
    if _is_symbolic(x):  # overflow-free softplus: max(x, 0) + log(1 + exp(-|x|))
        ramp = (ca.fmax(x, 0) + ca.log(1 + ca.exp(-ca.fabs(x)))) / s
    else:  # the same overflow-free form (numpy arrays, or Drake expressions: no logaddexp there)
        ramp = (0.5 * (x + np.abs(x)) + np.log(1 + np.exp(-np.abs(x)))) / s
    closing = side * v
    return -side * ramp * (k + c * 0.5 * closing * (1.0 + smooth_sign(closing, eps)))


EFFECTS: dict[str, Effect] = {
    e.type: e
    for e in (
        Effect("viscous_damping", ("damping",), ("N*m*s/rad", "N*s/m"), (0.0,), _viscous),
        Effect("coulomb_friction", ("coulomb",), ("N*m", "N"), (0.0,), _coulomb),
        Effect(
            "stribeck_friction", ("stribeck", "v_stribeck"), ("N*m", "N"), (0.0, 1e-3), _stribeck
        ),
        Effect(
            "spring",
            ("spring_stiffness", "spring_rest"),
            ("N*m/rad", "N/m"),
            (0.0, -np.inf),
            _spring,
            conservative=True,
        ),
        Effect("constant_bias", ("bias",), ("N*m", "N"), (-np.inf,), _bias),
        Effect("quadratic_drag", ("drag",), ("N*m*s^2/rad^2", "N*s^2/m^2"), (0.0,), _drag),
        Effect("limit_contact", ("limit_stop", "limit_stiffness", "limit_damping"), ("rad", "m"), (-np.inf, 0.0, 0.0),
               _limit_contact),
        Effect("axis_tilt", ("axis",), ("rad", "rad"), (), None, model_parameters=("axis",)),
        Effect("inertia_error", ("inertia_ratio",), ("1", "1"), (), None, model_parameters=("inertia",)),
    )
}

FORCE_EFFECTS = tuple(t for t, e in EFFECTS.items() if e.force is not None)


def dynamics_effects(dynamics) -> tuple[str, ...]:
    """Force effects a :class:`~kinemaforge_opt.model.JointDynamics` switches on: those whose
    parameters are its fields and whose first parameter (the reported value) is non-zero; a
    limit contact when its stiffness is (its stop may sit at q = 0)."""
    def on(t: str) -> bool:
        p = "limit_stiffness" if t == "limit_contact" else EFFECTS[t].params[0]
        return bool(getattr(dynamics, p, 0.0))

    return tuple(t for t in FORCE_EFFECTS if on(t))


def effect_arguments(dynamics, effect_type: str) -> tuple[tuple[float, ...], dict]:
    """(positional parameters, keyword arguments) of ``EFFECTS[effect_type].force`` as a
    :class:`~kinemaforge_opt.model.JointDynamics` holds them (the stop's side for a limit contact)."""
    args = tuple(getattr(dynamics, p) for p in EFFECTS[effect_type].params)
    return args, ({"side": dynamics.limit_side} if effect_type == "limit_contact" else {})
