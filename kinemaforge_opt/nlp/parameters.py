"""Free parameters of a joint-space calibration: names, physical scales and bounds.

Two families share one naming scheme ``<joint or link>.<field>``:
- rigid-body parameters handled by the native bridge (``symbolic.available_parameters``):
  ``<joint>.axis``, ``<joint>.origin``, ``<joint>.pitch``, ``<joint>.armature``, ``<link>.inertia``,
  ``gravity``;
- joint force parameters of the effect library (``physics.effects``): ``<joint>.damping``,
  ``.coulomb``, ``.stribeck``, ``.v_stribeck``, ``.spring_stiffness``, ``.spring_rest``, ``.bias``,
  ``.drag``, ``.limit_stop``, ``.limit_stiffness``, ``.limit_damping``.

The NLP optimises z = p / scale, with scales taken from the data (force and speed levels of the
recording) so that IPOPT sees O(1) variables whatever the object's size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.articulated import ArticulatedModel

FORCE_PARAMS = (
    "damping", "coulomb", "stribeck", "v_stribeck", "spring_stiffness", "spring_rest",
    "bias", "drag", "limit_stop", "limit_stiffness", "limit_damping",
)
_NONNEGATIVE = {"damping", "coulomb", "stribeck", "spring_stiffness", "drag", "limit_stiffness", "limit_damping"}


@dataclass(frozen=True)
class DataScales:
    """Per-joint typical magnitudes of a recording (arrays of shape (n,)):
    q [rad or m], v [rad/s or m/s], force [N·m or N], inertia [kg·m² or kg]."""

    q: np.ndarray
    v: np.ndarray
    force: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class ParameterBlock:
    """One named free parameter block: physical value p = scale * z."""

    name: str
    nominal: np.ndarray
    scale: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @property
    def size(self) -> int:
        return int(self.nominal.size)

    @property
    def is_force(self) -> bool:
        return self.name.rsplit(".", 1)[-1] in FORCE_PARAMS


def force_parameter_names(model: ArticulatedModel) -> tuple[str, ...]:
    return tuple(f"{j}.{p}" for j in model.joint_names for p in FORCE_PARAMS)


def nominal_force_parameters(model: ArticulatedModel, joint: str) -> dict[str, float]:
    """The model's value of every force parameter of ``joint`` (a limit stop the dynamics do not
    hold defaults to the upper limit, its stiffness to 0, i.e. no contact)."""
    j = model.joint(joint)
    d = j.dynamics
    upper = j.limits.upper if j.limits is not None and np.isfinite(j.limits.upper) else 0.0
    if d.limit_stiffness > 0:
        upper = d.limit_stop
    return {
        "damping": d.damping, "coulomb": d.coulomb, "stribeck": d.stribeck, "v_stribeck": d.v_stribeck,
        "spring_stiffness": d.spring_stiffness, "spring_rest": d.spring_rest, "bias": d.bias,
        "drag": d.drag, "limit_stop": upper, "limit_stiffness": d.limit_stiffness, "limit_damping": d.limit_damping,
    }


def make_block(model: ArticulatedModel, name: str, nominal: np.ndarray, scales: DataScales) -> ParameterBlock:
    """Scale and bounds of a free parameter block from the model and the data scales."""
    owner, field = name.rsplit(".", 1) if "." in name else ("", name)
    nominal = np.asarray(nominal, dtype=float)
    n = nominal.size
    lower, upper = np.full(n, -np.inf), np.full(n, np.inf)
    if field in FORCE_PARAMS:
        k = model.joint_index(owner)
        F, q, v = scales.force[k], scales.q[k], scales.v[k]
        scale = {
            "damping": F / v, "coulomb": F, "stribeck": F, "v_stribeck": v, "spring_stiffness": F / q,
            "spring_rest": q, "bias": F, "drag": F / v**2, "limit_stop": q, "limit_stiffness": F / (0.01 * q),
            "limit_damping": F / (0.01 * q * v),
        }[field]
        scale = np.array([scale])
        if field in _NONNEGATIVE:
            lower[:] = 0.0
        if field == "v_stribeck":
            lower[:] = 1e-3 * v
    elif field == "axis":
        scale = np.ones(3)
    elif field == "origin":
        scale = np.full(3, 0.1)
    elif field == "pitch":
        scale = np.array([0.01])
    elif field == "armature":
        scale = np.array([scales.inertia[model.joint_index(owner)]])
        lower[:] = 0.0
    elif field == "inertia":
        m = max(nominal[0], 1e-6)
        length = max(np.linalg.norm(nominal[1:4]) / m, 0.05)
        scale = np.concatenate([[m], np.full(3, m * length), np.full(6, max(np.abs(nominal[4:]).max(), m * length**2))])
        lower[0] = 0.0
    elif field == "inertia_ratio":
        scale = np.ones(1)
        lower[:] = 1e-3
    elif field == "gravity":
        scale = np.ones(3)
    else:  # pragma: no cover - names are validated before
        raise ValueError(name)
    return ParameterBlock(name, nominal, np.maximum(scale, 1e-12), lower, upper)
