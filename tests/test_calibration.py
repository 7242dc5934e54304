"""calibrate(): estimates vs an independent ground truth (MuJoCo), intervals, identifiability,
named terms, non-convergence as a state, and errors that name the culprit."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.calibration import calibrate
from kinemaforge_opt.errors import DataError, UnknownNameError
from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.nlp.joint_space import build_joint_space_fit
from kinemaforge_opt.spatial import axis_angle_error
from kinemaforge_opt.synth.effects import ConcealedEffect, true_model
from kinemaforge_opt.synth.groundtruth import HandPlan, simulate
from kinemaforge_opt.synth.objects import make_object

NOISE = 2e-3


@pytest.fixture(scope="module")
def door_case():
    """A MuJoCo door with a 3° hinge tilt, damping 0.2 and Coulomb 0.3 unknown to the model."""
    obj = make_object("cabinet", 0)
    j = obj.model.joint_names[0]
    effects = (
        ConcealedEffect("axis_tilt", j, np.deg2rad(3.0), (("azimuth", 0.6),)),
        ConcealedEffect("viscous_damping", j, 0.2),
        ConcealedEffect("coulomb_friction", j, 0.3),
    )
    ep = simulate(obj.model, obj.handles, effects, plan=HandPlan(goals=(0.5,), push_s=0.8, free_s=1.7, release_speed=0.15), record_hz=30)
    rng = np.random.default_rng(1)
    rec = Recording(ep.t, ep.joint_names, ep.q + rng.normal(0, NOISE, ep.q.shape), tau=ep.tau)
    return obj.model, rec, j, true_model(obj.model, effects).joint(j).axis


@pytest.mark.parametrize("energy", ["soft", "hard"])
def test_recovers_hidden_axis_damping_friction(door_case, energy):
    model, rec, j, true_axis = door_case
    cal = calibrate(model, rec, free=[f"{j}.axis", f"{j}.damping", f"{j}.coulomb"], energy=energy)
    assert cal.success, cal.status
    assert np.rad2deg(axis_angle_error(cal.estimates[f"{j}.axis"].value, true_axis)) < 0.2
    for name, truth in ((f"{j}.damping", 0.2), (f"{j}.coulomb", 0.3)):
        e = cal.estimates[name]
        assert e.ci95_low[0] <= truth <= e.ci95_high[0], (name, e)
        assert abs(e.value[0] - truth) < 0.25 * truth
    assert max(cal.rms_q.values()) < 1.5 * NOISE  # fits to the noise level
    assert cal.model.joint(j).dynamics.coulomb == pytest.approx(cal.estimates[f"{j}.coulomb"].value[0])


def test_free_response_cannot_separate_friction_from_inertia(door_case):
    """Without applied forces, scaling inertia and all forces together leaves the motion
    unchanged: the report must say so in words."""
    model, rec, j, _ = door_case
    release = rec.t >= 0.8 + 2 / 30
    free_rec = Recording(rec.t[release], rec.joint_names, rec.q[release])
    child = model.joint(j).child
    cal = calibrate(model, free_rec, free=[f"{j}.damping", f"{j}.coulomb", f"{child}.inertia"])
    text = " ".join(cal.identifiability)
    assert "cannot determine" in text and f"{child}.inertia" in text and f"{j}.coulomb" in text


def test_problem_can_be_inspected_before_solving(door_case):
    model, rec, j, _ = door_case
    fit = build_joint_space_fit(model, rec, (f"{j}.axis", f"{j}.damping"), energy="hard")
    terms = fit.problem.terms
    assert terms["costs"] == ["output_q"]
    assert set(terms["constraints"]) == {"dynamics", "energy_books", "energy", f"unit_axis:{j}"}
    assert fit.problem.sizes["variables"] == 2 * rec.t.size + 4 + rec.t.size  # x, axis + damping, books


def test_non_convergence_is_a_state_not_an_exception(door_case):
    model, rec, j, _ = door_case
    cal = calibrate(model, rec, free=[f"{j}.axis", f"{j}.damping", f"{j}.coulomb"], max_iter=1)
    assert not cal.success and "Maximum" in cal.status


def test_bad_input_names_the_culprit(door_case):
    model, rec, j, _ = door_case
    with pytest.raises(UnknownNameError, match=rf"free parameter '{j}\.dampin' does not exist; available: .*'{j}\.damping'"):
        calibrate(model, rec, free=[f"{j}.dampin"])
    still = Recording(rec.t, rec.joint_names, np.zeros_like(rec.q))
    with pytest.raises(DataError, match="no motion"):
        calibrate(model, still)
    other = Recording(rec.t, ("elbow",), rec.q)
    with pytest.raises(UnknownNameError, match=r"joint \(recorded\) 'elbow' does not exist; available: "):
        calibrate(model, other)
    from kinemaforge_opt.model import read_urdf

    cabinet = read_urdf("models/cabinet/cabinet.urdf")
    door_only = Recording(rec.t, ("door_hinge",), rec.q)
    with pytest.raises(DataError, match=r"no q column for joint\(s\) \['drawer_slide'\]"):
        calibrate(cabinet, door_only)


@pytest.mark.parametrize("field, true", [("damping", 0.02), ("coulomb", 0.03)])
def test_a_lid_resting_shut_under_its_weight_is_fitted_from_where_it_leaves_its_stop(field, true):
    """The model has no law for the stop it declares: fitted over the seconds the lid rested shut
    under its weight, the damping came out 0.099 for 0.02 and the friction 0.042 for 0.03."""
    from factories import lid_lifted_off_its_stop

    model, rec = lid_lifted_off_its_stop({field: true})
    cal = calibrate(model, rec, free=[f"{model.joint_names[0]}.{field}"])
    assert cal.success, cal.status
    assert cal.estimates[f"{model.joint_names[0]}.{field}"].value[0] == pytest.approx(true, rel=0.03)
    assert cal.recording.t[0] > 0.5 and "s of the 6.47-s recording was fitted" in cal.identifiability[0]
