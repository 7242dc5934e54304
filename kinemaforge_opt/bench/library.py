"""The candidate-term library shared by the two baselines (inverse-dynamics least squares and
SINDy): named regressor columns evaluated on (q, v, a) of one joint, grouped by DESIGN.md effect
type, and the map from fitted coefficients back to the effect's reported ``value``.

Each column is the generalised force per unit coefficient with the sign convention of
:mod:`kinemaforge_opt.physics.effects` (damping column -v, Coulomb column -sign(v), ...), so a
physically meaningful coefficient is non-negative where DESIGN.md says so.

=====================  ===============  ==========================================================
type                   columns           value
=====================  ===============  ==========================================================
viscous_damping        v: -v             b
coulomb_friction       sign: -sign(v)    f
stribeck_friction      stribeck          excess; column -exp(-(v/v_s)²)·sign(v)
spring                 q: -q, one: 1     k; rest = c_one / k (the constant belongs to the spring)
constant_bias          one: 1            c
quadratic_drag         drag: -v·|v|      d
inertia_error          id: M a + h       λ = 1 - θ  (nominal residual = (1 - λ)(M a + h))
axis_tilt (revolute)   sin, cos          √(θ_sin² + θ_cos²) / (m g r), r: COM lever arm
=====================  ===============  ==========================================================

``v_s`` of the Stribeck column is the median speed of the samples: the library must be fixed
before regression (SINDy's premise), and that is the speed scale the data resolves.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..model.articulated import ArticulatedModel
from ..physics.effects import smooth_sign

GROUPS: dict[str, tuple[str, ...]] = {
    "viscous_damping": ("v",), "coulomb_friction": ("sign",), "stribeck_friction": ("stribeck",),
    "spring": ("q", "one"), "constant_bias": ("one",), "quadratic_drag": ("drag",),
    "inertia_error": ("id",), "axis_tilt": ("sin", "cos"),
}
NONNEGATIVE = ("v", "sign", "stribeck", "q", "drag")  # columns whose coefficient is >= 0


@dataclass(frozen=True)
class JointLibrary:
    """Named columns (each (T,)) for one joint; ``v_stribeck`` [rad/s or m/s] the speed scale of
    the Stribeck column; ``tilt_scale`` m·g·r [N·m] (None for a prismatic joint: no tilt terms)."""

    joint: str
    columns: dict[str, np.ndarray]
    v_stribeck: float
    tilt_scale: float | None

    @property
    def effects(self) -> tuple[str, ...]:
        """Effect types this library can express."""
        return tuple(e for e, cols in GROUPS.items() if all(c in self.columns for c in cols))


def gravity_lever(model: ArticulatedModel, joint: str) -> float | None:
    """m·|g|·r of the joint's child link [N·m]: the gravity torque per radian of axis tilt, r the
    distance of its centre of mass from the nominal axis at q = 0 (None for a prismatic joint
    or a link whose centre of mass is on the axis)."""
    import pinocchio as pin

    from ..model.pinocchio import build_pin_model

    if model.joint(joint).type == "prismatic":
        return None
    pm = build_pin_model(model)
    pd = pm.createData()
    pin.forwardKinematics(pm, pd, pin.neutral(pm))
    jid = pm.getJointId(joint)
    R = pd.oMi[jid].rotation
    axis = R @ model.joint(joint).axis
    lever = R @ pm.inertias[jid].lever
    r = np.linalg.norm(lever - (lever @ axis) * axis)
    scale = float(pm.inertias[jid].mass * np.linalg.norm(model.gravity) * r)
    return scale or None


def _columns(q, v, vs: float, sign) -> dict[str, np.ndarray]:
    """The library's columns at q, v: numpy arrays (T,), or CasADi symbols (a simulated law)."""
    xp = ca if isinstance(q, (ca.SX, ca.MX)) else np
    return {"v": -v, "sign": -sign(v), "stribeck": -xp.exp(-((v / vs) ** 2)) * sign(v),
            "q": -q, "one": 0 * q + 1, "drag": -v * abs(v), "sin": xp.sin(q), "cos": xp.cos(q)}


def joint_library(model: ArticulatedModel, joint: str, q: np.ndarray, v: np.ndarray, id_force: np.ndarray) -> JointLibrary:
    """The library of ``joint`` on samples q, v (T,) and the nominal inverse-dynamics force
    ``id_force`` (T,) = M(q) a + h(q, v) of that joint."""
    vs = max(float(np.median(np.abs(v))), np.finfo(float).tiny)
    tilt = gravity_lever(model, joint)
    cols = _columns(q, v, vs, np.sign)
    cols["id"] = id_force
    if tilt is None:
        del cols["sin"], cols["cos"]
    return JointLibrary(joint, cols, vs, tilt)


def selected_effects(lib: JointLibrary, coef: dict[str, float]) -> dict[str, tuple[float, dict]]:
    """Effect type -> (DESIGN.md value, extra params) from the non-zero coefficients ``coef``
    (column name -> coefficient) of one joint."""
    on = {c for c, x in coef.items() if x != 0.0}
    out = {}
    if "q" in on:
        k = coef["q"]
        out["spring"] = (k, {"rest": coef.get("one", 0.0) / k})
    elif "one" in on:
        out["constant_bias"] = (coef["one"], {})
    if on & {"sin", "cos"}:
        out["axis_tilt"] = (float(np.hypot(coef.get("sin", 0.0), coef.get("cos", 0.0)) / lib.tilt_scale), {})
    if "id" in on:
        out["inertia_error"] = (1.0 - coef["id"], {})
    if "stribeck" in on:
        out["stribeck_friction"] = (coef["stribeck"], {"v_stribeck": lib.v_stribeck})
    for col, effect in (("v", "viscous_damping"), ("sign", "coulomb_friction"), ("drag", "quadratic_drag")):
        if col in on:
            out[effect] = (coef[col], {})
    return out


def force_law(lib: JointLibrary, coef: dict[str, float]):
    """The fitted passive force law f(q, v) of the non-zero coefficients (the ``id`` column is
    not a force law but an inertia change; see :func:`kinemaforge_opt.bench.predict.augmented`).
    Uses the smooth sign of the effect library so the law can be integrated."""

    def force(q, v):  # q, v: the simulator's CasADi symbols of the joint
        cols = _columns(q, v, lib.v_stribeck, smooth_sign)
        return sum(coef[c] * cols[c] for c in coef if c != "id" and coef[c] != 0.0)

    return force
