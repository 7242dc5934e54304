"""Python face of the native bridge: Pinocchio's algorithms on ``casadi.SX`` as named
``casadi.Function`` s of (q, v, tau, theta), where theta stacks the chosen free parameters.

Free parameter names (see :func:`available_parameters`):

=====================  ====  ==========================================================
``<joint>.axis``        3    axis direction in the joint frame (normalised inside; any non-zero vector)
``<joint>.origin``      3    joint frame origin in the parent link frame [m] (a point on the axis)
``<joint>.pitch``       1    helical pitch [m/rad] (helical joints only)
``<joint>.armature``    1    armature (reflected rotor inertia) [kg m^2 or kg]
``<link>.inertia``     10    Pinocchio dynamic parameters about the link origin:
                             [m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] [kg, kg m, kg m^2]
``gravity``             3    world gravity [m/s^2]
=====================  ====  ==========================================================

The bridge builds every function over a full parameter vector P (layout documented in
``native/bridge.hpp``); here the non-free entries of P are fixed to the model's values and the
free ones are taken from theta, so constants fold into the expression graphs.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .errors import KinemaforgeError, UnknownNameError
from .model.articulated import ArticulatedModel
from .native import build_functions

JOINT_PARAMS = 17  # R (9), p (3), axis (3), pitch (1), armature (1)
LINK_PARAMS = 10
_JOINT_FIELDS = {"origin": (9, 3), "axis": (12, 3), "pitch": (15, 1), "armature": (16, 1)}
_TYPE_CODE = {"revolute": "R", "continuous": "R", "prismatic": "P", "helical": "H", "fixed": "F"}


@dataclass(frozen=True)
class FreeParameter:
    """One named block of theta: ``name`` ("door.inertia"), its ``size``, its ``slice`` in theta and
    the model's ``nominal`` value."""

    name: str
    size: int
    slice: slice
    nominal: np.ndarray


@dataclass(frozen=True)
class Dynamics:
    """Named CasADi functions of a model, all built by Pinocchio on SX.

    aba(q, v, tau, theta) -> a; rnea(q, v, a, theta) -> tau; crba(q, theta) -> M (nq, nq);
    kinetic_energy(q, v, theta) -> [J]; potential_energy(q, theta) -> [J];
    link_poses(q, theta) -> Ts_world_link stacked (4 L, 4), link order ``link_names``.
    q, v, tau, a have the length ``nq`` in ``joint_names`` order; theta has ``theta0.size``.
    """

    aba: ca.Function
    rnea: ca.Function
    crba: ca.Function
    kinetic_energy: ca.Function
    potential_energy: ca.Function
    link_poses: ca.Function
    joint_names: tuple[str, ...]
    link_names: tuple[str, ...]
    parameters: tuple[FreeParameter, ...]
    theta0: np.ndarray

    @property
    def nq(self) -> int:
        return len(self.joint_names)

    def parameter(self, name: str) -> FreeParameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise UnknownNameError("free parameter", name, (p.name for p in self.parameters))

    def poses(self, q, theta=None) -> np.ndarray:
        """Numeric link poses: (L, 4, 4) ``Ts_world_link`` for one configuration q (nq,)."""
        theta = self.theta0 if theta is None else theta
        stacked = self.link_poses(np.asarray(q, float), np.asarray(theta, float)).full()
        return stacked.reshape(len(self.link_names), 4, 4)


def available_parameters(model: ArticulatedModel) -> tuple[str, ...]:
    """Every valid free-parameter name of ``model``."""
    names = []
    for j in model.joints:
        if j.type == "fixed":
            names.append(f"{j.name}.origin")
            continue
        names += [f"{j.name}.axis", f"{j.name}.origin", f"{j.name}.armature"]
        if j.type == "helical":
            names.append(f"{j.name}.pitch")
    names += [f"{l.name}.inertia" for l in model.links if l.name != model.root.name]
    names.append("gravity")
    return tuple(names)


def topology_spec(model: ArticulatedModel) -> str:
    """The bridge's topology string: link indices follow ``model.link_names``."""
    index = {n: i for i, n in enumerate(model.link_names)}
    parts = [f"kfbridge/1 {len(model.links)} {len(model.joints)}"]
    parts += [f"{_TYPE_CODE[j.type]} {index[j.parent]} {index[j.child]}" for j in model.joints]
    return " ".join(parts)


def parameter_vector(model: ArticulatedModel) -> np.ndarray:
    """The full bridge parameter vector P of ``model`` (layout in ``native/bridge.hpp``)."""
    P = []
    for j in model.joints:
        P += list(j.T_parent_joint[:3, :3].reshape(-1)) + list(j.T_parent_joint[:3, 3])
        P += list(j.axis) + [j.pitch, j.dynamics.armature]
    for name in model.link_names[1:]:
        inertial = model.link(name).inertial
        P += list(np.zeros(10) if inertial is None else inertial.dynamic_parameters())
    P += list(model.gravity)
    return np.asarray(P, dtype=float)


def _parameter_slots(model: ArticulatedModel) -> dict[str, slice]:
    """Where each named free parameter sits in P."""
    slots = {}
    for i, j in enumerate(model.joints):
        for field, (off, size) in _JOINT_FIELDS.items():
            slots[f"{j.name}.{field}"] = slice(JOINT_PARAMS * i + off, JOINT_PARAMS * i + off + size)
    base = JOINT_PARAMS * len(model.joints)
    for k, name in enumerate(model.link_names[1:]):
        slots[f"{name}.inertia"] = slice(base + LINK_PARAMS * k, base + LINK_PARAMS * (k + 1))
    g = base + LINK_PARAMS * (len(model.links) - 1)
    slots["gravity"] = slice(g, g + 3)
    return slots


@functools.lru_cache(maxsize=64)
def _raw_functions(spec: str) -> tuple[ca.Function, ...]:
    return tuple(build_functions(spec))


def build_dynamics(model: ArticulatedModel, free: tuple[str, ...] | list[str] = ()) -> Dynamics:
    """Build the named functions of ``model`` with ``free`` parameters stacked into theta.

    Raises :class:`UnknownNameError` listing the valid names for an unknown parameter, and
    :class:`~kinemaforge_opt.errors.MissingDynamicsError` if a movable joint moves no mass.
    """
    model.check_dynamics()
    valid = available_parameters(model)
    free = tuple(free)
    for name in free:
        if name not in valid:
            raise UnknownNameError("free parameter", name, valid)
    if len(set(free)) != len(free):
        raise KinemaforgeError(f"free parameters are repeated: {list(free)}")
    raw = _raw_functions(topology_spec(model))
    P0 = parameter_vector(model)
    slots = _parameter_slots(model)

    theta_parts, params, offset = [], [], 0
    P = ca.SX(P0)
    for name in free:
        s = slots[name]
        size = s.stop - s.start
        sym = ca.SX.sym(name.replace(".", "_"), size)
        P[s.start : s.stop] = sym
        theta_parts.append(sym)
        params.append(FreeParameter(name, size, slice(offset, offset + size), P0[s].copy()))
        offset += size
    theta = ca.vertcat(*theta_parts) if theta_parts else ca.SX(0, 1)
    theta0 = np.concatenate([p.nominal for p in params]) if params else np.zeros(0)

    n = model.nq
    q, v, u = ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("tau", n)
    aba, rnea, crba, ke, pe, poses = raw
    return Dynamics(
        aba=ca.Function("aba", [q, v, u, theta], [aba(q, v, u, P)], ["q", "v", "tau", "theta"], ["a"]),
        rnea=ca.Function("rnea", [q, v, u, theta], [rnea(q, v, u, P)], ["q", "v", "a", "theta"], ["tau"]),
        crba=ca.Function("crba", [q, theta], [crba(q, P)], ["q", "theta"], ["M"]),
        kinetic_energy=ca.Function("kinetic_energy", [q, v, theta], [ke(q, v, P)], ["q", "v", "theta"], ["T"]),
        potential_energy=ca.Function("potential_energy", [q, theta], [pe(q, P)], ["q", "theta"], ["V"]),
        link_poses=ca.Function("link_poses", [q, theta], [poses(q, P)], ["q", "theta"], ["Ts_world_link"]),
        joint_names=model.joint_names,
        link_names=model.link_names,
        parameters=tuple(params),
        theta0=theta0,
    )
