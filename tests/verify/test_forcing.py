"""Joint values from part tracks and wrenches mapped to joint forces, checked against MuJoCo's own
joint record (the synthetic world's recording.csv: true q and the hand's J^T f from MuJoCo)."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.errors import DataError
from kinemaforge_opt.io.recording import read_recording
from kinemaforge_opt.io.sequence import Wrenches, read_wrenches
from kinemaforge_opt.io.tracks import PoseTracks, read_tracks
from kinemaforge_opt.model import read_urdf
from kinemaforge_opt.synth.case import Case
from kinemaforge_opt.synth.effects import ConcealedEffect
from kinemaforge_opt.synth.generate import generate_case
from kinemaforge_opt.verify.forcing import joint_recording, joint_values, map_wrenches, window_means


def small_case(category: str, effects=()) -> Case:
    """24 time steps of one 3 s push-and-release stroke, rendered tiny (only tracks/wrenches are used)."""
    return Case(f"small_{category}", category, 0, tuple(effects), views=1, frames=24, width=16, height=12)


@pytest.fixture(scope="module")
def door(tmp_path_factory):
    return generate_case(small_case("cabinet", (ConcealedEffect("viscous_damping", "door_joint", 0.8),)),
                         tmp_path_factory.mktemp("door"), workers=1)


@pytest.fixture(scope="module")
def drawer(tmp_path_factory):
    return generate_case(small_case("drawer"), tmp_path_factory.mktemp("drawer"), workers=1)


def _inputs(paths):
    model = read_urdf(paths.model_urdf)
    tracks = read_tracks(paths.tracks)
    return model, tracks, {n: [n] for n in tracks.names}, read_wrenches(paths.sequence / "wrenches.csv")


@pytest.fixture(scope="module")
def two_joints(tmp_path_factory):
    """A door and a drawer on one cabinet: the hand pushes one, then the other."""
    return generate_case(small_case("cabinet_multi"), tmp_path_factory.mktemp("multi"), workers=1)


@pytest.mark.parametrize("which", ["door", "drawer", "two_joints"])
def test_joint_values_and_forces_match_mujoco(which, request):
    paths = request.getfixturevalue(which)
    model, tracks, links, wrenches = _inputs(paths)
    truth = read_recording(paths.recording)
    jr = joint_recording(model, tracks, links, wrenches)
    rec = jr.recording
    q_true = np.column_stack([np.interp(rec.t, truth.t, truth.q[:, k]) for k in range(model.nq)])
    q_true -= q_true[jr.values.zero_step]  # the reconstruction's q is 0 at the zero step
    np.testing.assert_allclose(rec.q, q_true, atol=1e-9)
    assert np.ptp(rec.q) > 0.05  # the joint really moved
    # the hand's force mapped through Pinocchio = MuJoCo's J^T f, row by row
    scale = np.abs(truth.tau).max()
    assert scale > 1.0
    np.testing.assert_allclose(jr.wrenches.tau, truth.tau, atol=1e-3 * scale)
    # one contact per stroke, each on the link its joint moves
    assert [link for _, _, link in jr.wrenches.contacts] == [j.child for j in model.movable_joints]
    # the windowed means keep the impulse of the push: ∫τ dt agrees to 5 % (the windows are half
    # as wide at both ends, as the trapezoid rule weights them)
    impulse_true = np.trapezoid(truth.tau, truth.t, axis=0)
    impulse_rec = np.trapezoid(rec.tau, rec.t, axis=0)
    np.testing.assert_allclose(impulse_rec, impulse_true, rtol=0.05)
    # the full-rate forcing starts with the recording
    assert jr.forcing.t[0] == rec.t[0]


def test_window_means_are_means_over_the_nearest_rows():
    t_in = np.arange(10) * 0.1
    values = np.arange(10.0)[:, None]
    out = window_means(np.array([0.0, 0.5, 0.9]), t_in, values)
    # windows: [-0.25, 0.25) -> 0,1,2 ; [0.25, 0.7) -> 3..6 ; [0.7, 1.1) -> 7,8,9
    np.testing.assert_allclose(out[:, 0], [1.0, 4.5, 8.0])


def test_a_still_contact_goes_to_the_link_under_it(door):
    """Nothing moves: the point's spread is zero on every link, the link's cloud decides."""
    model, tracks, links, _ = _inputs(door)
    p_door = np.array([0.3, -0.05, 0.4])
    t = np.linspace(0, 1, 5)
    w = Wrenches(t, np.tile(p_door, (5, 1)), np.tile([0.0, 5.0, 0.0], (5, 1)))
    q = np.zeros((2, model.nq))
    clouds = {"door": p_door[None, :] + 0.01, "body": np.array([[-1.0, 0.0, 0.0]])}
    mapped = map_wrenches(model, np.array([0.0, 1.0]), q, w, clouds)
    assert [c[2] for c in mapped.contacts] == ["door"]
    clouds = {"door": np.array([[5.0, 5.0, 5.0]]), "body": p_door[None, :]}
    mapped = map_wrenches(model, np.array([0.0, 1.0]), q, w, clouds)
    assert [c[2] for c in mapped.contacts] == ["body"] and np.all(mapped.tau == 0)  # the base takes it


def test_a_jump_or_a_pause_starts_a_new_contact(door):
    model, *_ = _inputs(door)
    t = np.arange(6) * 0.01
    P = np.array([[0.3, 0, 0.4]] * 3 + [[0.3, 0.5, 0.4]] * 3)
    F = np.tile([0.0, 1.0, 0.0], (6, 1))
    F[4] = 0.0
    mapped = map_wrenches(model, np.array([0.0, 1.0]), np.zeros((2, 1)), Wrenches(t, P, F))
    assert [(a, b) for a, b, _ in mapped.contacts] == [(0, 2), (3, 3), (5, 5)]
    assert np.all(mapped.tau[4] == 0)


def test_errors_name_the_link_and_the_joint(door):
    model, tracks, links, _ = _inputs(door)
    with pytest.raises(DataError, match="link 'door' has no tracks listed"):
        joint_values(model, tracks, {"body": ["body"]})
    with pytest.raises(DataError, match=r"link 'door': none of its tracks \['ghost'\]"):
        joint_values(model, tracks, {"body": ["body"], "door": ["ghost"]})
    k = tracks.names.index("door")
    P = tracks.positions.copy()
    R = tracks.Rs_world_track.copy()
    P[k, 1:] = np.nan
    R[k, 1:] = np.nan
    once = PoseTracks(tracks.times, tracks.names, P, R)
    with pytest.raises(DataError, match="joint 'door_joint'.*1 time step"):
        joint_values(model, once, links)
    with pytest.raises(DataError, match="position-only"):
        joint_values(model, PoseTracks(tracks.times, tracks.names, tracks.positions), links)


def test_values_span_only_the_steps_where_every_joint_is_measured(two_joints):
    """The drawer's track starts at step 5 and ends at step 18 (hidden before and after): the values
    span steps 5..18, where they are MuJoCo's q; a held value before or after would be no measurement."""
    model, tracks, links, wrenches = _inputs(two_joints)
    k = tracks.names.index("drawer")
    P, R = tracks.positions.copy(), tracks.Rs_world_track.copy()
    P[k, :5] = P[k, 19:] = np.nan
    R[k, :5] = R[k, 19:] = np.nan
    late = PoseTracks(tracks.times, tracks.names, P, R)
    jr = joint_recording(model, late, links, wrenches)
    np.testing.assert_array_equal(jr.recording.t, tracks.times[5:19])
    assert jr.values.zero_step == 0 and jr.values.observed.all()
    assert jr.forcing.t[0] == tracks.times[5]  # the replay starts at the first measured step
    truth = read_recording(two_joints.recording)
    q_true = np.column_stack([np.interp(jr.recording.t, truth.t, truth.q[:, j]) for j in range(model.nq)])
    np.testing.assert_allclose(jr.recording.q, q_true - q_true[0], atol=1e-9)


def test_joints_measured_together_at_one_step_only_is_a_named_error(two_joints):
    model, tracks, links, _ = _inputs(two_joints)
    P, R = tracks.positions.copy(), tracks.Rs_world_track.copy()
    for name, seen in (("door", slice(0, 2)), ("drawer", slice(1, 3))):
        k = tracks.names.index(name)
        hide = np.ones(tracks.times.size, dtype=bool)
        hide[seen] = False
        P[k, hide] = np.nan
        R[k, hide] = np.nan
    with pytest.raises(DataError, match="door_joint, drawer_joint are measured together at fewer than 2 time steps"):
        joint_values(model, PoseTracks(tracks.times, tracks.names, P, R), links)


def test_joints_never_measured_together_are_each_zero_where_their_part_was_placed(two_joints):
    """The door's track ends at step 9 and the drawer's starts at step 10 (a part tracked in
    halves, a drawer hidden while the door is seen): no step sees both.  The door's q is 0 at step
    0, the drawer's at step 10 (the nearest step that sees it), and both are MuJoCo's q from there."""
    model, tracks, links, _ = _inputs(two_joints)
    P, R = tracks.positions.copy(), tracks.Rs_world_track.copy()
    for name, hidden in (("door", slice(10, None)), ("drawer", slice(0, 10))):
        k = tracks.names.index(name)
        P[k, hidden] = np.nan
        R[k, hidden] = np.nan
    values = joint_values(model, PoseTracks(tracks.times, tracks.names, P, R), links)
    assert values.zero_t == {"door_joint": tracks.times[0], "drawer_joint": tracks.times[10]}
    truth = read_recording(two_joints.recording)
    for k, name in enumerate(model.joint_names):
        q_true = np.interp(values.t, truth.t, truth.q[:, k]) - np.interp(values.zero_t[name], truth.t, truth.q[:, k])
        seen = values.observed[:, k]
        assert seen.sum() >= 10
        np.testing.assert_allclose(values.q[seen, k], q_true[seen], atol=1e-9)
    assert np.ptp(values.q[values.observed[:, 1], 1]) > 0.05  # the drawer moved while it was seen


def test_measured_joint_values_replace_the_tracks_at_the_steps_they_observe(two_joints):
    """A measurement of the door's joint (as a reconstruction's visual fit gives, in the model's own
    coordinates: here MuJoCo's q 0.02 rad off the tracks' zero) replaces the door's values where its
    track is observed; where it is not, the measured values are interpolated, as the tracks' are.
    The drawer, not in the measurement, keeps its tracks' values."""
    from kinemaforge_opt.io.recording import Recording

    model, tracks, links, wrenches = _inputs(two_joints)
    truth = read_recording(two_joints.recording)
    k = tracks.names.index("door")
    P, R = tracks.positions.copy(), tracks.Rs_world_track.copy()
    P[k, 7] = R[k, 7] = np.nan  # the door unseen at step 7
    hidden = PoseTracks(tracks.times, tracks.names, P, R)
    door_q = np.interp(tracks.times, truth.t, truth.q[:, 0]) + 0.02
    measured_door = door_q.copy()
    measured_door[7] += 0.5  # not a measurement of the door's track: left out
    measured = Recording(tracks.times, ("door_joint",), measured_door[:, None])
    values = joint_values(model, hidden, links, measured)
    seen = np.arange(tracks.times.size) != 7
    np.testing.assert_allclose(values.q[seen, 0], door_q[seen], atol=1e-9)
    assert values.q[7, 0] == pytest.approx(np.interp(tracks.times[7], tracks.times[seen], door_q[seen]))
    assert not values.observed[7, 0] and values.observed[:7, 0].all()
    plain = joint_values(model, hidden, links)
    np.testing.assert_array_equal(values.q[:, 1], plain.q[:, 1])
    # a measurement that lacks a time step of the tracks is a named error
    short = Recording(tracks.times[:-1], ("door_joint",), door_q[:-1, None])
    with pytest.raises(DataError, match=r"no sample at t = .* of the tracks \(joint 'door_joint'\)"):
        joint_values(model, hidden, links, short)
    # and one that names a joint the model lacks too
    stray = Recording(tracks.times, ("door_joint", "lid_joint"), np.column_stack([door_q, door_q]))
    with pytest.raises(DataError, match="name 'lid_joint', not a movable joint of the model; its joints: door_joint, drawer_joint"):
        joint_values(model, hidden, links, stray)


def test_the_joint_values_source_names_the_joints_the_measurement_lacks():
    from kinemaforge_opt.io.recording import Recording
    from kinemaforge_opt.verify.reconstruction import joint_values_source

    door_only = Recording(np.arange(3.0), ("door_joint",), np.zeros((3, 1)))
    assert joint_values_source(("door_joint", "drawer_joint"), None) == "tracks.csv"
    assert joint_values_source(("door_joint",), door_only).startswith("measured_q.csv: the visual fit")
    assert "tracks.csv" not in joint_values_source(("door_joint",), door_only)
    assert joint_values_source(("door_joint", "drawer_joint"), door_only).endswith(
        "; tracks.csv for drawer_joint (not in measured_q.csv)")
