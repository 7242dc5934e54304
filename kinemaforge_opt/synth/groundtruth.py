"""Ground-truth physics in MuJoCo: the nominal model plus concealed effects, driven by a hand
force at a handle and then released so that a free response follows.

MuJoCo is only the independent ground-truth simulator; estimators never import this module.
MJCF is written with ``<compiler angle="radian"/>`` (MuJoCo defaults to degrees).  Bodies are
placed at the URDF joint frames, so each body frame is the URDF link frame.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco
import numpy as np

from ..model import ArticulatedModel
from ..spatial import log_so3
from .effects import ConcealedEffect, true_model
from .objects import Handle

SIM_HZ = 1200  # MuJoCo steps per second


@dataclass(frozen=True)
class HandPlan:
    """How the hand drives each movable joint in turn.

    goals: per stroke, the target as a fraction of the joint range (0 = lower, 1 = upper); the
    hand tracks q_ref(τ) = q_start + Δ·((1 - α)(3τ² - 2τ³) + α τ²), Δ = q_goal - q_start, for
    τ ∈ [0, 1] over ``push_s`` [s], so it releases the part at q_goal while it still moves at
    2αΔ/push_s (α = ``release_speed``), then lets go for ``free_s`` [s].
    max_force: hand force bound [N].  bandwidth_hz: tracking bandwidth of the hand.
    """

    goals: tuple[float, ...] = (0.6,)
    push_s: float = 0.8
    free_s: float = 2.2
    release_speed: float = 0.3
    max_force: float = 80.0
    bandwidth_hz: float = 4.0

    @property
    def stroke_s(self) -> float:
        return self.push_s + self.free_s


@dataclass(frozen=True, eq=False)
class Episode:
    """A simulated episode sampled at ``record_hz``.

    t: (T,) [s].  joint_names: the n movable joints.  q, v: (T, n) true joint positions and
    velocities.  tau: (T, n) the hand's generalised force on each joint (what a recording calls
    the applied force; concealed forces are not in it).  grip_world: (T, 3) the hand's contact
    point [m] and force_world: (T, 3) its force [N] (zero while released).  link_names: the L
    links.  Ts_world_link: (T, L, 4, 4) true link poses.
    """

    t: np.ndarray
    joint_names: tuple[str, ...]
    q: np.ndarray
    v: np.ndarray
    tau: np.ndarray
    grip_world: np.ndarray
    force_world: np.ndarray
    link_names: tuple[str, ...]
    Ts_world_link: np.ndarray


def _vec(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    w = log_so3(R)
    th = np.linalg.norm(w)
    if th < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(th / 2)], np.sin(th / 2) * w / th])


def mjcf_string(model: ArticulatedModel) -> str:
    """MJCF of ``model`` as it is: joint damping, Coulomb friction (frictionloss), spring
    (stiffness/springref), armature, axis, limits and inertials.  Concealed effects enter by
    passing :func:`effects.true_model` here and the per-step forces to :func:`simulate`."""
    root = ET.Element("mujoco", {"model": model.name})
    ET.SubElement(root, "compiler", {"angle": "radian", "autolimits": "true"})
    ET.SubElement(root, "option", {"timestep": repr(1.0 / SIM_HZ), "gravity": _vec(model.gravity),
                                   "integrator": "implicitfast"})
    world = ET.SubElement(root, "worldbody")
    elems = {model.root.name: world}
    for j in model.joints:
        T = j.T_parent_joint
        body = ET.SubElement(elems[j.parent], "body", {"name": j.child, "pos": _vec(T[:3, 3]),
                                                         "quat": _vec(_quat_wxyz(T[:3, :3]))})
        elems[j.child] = body
        inertial = model.link(j.child).inertial
        if inertial is not None and inertial.mass > 0:
            I = inertial.inertia
            ET.SubElement(body, "inertial", {
                "pos": _vec(inertial.com), "mass": repr(inertial.mass),
                "fullinertia": _vec([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])})
        if not j.is_movable:
            continue
        d = j.dynamics
        attrs = {"name": j.name, "type": "slide" if j.type == "prismatic" else "hinge", "axis": _vec(j.axis),
                 "damping": repr(d.damping), "frictionloss": repr(d.coulomb), "armature": repr(d.armature)}
        if d.spring_stiffness > 0:
            attrs.update(stiffness=repr(d.spring_stiffness), springref=repr(d.spring_rest))
        if j.limits is not None and np.isfinite(j.limits.lower) and np.isfinite(j.limits.upper):
            attrs["range"] = _vec([j.limits.lower, j.limits.upper])
        ET.SubElement(body, "joint", attrs)
    return ET.tostring(root, encoding="unicode")


def axes_world(model: ArticulatedModel) -> dict[str, np.ndarray]:
    """Joint name -> (3,) world axis at q = 0, as MuJoCo places it."""
    mj = mujoco.MjModel.from_xml_string(mjcf_string(model))
    data = mujoco.MjData(mj)
    mujoco.mj_kinematics(mj, data)
    return {n: data.xaxis[mj.joint(n).id].copy() for n in model.joint_names}


class _ForceEffects:
    """Per-step concealed forces (Stribeck, quadratic drag, bias, one-sided stop) on one dof."""

    def __init__(self, effects: dict[str, ConcealedEffect], m_jj: float, dt: float):
        self.e = effects
        if "stribeck_friction" in effects:
            s = effects["stribeck_friction"]
            vs = float(s.param("v_stribeck"))
            # tanh smoothing velocity: small, but large enough for explicit stability (dt·Δ/ε/m < 1/4)
            self.eps = max(vs / 20.0, 4.0 * s.value * dt / m_jj)

    def __call__(self, q: float, v: float) -> float:
        e, f = self.e, 0.0
        if "stribeck_friction" in e:
            s = e["stribeck_friction"]
            f -= s.value * np.exp(-(v / float(s.param("v_stribeck"))) ** 2) * np.tanh(v / self.eps)
        if "quadratic_drag" in e:
            f -= e["quadratic_drag"].value * v * abs(v)
        if "constant_bias" in e:
            f += e["constant_bias"].value
        if "limit_contact" in e:
            c = e["limit_contact"]
            pen = q - c.value if c.param("side") == "upper" else c.value - q
            if pen > 0:
                f -= float(c.param("stiffness")) * (q - c.value)
        return f


def _centred_means(per_step: np.ndarray, decim: int) -> np.ndarray:
    """(S, k) per-step values -> (ceil(S/decim), k) means over the ``decim`` steps centred on
    every ``decim``-th step (windows clipped at the ends)."""
    half = decim // 2
    rows = []
    for c in range(0, per_step.shape[0], decim):
        rows.append(per_step[max(0, c - half) : c - half + decim].mean(axis=0))
    return np.asarray(rows)


def simulate(model: ArticulatedModel, handles: dict[str, Handle], effects: tuple[ConcealedEffect, ...] = (),
             plan: HandPlan = HandPlan(), record_hz: int = 120, q0: np.ndarray | None = None) -> Episode:
    """Run the hand plan on every movable joint in turn (``plan.goals`` strokes each) in MuJoCo,
    on the true system: ``model`` (nominal) with ``effects`` applied.

    handles: joint name -> grip.  record_hz must divide :data:`SIM_HZ`.  q0: (n,) initial joint
    positions (default: lower limits).  Returns the :class:`Episode`, including the hand force.
    """
    if SIM_HZ % record_hz:
        raise ValueError(f"record_hz={record_hz} must divide the simulation rate {SIM_HZ} Hz")
    effects = tuple(effects)
    mj = mujoco.MjModel.from_xml_string(mjcf_string(true_model(model, effects)))
    data = mujoco.MjData(mj)
    names = model.joint_names
    dof = [mj.joint(n).dofadr[0] for n in names]
    qadr = [mj.joint(n).qposadr[0] for n in names]
    lower = np.array([model.joint(n).limits.lower for n in names])
    upper = np.array([model.joint(n).limits.upper for n in names])
    data.qpos[qadr] = lower if q0 is None else q0
    mujoco.mj_forward(mj, data)
    M = np.zeros((mj.nv, mj.nv))
    mujoco.mj_fullM(mj, data, M)
    dt = mj.opt.timestep
    forces = [_ForceEffects({e.type: e for e in effects if e.joint == n}, M[d, d], dt) for n, d in zip(names, dof)]
    body_ids = [mj.body(l).id if l != model.root.name else 0 for l in model.link_names]

    strokes = [(i, g) for i in range(len(names)) for g in plan.goals]
    n_steps = int(round(len(strokes) * plan.stroke_s * SIM_HZ))
    decim = SIM_HZ // record_hz
    rec = {k: [] for k in ("t", "q", "v", "p", "T")}
    taus, forces_world = [], []  # every simulation step
    jacp = np.zeros((3, mj.nv))
    w = 2 * np.pi * plan.bandwidth_hz
    q_start = None
    for step in range(n_steps + 1):
        mujoco.mj_step1(mj, data)  # kinematics, mass matrix and bias forces of the current state
        t = step * dt
        k = int(t // plan.stroke_s)
        tau_s = t - k * plan.stroke_s
        i, goal = strokes[min(k, len(strokes) - 1)]
        h = handles[names[i]]
        body = mj.body(h.link).id
        p_grip = data.xpos[body] + data.xmat[body].reshape(3, 3) @ np.asarray(h.p_link)
        f_world = np.zeros(3)
        tau_hand = np.zeros(len(names))
        if tau_s < 0.5 * dt:
            q_start = data.qpos[qadr[i]]
        if k < len(strokes) and tau_s < plan.push_s:
            s = tau_s / plan.push_s
            q_goal = lower[i] + goal * (upper[i] - lower[i])
            dq, al, T = q_goal - q_start, plan.release_speed, plan.push_s
            q_ref = q_start + dq * ((1 - al) * (3 * s**2 - 2 * s**3) + al * s**2)
            v_ref = dq * ((1 - al) * (6 * s - 6 * s**2) + 2 * al * s) / T
            a_ref = dq * ((1 - al) * (6 - 12 * s) + 2 * al) / T**2
            mujoco.mj_fullM(mj, data, M)
            m = M[dof[i], dof[i]]
            q, v = data.qpos[qadr[i]], data.qvel[dof[i]]
            tau_des = m * (a_ref + w * w * (q_ref - q) + 2 * w * (v_ref - v)) + data.qfrc_bias[dof[i]]
            mujoco.mj_jac(mj, data, jacp, None, p_grip, body)
            g = jacp[:, dof[i]]  # d p_grip / d q_i (3,)
            f_world = g * tau_des / max(g @ g, 1e-12)
            norm = np.linalg.norm(f_world)
            if norm > plan.max_force:
                f_world *= plan.max_force / norm
            tau_hand = np.array([jacp[:, d] @ f_world for d in dof])
        taus.append(tau_hand)
        forces_world.append(f_world)
        if step % decim == 0:
            rec["t"].append(t)
            rec["q"].append(data.qpos[qadr].copy())
            rec["v"].append(data.qvel[dof].copy())
            rec["p"].append(p_grip)
            Ts = np.tile(np.eye(4), (len(body_ids), 1, 1))
            Ts[:, :3, :3] = data.xmat[body_ids].reshape(-1, 3, 3)
            Ts[:, :3, 3] = data.xpos[body_ids]
            rec["T"].append(Ts)
        if step == n_steps:
            break
        data.qfrc_applied[:] = 0.0
        data.qfrc_applied[dof] = tau_hand + [fe(data.qpos[a], data.qvel[d]) for fe, a, d in zip(forces, qadr, dof)]
        mujoco.mj_step2(mj, data)  # forces, constraints and integration
    a = {k: np.asarray(v) for k, v in rec.items()}
    # A force sensor averages over its sample period: record the mean hand force over the
    # simulation steps centred on each sample, so replaying the samples (linearly interpolated)
    # delivers the impulse the hand really applied, even through its fast feedback transients.
    a["tau"] = _centred_means(np.asarray(taus), decim)
    a["f"] = _centred_means(np.asarray(forces_world), decim)
    return Episode(a["t"], names, a["q"], a["v"], a["tau"], a["p"], a["f"], model.link_names, a["T"])
