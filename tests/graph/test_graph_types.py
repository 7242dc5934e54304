"""Joint-type decisions on noisy synthetic tracks whose truth is known by construction: small
angles, pure translations, orientations flipped by a shape symmetry, outlier frames, no motion."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinemaforge_opt.errors import DataError
from kinemaforge_opt.graph import fit_all, infer_tree, relative_motion, score_pair
from kinemaforge_opt.io.tracks import PoseTracks
from kinemaforge_opt.spatial import axis_angle_error, make_transform, screw_motion, translation_motion

from .tracks import noisy_track

T = 20
SIGMA_P = 1.5e-3  # position noise per coordinate [m]
SIGMA_R = np.radians(0.5)  # rotation noise per coordinate [rad]
HINGE = np.array([0.0, 0.0, 1.0])
RAIL = np.array([0.0, -1.0, 0.05]) / np.linalg.norm([0.0, -1.0, 0.05])


def _noisy(poses, seed, flip=None):
    return noisy_track(poses, np.random.default_rng(seed), SIGMA_P, SIGMA_R, flip)


def _tracks(*tracks):
    names = tuple(f"p{i}" for i in range(len(tracks)))
    return PoseTracks(np.arange(T) / 10.0, names, np.array([p for p, _ in tracks]), np.array([r for _, r in tracks]))


def _door(angles, width=0.4):
    """A door panel's centroid frame, half a width from a vertical hinge through (0.3, 0.1, 0.2)."""
    return [screw_motion(HINGE, np.array([0.3, 0.1, 0.2]), a) @ make_transform(p=(0.3 + width / 2, 0.1, 0.2)) for a in angles]


def _drawer(stroke=0.3):
    return [translation_motion(RAIL, d) @ make_transform(p=(0.2, 0.0, 0.3)) for d in np.linspace(0.0, stroke, T)]


def _best(hyps):
    return max(hyps.values(), key=lambda h: h.confidence)


@pytest.mark.parametrize("seed", range(3))
def test_small_angle_revolute_is_revolute(seed):
    """A door opened by 12° only (its centroid moves 4 cm on an arc of 2 mm sagitta, barely
    above the noise) is still a hinge: its rotation is 24 times the rotation noise.  The axis is
    noise-limited here (0.5° rotation noise over a 12° swing: 1–4° on these seeds), so its bound
    only rules out a wrong line."""
    tracks = _tracks(_noisy(_door(np.linspace(0.0, np.radians(12.0), T)), seed))
    best = _best(score_pair(fit_all(relative_motion(tracks, None, 0))))
    assert best.type == "revolute"
    assert np.degrees(axis_angle_error(best.axis_world, HINGE)) < 8.0


@pytest.mark.parametrize("seed", range(3))
def test_noisy_translation_is_prismatic(seed):
    (j,) = infer_tree(_tracks(_noisy(_drawer(), seed))).best.joints
    assert j.type == "prismatic"
    assert np.degrees(axis_angle_error(j.hypothesis.axis_world, RAIL)) < 3.0


def test_translation_between_two_moving_parts_is_prismatic():
    """A tray sliding 15 cm in a drawer that itself slides 30 cm: the tray's motion relative to
    the drawer is a pure translation plus noise, never a hinge or a screw."""
    drawer = _drawer()
    tray_rail = np.array([1.0, 0.0, 0.0])
    tray = [X @ translation_motion(tray_rail, d) @ make_transform(p=(0.0, 0.0, 0.05)) for X, d in zip(drawer, np.linspace(0.0, 0.15, T))]
    tracks = _tracks(_noisy(drawer, 0), _noisy(tray, 1))
    best = _best(score_pair(fit_all(relative_motion(tracks, 0, 1))))
    assert best.type == "prismatic"
    assert np.degrees(axis_angle_error(best.axis_parent, tray_rail)) < 3.0


def test_translation_with_flipped_orientations_is_prismatic():
    """A drawer front registered turned by π about its normal on the last third of the frames:
    the orientation jumps, the centroid does not.  A hinge 'explaining' the jump misses the
    straight path; the joint is prismatic."""
    mask = np.arange(T) >= 2 * T // 3
    (j,) = infer_tree(_tracks(_noisy(_drawer(), 5, flip=(mask, np.pi * RAIL)))).best.joints
    assert j.type == "prismatic"
    assert np.degrees(axis_angle_error(j.hypothesis.axis_world, RAIL)) < 3.0


@pytest.mark.parametrize("first", [3, 10])
def test_door_with_flipped_orientations_is_revolute(first):
    """A flat door registered turned by π about its own vertical centre line from frame
    ``first`` on (a microwave door at 640×480): the centroid still traces the hinge's arc."""
    mask = np.arange(T) >= first
    poses = _door(np.linspace(0.0, 1.6, T))
    (j,) = infer_tree(_tracks(_noisy(poses, first, flip=(mask, np.pi * HINGE)))).best.joints
    assert j.type == "revolute"
    assert np.degrees(axis_angle_error(j.hypothesis.axis_world, HINGE)) < 3.0


def test_drawer_with_one_outlier_frame_is_prismatic():
    """One frame registered 7 cm off and turned by 26° (a gross outlier) must not make a 25 cm
    stroke look like rest: the drawer is prismatic, not merged into the base."""
    P, R = _noisy(_drawer(0.25), 7)
    P[4] += [0.0, 0.0, 0.07]
    R[4] = Rotation.from_rotvec([np.radians(26.0), 0.0, 0.0]).as_matrix() @ R[4]
    (j,) = infer_tree(_tracks((P, R))).best.joints
    assert j.type == "prismatic"
    assert np.degrees(axis_angle_error(j.hypothesis.axis_world, RAIL)) < 3.0


def test_barely_moving_part_is_no_motion():
    """A part that creeps 1 mm (below the 1.5 mm noise) over the recording: 'no motion'."""
    poses = [translation_motion(RAIL, d) @ make_transform(p=(0.2, 0.0, 0.3)) for d in np.linspace(0.0, 1e-3, T)]
    with pytest.raises(DataError, match="no motion"):
        infer_tree(_tracks(_noisy(poses, 2)))


@pytest.mark.parametrize("seed", range(3))
def test_turning_door_under_smooth_registration_error_is_not_rigid(seed):
    """A door turning 80° over 60 samples, registered with 0.6 mm jitter plus a smooth 3 cm
    error (one moving camera's drift): the residuals are strongly autocorrelated, the χ² scale
    collapses towards 1/N, and the parameter count alone once made the door rigid.  The rigid
    fit turns 0.4 rad away from the track where the hinge's stays within 0.06 rad: rigid is
    shown inadequate and is no candidate."""
    n = 60
    rng = np.random.default_rng(seed)
    poses = [screw_motion(HINGE, np.array([0.3, 0.1, 0.2]), a) @ make_transform(p=(0.5, 0.1, 0.2))
             for a in np.linspace(0.0, np.radians(80.0), n)]
    P, R = noisy_track(poses, rng, 6e-4, np.radians(0.1))
    t = np.arange(n) / n
    P = P + 0.03 * np.stack([np.sin(2 * np.pi * t), np.cos(3 * np.pi * t), np.sin(np.pi * t)], axis=1)
    tracks = PoseTracks(np.arange(n) / 10.0, ("p0",), P[None], R[None])
    hyps = score_pair(fit_all(relative_motion(tracks, None, 0)))
    assert hyps["rigid"].confidence == 0.0
    (j,) = infer_tree(tracks).best.joints
    assert j.type == "revolute"
    assert np.degrees(axis_angle_error(j.hypothesis.axis_world, HINGE)) < 5.0
