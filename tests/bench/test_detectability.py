"""The oracle ΔBIC on MuJoCo recordings of the concealed-effects set (the truth is the
catalogue's; the recording is the independent simulator's)."""

import numpy as np

from kinemaforge_opt.bench.detectability import oracle_delta_bic
from kinemaforge_opt.bench.recordings import effect_recording
from kinemaforge_opt.physics.selection import DELTA_BIC


def test_a_visible_damping_is_supported_far_beyond_the_selection_margin():
    assert oracle_delta_bic(effect_recording("effect_door_viscous_damping")) < 10 * DELTA_BIC


def test_stribeck_excess_on_quick_strokes_does_not_show_in_the_recording():
    # two 0.8-s pushes pass through the Stribeck regime (|v| < 0.1 rad/s) in a fraction of a
    # second: even the true law, fitted from its true values, gains less than the margin
    assert oracle_delta_bic(effect_recording("effect_door_stribeck_friction")) >= DELTA_BIC


def test_null_case_has_no_oracle():
    assert oracle_delta_bic(effect_recording("null_door")) is None


def _exact_law_prediction_error(case_name: str, t_end: float) -> float:
    """RMS error [m or rad] of the true concealed law (the simulator's own per-step force),
    integrated (LSODA) from the true state under the hand force the simulator applied, against
    the MuJoCo trajectory over [0, t_end] s: how predictable the recording is for any
    output-error fit, with nothing estimated."""
    import mujoco
    from scipy.integrate import solve_ivp

    from kinemaforge_opt.synth.groundtruth import SIM_HZ, _ForceEffects, mjcf_string, simulate
    from kinemaforge_opt.synth.objects import make_object
    from problems.catalogue import get_case

    case = get_case(case_name)
    obj = make_object(case.category, case.seed)
    ep = simulate(obj.model, obj.handles, case.effects, plan=case.plan, record_hz=SIM_HZ)
    (effect,) = case.effects
    k = ep.joint_names.index(effect.joint)
    mj = mujoco.MjModel.from_xml_string(mjcf_string(obj.model))
    data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, data)
    M = np.zeros((mj.nv, mj.nv))
    mujoco.mj_fullM(mj, data, M)
    dof = mj.joint(effect.joint).dofadr[0]
    m = M[dof, dof]  # a single prismatic or hinge dof: constant inertia
    law = _ForceEffects({effect.type: effect}, m, 1.0 / SIM_HZ)
    s = ep.t <= t_end
    t, tau = ep.t[s], ep.tau[s, k]
    sol = solve_ivp(lambda tt, x: [x[1], (np.interp(tt, t, tau) + law(x[0], x[1])) / m], (0.0, t[-1]),
                    [ep.q[0, k], ep.v[0, k]], method="LSODA", t_eval=t, rtol=1e-9, atol=1e-12, max_step=1.0 / SIM_HZ)
    return float(np.sqrt(np.mean((sol.y[0] - ep.q[s, k]) ** 2)))


def test_a_slow_push_through_a_steep_stribeck_drop_is_unpredictable_even_for_the_true_law():
    # The drawer's Stribeck excess (3 N on 5.1 kg, v_s 0.02 m/s) falls with speed at up to
    # F sqrt(2) e^-1/2 / v_s = 129 N s/m: under the recorded force the model is open-loop unstable
    # at about 25 /s, and the 3-s push near v_s grows any error by e^60.  Even the exact law, from
    # the exact state, under the exact 1200-Hz force, then misses the MuJoCo motion by far more
    # than the 2-mm encoder noise, so no output-error fit can show the effect (oracle ΔBIC above
    # the margin); the door's slow push (growth about e^7.5 per stroke) stays within the noise.
    noise = 2e-3
    assert _exact_law_prediction_error("effect_drawer_stribeck_friction_slow_push", 4.0) > 10 * noise
    assert _exact_law_prediction_error("effect_door_stribeck_friction_slow_push", 4.0) < noise
