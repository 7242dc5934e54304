"""The shared hypothesis NLP (physics.search) and what diagnose finds with it: derivatives
assembled per interval equal CasADi's automatic ones on the whole problem; concealed effects in
MuJoCo (limit stop, drawer tilt) are found with values near the truth."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.model import parse_urdf, urdf_string
from kinemaforge_opt.nlp.joint_space import match_recording, noise_std
from kinemaforge_opt.physics.diagnose import CANDIDATES, diagnose
from kinemaforge_opt.physics.search import HypothesisFit, effect_parameters
from kinemaforge_opt.synth.effects import ConcealedEffect as E
from kinemaforge_opt.synth.groundtruth import HandPlan, simulate
from kinemaforge_opt.synth.objects import make_object

NOISE = 2e-3
PLAN = HandPlan(goals=(0.5, 0.3), push_s=0.8, free_s=1.7, release_speed=0.15)


def _recording(category: str, effects, seed: int = 0):
    obj = make_object(category, seed)
    joint = obj.model.joint_names[0]
    ep = simulate(obj.model, obj.handles, effects(joint), plan=PLAN, record_hz=30)
    q = ep.q + np.random.default_rng(seed).normal(0, NOISE, ep.q.shape)
    return obj.model, joint, Recording(ep.t, ep.joint_names, q, tau=ep.tau)


def _point(hf, nlp, rng):
    """A decision vector of ``nlp``: states from the data, every free parameter away from nominal
    (so every term is active)."""
    nxG = nlp.nx * nlp.G
    w = np.concatenate([hf.x_init.ravel(order="F"), np.zeros(nlp.nz)])
    for b in nlp.blocks:
        sl = slice(nxG + nlp.z_offsets[b.name], nxG + nlp.z_offsets[b.name] + b.size)
        w[sl] = hf.nominal_z(b.name) + 0.2 * rng.normal(size=b.size)
    return w


@pytest.mark.parametrize("subset", [False, True])
def test_assembled_derivatives_equal_automatic_ones(subset):
    model, joint, rec = _recording("cabinet", lambda j: (E("viscous_damping", j, 0.8),))
    rec = match_recording(model, rec).window(0.0, 1.5)
    hf = HypothesisFit(model, rec, [(joint, c) for c in CANDIDATES], sigma_q=noise_std(rec.q))
    free = [n for c in ("coulomb_friction", "axis_tilt") for n in effect_parameters(model, joint, c)] \
        if subset else tuple(hf.blocks)
    nlp = hf.nlp_for(free)
    rng = np.random.default_rng(1)
    w = _point(hf, nlp, rng)
    lam_g = rng.normal(size=nlp.ng)
    x = ca.MX.sym("x", w.size)
    lg = ca.MX.sym("lg", nlp.ng)
    oracle = nlp.solver.oracle()(x=x, p=ca.MX(0, 1))
    lagrangian = 0.7 * oracle["f"] + ca.dot(lg, oracle["g"])
    H_auto = ca.Function("h", [x, lg], [ca.hessian(lagrangian, x)[0]])(w, lam_g).full()
    J_auto = ca.Function("j", [x], [ca.jacobian(oracle["g"], x)])(w).full()
    H = nlp.solver.get_function("nlp_hess_l")(w, [], 0.7, lam_g).full()
    _, J = nlp.solver.get_function("nlp_jac_g")(w, [])
    assert np.allclose(np.triu(H), np.triu(H_auto), rtol=1e-9, atol=1e-9 * np.abs(H_auto).max())
    assert np.allclose(J.full(), J_auto, rtol=1e-12, atol=1e-12)


def test_a_problem_with_fewer_free_parameters_is_the_full_one_at_nominal():
    """The problem of a subset (other blocks folded in as constants) has the same objective and
    defects as the problem with every block free, evaluated with those blocks at nominal."""
    model, joint, rec = _recording("cabinet", lambda j: (E("viscous_damping", j, 0.8),))
    rec = match_recording(model, rec).window(0.0, 1.5)
    hf = HypothesisFit(model, rec, [(joint, c) for c in CANDIDATES], sigma_q=noise_std(rec.q))
    sub = hf.nlp_for(effect_parameters(model, joint, "stribeck_friction"))
    full = hf.nlp_for(tuple(hf.blocks))
    w_sub = _point(hf, sub, np.random.default_rng(2))
    nxG = sub.nx * sub.G
    w_full = np.concatenate([w_sub[:nxG], np.zeros(full.nz)])
    for name, b in hf.blocks.items():
        o = nxG + full.z_offsets[name]
        w_full[o: o + b.size] = w_sub[nxG + sub.z_offsets[name]: nxG + sub.z_offsets[name] + b.size] \
            if name in sub.z_offsets else hf.nominal_z(name)
    f_sub = sub.solver.oracle()(x=w_sub, p=[])
    f_full = full.solver.oracle()(x=w_full, p=[])
    assert float(f_sub["f"]) == pytest.approx(float(f_full["f"]), rel=1e-12)
    g_sub, g_full = f_sub["g"].full().ravel(), f_full["g"].full().ravel()
    assert sub.ng == full.ng - 1  # the fixed axis' unit-norm row is gone
    assert np.allclose(g_sub, g_full[: sub.ng], rtol=1e-12, atol=1e-12)
    assert np.abs(g_sub).max() > 1e-3  # the point is not a trivial solution


def test_a_fixed_out_effect_is_absent_and_a_freed_one_is_recovered():
    model, joint, rec = _recording("cabinet", lambda j: (E("viscous_damping", j, 0.8),))
    rec = match_recording(model, rec).window(0.0, 3.7)
    hf = HypothesisFit(model, rec, [(joint, c) for c in CANDIDATES if c != "axis_tilt"], sigma_q=noise_std(rec.q))
    nominal = hf.solve([])
    assert all(np.allclose(nominal.values[n], hf.blocks[n].nominal) for n in hf.blocks)
    damped = hf.solve(effect_parameters(model, joint, "viscous_damping"), start=nominal)
    assert damped.success
    assert damped.values[f"{joint}.damping"][0] == pytest.approx(0.8, rel=0.05)
    assert np.sqrt(np.mean((damped.q_fit - rec.q) ** 2)) < 1.5 * NOISE


def test_finds_a_hidden_stop_where_the_recording_turns():
    model, joint, rec = _recording("cabinet", lambda j: (E("limit_contact", j, 1.2, (("stiffness", 60.0), ("side", "upper"))),))
    d = diagnose(model, rec)
    assert [e.type for e in d.effects] == ["limit_contact"], d.summary()
    assert d.effects[0].value == pytest.approx(1.2, abs=0.02)
    # the augmented model holds the stop (an upper one, with its stiffness), through a URDF too
    dyn = d.model.joint(joint).dynamics
    assert (dyn.limit_stop, dyn.limit_side) == (pytest.approx(1.2, abs=0.02), 1.0) and dyn.limit_stiffness > 0
    assert parse_urdf(urdf_string(d.model)).joint(joint).dynamics == dyn
    # the stop passed the simulation check like any effect: the model holds it, and it simulates
    # the fit span better than the nominal model
    (check,) = [t for t in d.tested if "simulation_check" in t]
    assert check["simulation_check"] == [f"limit_contact on {joint}"]
    before, after = check["fit_span_simulated_rms"]
    assert after < before / 3, (before, after)


def test_prismatic_tilt_is_reported_with_its_equivalent_bias():
    """On a prismatic joint a tilted axis adds only the constant gravity force m g sin(tilt) along
    it: in joint space it is a constant bias.  diagnose reports one with the other as an equivalent
    explanation, and the tilt it names matches the concealed one."""
    model, joint, rec = _recording("drawer", lambda j: (E("axis_tilt", j, 0.03, (("azimuth", 0.0),)),))
    d = diagnose(model, rec)
    assert len(d.effects) == 1, d.summary()
    e = d.effects[0]
    cls = {e.type: e.value, **{a["type"]: a["value"] for a in e.params.get("equivalent", ())}}
    assert {"constant_bias", "axis_tilt"} <= set(cls), d.summary()
    assert cls["axis_tilt"] == pytest.approx(0.03, rel=0.1)
    mass = model.link(model.joint(joint).child).inertial.mass
    assert abs(cls["constant_bias"]) == pytest.approx(mass * 9.81 * np.sin(0.03), rel=0.1)


def test_linear_prescreen_keeps_the_concealed_effects():
    """With the inverse-dynamics pre-screen only 4 of a round's 18 hypotheses (a door and a
    drawer) get an NLP fit; the concealed damping and Coulomb friction of the MuJoCo door are
    still the ones found.  (A one-joint round is fitted whole whatever ``screen`` says.)"""
    model, joint, rec = _recording("cabinet_multi", lambda j: (E("coulomb_friction", j, 0.4),
                                                               E("viscous_damping", j, 0.8)))
    d = diagnose(model, rec, screen=4)
    found = {e.type: e.value for e in d.effects}
    assert set(found) == {"coulomb_friction", "viscous_damping"}, d.summary()
    assert found["coulomb_friction"] == pytest.approx(0.4, rel=0.1)
    assert found["viscous_damping"] == pytest.approx(0.8, rel=0.1)
    assert {e.joint for e in d.effects} == {joint}
    assert sum("type" in t for t in d.tested) < 9 * 2  # fewer fits than one full round

