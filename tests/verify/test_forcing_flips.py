"""Joint values from tracks whose orientation turns over: a tracker may register a symmetric part
(a door slab, a drawer front) half a turn off, while the track's position stays on the part.  The
joint values must follow the true joint motion (analytic: the tracks are built from it)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation
from verify_models import cabinet, slider

from kinemaforge_opt.io.tracks import PoseTracks
from kinemaforge_opt.model.pinocchio import build_pin_model
from kinemaforge_opt.verify.forcing import joint_values


def _tracks(model, q, offsets, flips):
    """Tracks of ``model``'s moving links for the joint values q (T, n): link frame moved by
    ``offsets[link]`` (3,) [m] (a track's origin is a point of the part, not the joint frame),
    right-multiplied by ``flips[link]`` (3, 3) at the steps ``flips[link]`` marks."""
    pm = build_pin_model(model, check_dynamics=False)
    data = pm.createData()
    links = [j.child for j in model.joints]
    T = len(q)
    P, R = np.empty((len(links), T, 3)), np.empty((len(links), T, 3, 3))
    for s in range(T):
        pin.framesForwardKinematics(pm, data, q[s])
        for k, link in enumerate(links):
            X = data.oMf[pm.getFrameId(link)]
            P[k, s] = X.act(offsets[link])
            F, steps = flips.get(link, (np.eye(3), np.zeros(T, dtype=bool)))
            R[k, s] = X.rotation @ (F if steps[s] else np.eye(3))
    return PoseTracks(np.arange(T) * 0.1, tuple(links), P, R), {n: [n] for n in links}


def _half_turn(axis) -> np.ndarray:
    return Rotation.from_rotvec(np.pi * np.asarray(axis, float) / np.linalg.norm(axis)).as_matrix()


def test_a_door_track_turned_over_about_its_hinge_direction_keeps_its_joint_value():
    """The door (tilted hinge, on a moving drawer) is tracked from its middle, 0.2 m off the hinge;
    from step 6 on its orientation is half a turn off about the hinge direction."""
    model = cabinet()
    T = 15
    t = np.linspace(0.0, 1.0, T)
    q = np.column_stack([0.3 * t, 1.4 * np.sin(1.5 * t)])  # slide [m], hinge [rad] (beyond π/2)
    steps = np.arange(T) >= 6
    tracks, links = _tracks(model, q, {"drawer": np.array([0.1, 0.0, 0.05]), "door": np.array([0.2, 0.0, 0.3])},
                            {"door": (_half_turn([0, 0.2, 1]), steps)})
    jv = joint_values(model, tracks, links)
    np.testing.assert_allclose(jv.q, q - q[jv.zero_step], atol=1e-9)


def test_a_door_track_turned_over_across_its_hinge_is_read_from_its_position():
    """Turned over about an axis across the hinge (the door's width direction) at the odd steps
    from step 3: R_D then holds no rotation about the hinge; the origin's sweep gives q, exactly
    when the model's hinge is the true one."""
    model = cabinet()
    T = 15
    t = np.linspace(0.0, 1.0, T)
    q = np.column_stack([0.3 * t, 1.8 * t])
    steps = (np.arange(T) >= 3) & (np.arange(T) % 2 == 1)
    tracks, links = _tracks(model, q, {"drawer": np.array([0.1, 0.0, 0.05]), "door": np.array([0.2, 0.0, 0.3])},
                            {"door": (_half_turn([1, 0, 0]), steps)})
    jv = joint_values(model, tracks, links)
    np.testing.assert_allclose(jv.q, q - q[jv.zero_step], atol=1e-9)
    assert jv.observed.all()


def test_a_turned_over_step_of_a_track_on_the_hinge_line_counts_as_unobserved():
    """Origin on the hinge: the position cannot tell the angle, so a step turned over across the
    hinge is dropped and filled by interpolation (q linear in time: exactly)."""
    model = cabinet()
    T = 12
    q = np.column_stack([np.zeros(T), np.linspace(0.0, 1.2, T)])
    steps = np.arange(T) == 5
    tracks, links = _tracks(model, q, {"drawer": np.zeros(3), "door": np.zeros(3)}, {"door": (_half_turn([1, 0, 0]), steps)})
    jv = joint_values(model, tracks, links)
    np.testing.assert_allclose(jv.q, q, atol=1e-9)
    assert np.flatnonzero(~jv.observed[:, 1]).tolist() == [5]


def test_a_drawer_track_turned_over_keeps_its_joint_value():
    """A slider tracked 0.15 m off its frame's origin, turned over about its own z from step 4."""
    model = slider()
    T = 10
    q = np.linspace(0.0, 0.4, T)[:, None]
    steps = np.arange(T) >= 4
    tracks, links = _tracks(model, q, {"cart": np.array([0.15, 0.05, 0.0])}, {"cart": (_half_turn([0, 0, 1]), steps)})
    jv = joint_values(model, tracks, links)
    np.testing.assert_allclose(jv.q, q, atol=1e-9)


def test_a_track_on_the_hinge_line_is_read_from_its_orientation():
    """Origin on the hinge (as MuJoCo's link frames are): the position says nothing about the
    angle, the orientation (not turned over) gives it, q > π/2 included."""
    model = cabinet()
    T = 12
    q = np.column_stack([np.zeros(T), np.linspace(0.0, 2.5, T)])
    tracks, links = _tracks(model, q, {"drawer": np.zeros(3), "door": np.zeros(3)}, {})
    jv = joint_values(model, tracks, links)
    np.testing.assert_allclose(jv.q, q, atol=1e-9)
