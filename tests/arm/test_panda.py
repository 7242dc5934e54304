"""The nominal Panda and the two MuJoCo "real" Pandas."""

import numpy as np
import pinocchio as pin

from kinemaforge_opt.arm.mujoco_real import concealed_panda, kitchen_panda, record_plan
from kinemaforge_opt.arm.excitation import excitation_plan, model_limits, random_fourier
from kinemaforge_opt.arm.panda import load_panda
from kinemaforge_opt.model.pinocchio import build_pin_model


def test_nominal_panda_has_seven_arm_joints():
    m = load_panda()
    assert m.joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))


def test_kitchen_panda_kinematics_match_the_urdf():
    m = load_panda()
    pm = build_pin_model(m)
    pd = pm.createData()
    arm = kitchen_panda(m.joint_names)
    rng = np.random.default_rng(0)
    lo, hi = arm.q_limits
    for _ in range(5):
        q = rng.uniform(np.maximum(lo, -2.0), np.minimum(hi, 2.0))
        pin.forwardKinematics(pm, pd, q)
        data = arm.reset(q, np.zeros(7))
        for i in range(1, 8):
            body = arm.mj_model.body(f"panda0_link{i}").id
            np.testing.assert_allclose(data.xpos[body], pd.oMi[i].translation, atol=5e-4)
        # link 6 frame orientation pins the joint-6 offset (kitchen uses 1.57 for pi/2)
        R6 = data.xmat[arm.mj_model.body("panda0_link6").id].reshape(3, 3)
        np.testing.assert_allclose(R6, pd.oMi[6].rotation, atol=3e-3)


def test_concealed_panda_differs_and_records_a_plan():
    m = load_panda()
    arm, truth = concealed_panda(m, seed=0)
    masses = [(l.inertial.mass, truth.link(l.name).inertial.mass) for l in m.links if l.inertial and l.inertial.mass > 0]
    assert any(abs(a / b - 1) > 0.1 for a, b in masses)
    assert all(j.dynamics.coulomb > 0 and j.dynamics.armature > 0 for j in truth.movable_joints)
    plan = excitation_plan(m, random_fourier(7, model_limits(m), 0.2, seed=1), 0.5)
    rec = record_plan(arm, plan, np.full(7, 600.0), np.full(7, 40.0), seed=0)
    assert rec.joint_names == m.joint_names and rec.tau.shape == (501, 7)
    assert np.max(np.abs(rec.q - plan.q)) < 0.05
