"""The "real robot": a MuJoCo arm that the estimators never see, driven at 1 kHz.

Two real Pandas: :func:`concealed_panda` (the nominal URDF with hidden changes to inertias,
armature, damping and friction) and :func:`kitchen_panda` (the independently authored Franka
Kitchen Panda MJCF from the ``gymnasium-robotics`` wheel, inertias from its meshes).
Recorded torques are the motor torques MuJoCo actually applied (after effort clipping), plus
sensor noise.  Everything here is in the nominal model's joint coordinates (``q`` of the URDF);
:class:`RealArm` maps them to MuJoCo's ``qpos`` with a per-joint offset.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata as md
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from ..errors import DataError, InputFileError, ModelError
from ..io.recording import Recording
from ..model import ArticulatedModel, Inertial, JointDynamics
from .mjcf import model_to_mjcf

#: A controller: (t [s], q (n,) [rad], v (n,) [rad/s], k sample index) -> commanded torque (n,) [N·m].
Controller = Callable[[float, np.ndarray, np.ndarray, int], np.ndarray]


@dataclass(frozen=True, eq=False)
class SensorNoise:
    """Standard deviations of white Gaussian measurement noise: q [rad], v [rad/s], tau [N·m]."""

    q: float = 1e-4
    v: float = 2e-3
    tau: float = 0.05


@dataclass(eq=False)
class RealArm:
    """A MuJoCo arm.  ``joint_names`` are the nominal names in q order; MuJoCo joint
    ``mj_joint_names[i]`` has ``qpos = q[i] + q_offset[i]``; ``actuator_names[i]`` drives it."""

    name: str
    mj_model: mujoco.MjModel
    joint_names: tuple[str, ...]
    mj_joint_names: tuple[str, ...]
    actuator_names: tuple[str, ...]
    q_offset: np.ndarray

    def __post_init__(self):
        m = self.mj_model
        self._qadr = np.array([m.joint(n).qposadr[0] for n in self.mj_joint_names])
        self._vadr = np.array([m.joint(n).dofadr[0] for n in self.mj_joint_names])
        self._act = np.array([m.actuator(n).id for n in self.actuator_names])

    @property
    def dt(self) -> float:
        """Simulation and control period [s]."""
        return float(self.mj_model.opt.timestep)

    @property
    def q_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower (n,), upper (n,)) joint ranges in nominal coordinates [rad]."""
        r = np.array([self.mj_model.joint(n).range for n in self.mj_joint_names])
        return r[:, 0] - self.q_offset, r[:, 1] - self.q_offset

    def reset(self, q: np.ndarray, v: np.ndarray) -> mujoco.MjData:
        """A fresh MjData at state (q (n,) [rad], v (n,) [rad/s])."""
        data = mujoco.MjData(self.mj_model)
        data.qpos[self._qadr] = np.asarray(q) + self.q_offset
        data.qvel[self._vadr] = v
        mujoco.mj_forward(self.mj_model, data)
        return data

    def state(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """True (q (n,) [rad], v (n,) [rad/s])."""
        return data.qpos[self._qadr] - self.q_offset, data.qvel[self._vadr].copy()

    def step(self, data: mujoco.MjData, tau: np.ndarray) -> np.ndarray:
        """Command torques tau (n,) [N·m] for one step; returns the torque actually applied."""
        data.ctrl[self._act] = tau
        mujoco.mj_step(self.mj_model, data)
        return data.actuator_force[self._act].copy()


def run_controller(
    arm: RealArm,
    t: np.ndarray,
    q0: np.ndarray,
    v0: np.ndarray,
    controller: Controller,
    noise: SensorNoise | None = None,
    seed: int = 0,
) -> tuple[Recording, Recording]:
    """Run ``controller`` on ``arm`` at the sample times ``t`` (T,) [s] (spacing must equal ``arm.dt``).

    The controller sees the measured state (true + noise).  Returns (measured, true): recordings
    of q, v and the applied torque tau, with and without sensor noise, time-major (T, n)."""
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2 or not np.allclose(np.diff(t), arm.dt, rtol=1e-6, atol=1e-9):
        raise DataError(f"run_controller needs times spaced by the simulation step {arm.dt} s")
    rng = np.random.default_rng(seed)
    n = len(arm.joint_names)
    Q, V, TAU = (np.empty((t.size, n)) for _ in range(3))
    noise = noise or SensorNoise(0.0, 0.0, 0.0)
    data = arm.reset(q0, v0)
    for k, tk in enumerate(t):
        q, v = arm.state(data)
        Q[k], V[k] = q, v
        qm = q + noise.q * rng.standard_normal(n)
        vm = v + noise.v * rng.standard_normal(n)
        TAU[k] = arm.step(data, controller(tk, qm, vm, k))
    if not np.all(np.isfinite(Q)):
        raise DataError(f"the MuJoCo simulation of {arm.name!r} diverged")
    true = Recording(t, arm.joint_names, Q, V, TAU)
    measured = Recording(
        t,
        arm.joint_names,
        Q + noise.q * rng.standard_normal(Q.shape),
        V + noise.v * rng.standard_normal(V.shape),
        TAU + noise.tau * rng.standard_normal(TAU.shape),
    )
    return measured, true


def pd_feedforward(plan: Recording, kp: np.ndarray, kd: np.ndarray) -> Controller:
    """tau = plan.tau[k] + kp (q_d - q) + kd (v_d - v): gains (n,) [N·m/rad], [N·m·s/rad]."""
    if plan.v is None or plan.tau is None:
        raise DataError("a tracking plan needs v and tau columns")
    kp, kd = np.asarray(kp, dtype=float), np.asarray(kd, dtype=float)
    return lambda t, q, v, k: plan.tau[k] + kp * (plan.q[k] - q) + kd * (plan.v[k] - v)


def record_plan(
    arm: RealArm,
    plan: Recording,
    kp: np.ndarray,
    kd: np.ndarray,
    noise: SensorNoise | None = None,
    seed: int = 0,
) -> Recording:
    """Drive ``arm`` along ``plan`` (q, v, nominal tau) with PD + feedforward; the measured recording."""
    plan = plan.select(arm.joint_names)
    measured, _ = run_controller(arm, plan.t, plan.q[0], plan.v[0], pd_feedforward(plan, kp, kd), noise, seed)
    return measured


# --- the two real Pandas ----------------------------------------------------------------------


def conceal_changes(nominal: ArticulatedModel, seed: int = 0, spread: float = 0.3) -> ArticulatedModel:
    """The hidden truth: ``nominal`` with every link's mass and rotational inertia scaled by
    independent factors in [1 - spread, 1 + spread], its centre of mass moved up to 1 cm, and per
    joint armature 0.05–0.3 kg·m², damping 0.5–3 N·m·s/rad, Coulomb friction 0.3–2 N·m
    (smaller on joints whose effort limit is under 20 N·m)."""
    rng = np.random.default_rng(seed)
    out = nominal
    for link in nominal.links:
        i = link.inertial
        if i is None or i.mass <= 0:
            continue
        s_m, s_i = rng.uniform(1 - spread, 1 + spread, 2)
        out = out.with_link(
            link.name, inertial=Inertial(i.mass * s_m, i.com + rng.uniform(-0.01, 0.01, 3), i.inertia * s_i)
        )
    for j in nominal.movable_joints:
        small = j.limits is not None and j.limits.effort < 20
        scale = 0.3 if small else 1.0
        dyn = JointDynamics(
            damping=scale * rng.uniform(0.5, 3.0),
            coulomb=scale * rng.uniform(0.3, 2.0),
            armature=scale * rng.uniform(0.05, 0.3),
        )
        out = out.with_joint(j.name, dynamics=dyn)
    return out


def arm_from_model(model: ArticulatedModel, timestep: float = 1e-3) -> RealArm:
    """A RealArm simulating ``model`` exactly (its inertias and JointDynamics) in MuJoCo."""
    mj = mujoco.MjModel.from_xml_string(model_to_mjcf(model, timestep))
    names = model.joint_names
    return RealArm(model.name, mj, names, names, names, np.zeros(len(names)))


def concealed_panda(nominal: ArticulatedModel, seed: int = 0) -> tuple[RealArm, ArticulatedModel]:
    """Real robot (a): the nominal Panda converted to MJCF with :func:`conceal_changes`.
    Returns (arm, hidden truth model)."""
    truth = dataclasses.replace(conceal_changes(nominal, seed), name="panda_concealed")
    return arm_from_model(truth), truth


KITCHEN_DIR_IN_DIST = "gymnasium_robotics/envs/assets/kitchen_franka/franka_assets"
#: qpos of the Kitchen Panda = q of the example-robot-data URDF + offset: its link6 and link7
#: body frames are turned about the joint axis by pi/2 and pi/4 relative to the URDF's.
KITCHEN_Q_OFFSET = np.array([0.0, 0.0, 0.0, 0.0, 0.0, -np.pi / 2, -np.pi / 4])
#: Joint dynamics given to the Kitchen Panda instead of its authored damping (100 N·m·s/rad on
#: joints 1–4, 10 on 5–7: at 1 rad/s that alone exceeds the 87 / 12 N·m effort limits).
KITCHEN_DYNAMICS = (
    JointDynamics(damping=2.0, coulomb=1.2, armature=0.18),
    JointDynamics(damping=2.5, coulomb=1.5, armature=0.20),
    JointDynamics(damping=1.5, coulomb=1.0, armature=0.15),
    JointDynamics(damping=1.8, coulomb=1.3, armature=0.15),
    JointDynamics(damping=0.4, coulomb=0.4, armature=0.05),
    JointDynamics(damping=0.5, coulomb=0.3, armature=0.05),
    JointDynamics(damping=0.3, coulomb=0.25, armature=0.03),
)
_EFFORT = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)


def kitchen_assets_dir() -> Path:
    """Folder of the Franka Kitchen Panda MJCF (chain.xml, assets.xml, meshes/) in gymnasium-robotics."""
    try:
        path = Path(md.distribution("gymnasium-robotics").locate_file(KITCHEN_DIR_IN_DIST))
    except md.PackageNotFoundError:
        raise InputFileError("the Kitchen Panda comes from the pip package gymnasium-robotics, not installed") from None
    if not (path / "chain.xml").is_file():
        raise InputFileError(f"gymnasium-robotics is installed but {KITCHEN_DIR_IN_DIST}/chain.xml is missing")
    return path


def kitchen_mjcf(dynamics=KITCHEN_DYNAMICS, timestep: float = 1e-3) -> str:
    """MJCF text of the Kitchen Panda arm: its bodies, masses and meshes (inertia from geometry),
    fingers welded, contacts off, motor actuators with the Franka effort limits, and the given
    per-joint ``dynamics`` (7 JointDynamics) replacing the authored joint damping."""
    d = kitchen_assets_dir()
    assets = ET.parse(d / "assets.xml").getroot()
    chain = ET.parse(d / "chain.xml").getroot()
    for mesh in assets.iter("mesh"):
        mesh.set("file", str(d / "meshes" / mesh.get("file")))
    root = ET.Element("mujoco", {"model": "panda_kitchen"})
    ET.SubElement(root, "compiler", {"angle": "radian", "autolimits": "true"})
    opt = ET.SubElement(root, "option", {"timestep": repr(float(timestep))})
    ET.SubElement(opt, "flag", {"contact": "disable"})
    root.append(assets.find("asset"))
    root.append(assets.find("default"))
    world = ET.SubElement(root, "worldbody")
    world.append(chain.find("body"))
    for body in world.iter("body"):
        for joint in list(body.findall("joint")):
            if "finger" in joint.get("name"):
                body.remove(joint)
    actuators = ET.SubElement(root, "actuator")
    for i, dyn in enumerate(dynamics, start=1):
        name = f"robot:panda0_joint{i}"
        joint = next(j for j in world.iter("joint") if j.get("name") == name)
        joint.attrib.update(damping=repr(dyn.damping), frictionloss=repr(dyn.coulomb), armature=repr(dyn.armature))
        ET.SubElement(
            actuators, "motor", {"name": f"motor{i}", "joint": name, "gear": "1",
                                 "forcerange": f"{-_EFFORT[i - 1]} {_EFFORT[i - 1]}"}
        )
    return ET.tostring(root, encoding="unicode")


def kitchen_panda(nominal_joint_names, dynamics=KITCHEN_DYNAMICS, timestep: float = 1e-3) -> RealArm:
    """Real robot (b): the Franka Kitchen Panda, in the nominal URDF's joint coordinates
    (``nominal_joint_names``: the 7 arm joints in q order)."""
    names = tuple(nominal_joint_names)
    if len(names) != 7:
        raise ModelError(f"the Kitchen Panda has 7 arm joints; got names {names}")
    mj = mujoco.MjModel.from_xml_string(kitchen_mjcf(dynamics, timestep))
    mj_names = tuple(f"robot:panda0_joint{i}" for i in range(1, 8))
    return RealArm("panda_kitchen", mj, names, mj_names, tuple(f"motor{i}" for i in range(1, 8)), KITCHEN_Q_OFFSET.copy())
