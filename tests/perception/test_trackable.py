"""Which tracks can relate to a joint (perception.perceive._trackable): a door or drawer sampled at
2 frames a second moves too far between samples for the local-quadratic jitter to follow, and is
kept because one world screw explains its track; a track that jumps between surfaces is not."""

from __future__ import annotations

import numpy as np
import pytest

from factories import motion_about
from kinemaforge_opt.perception.perceive import _jitter, _trackable
from kinemaforge_opt.perception.track import ICP_FINE_VOXELS, Proposal

VOXEL = 0.0072  # [m] a 640x480 voxel at ~2 m
LIMIT = ICP_FINE_VOXELS * VOXEL
TIMES = np.arange(12) / 1.8  # [s] 12 samples at 1.8 frames a second
# (N, 3) a fridge door [m]: 0.6 m wide (+x from its hinge at x = 0), 5 cm thick, 1 m tall
DOOR = np.random.default_rng(3).uniform([0.0, -0.05, 0.0], [0.6, 0.0, 1.0], (800, 3))
HINGE = np.zeros(3)


def _noisy(poses: list[np.ndarray], mm: float = 2.0) -> np.ndarray:
    """(T, 4, 4) the poses with ``mm`` [mm] of translation noise per coordinate and 0.1° of turn
    (the same noise whichever test runs first)."""
    rng = np.random.default_rng(4)
    out = []
    for T in poses:
        turn = rng.normal(scale=np.radians(0.1), size=3)
        out.append(motion_about(turn, rng.normal(scale=mm * 1e-3, size=3), DOOR.mean(axis=0)) @ T)
    return np.stack(out)


def _door(angles_deg) -> Proposal:
    poses = [motion_about((0.0, 0.0, np.radians(a)), about=HINGE) for a in angles_deg]
    return Proposal("door", 0, DOOR, _noisy(poses))


def test_a_door_swung_between_sparse_samples_is_kept():
    """At rest for six samples, then 13° → 57° → 80° in two samples (protocol_refrigerator_1@s14
    at 12 frames: the door was lost)."""
    door = _door([0, 0, 0, 0, 0, 0, 13, 57, 80, 92, 89, 86])
    assert _jitter(door) > LIMIT  # the jitter holds the motion itself
    assert [p.name for p in _trackable([door], TIMES, VOXEL)] == ["door"]


def test_a_drawer_pulled_between_sparse_samples_is_kept():
    shifts = [0.0] * 6 + [0.02, 0.15, 0.32, 0.40, 0.40, 0.39]
    drawer = Proposal("drawer", 0, DOOR, _noisy([motion_about(t=(0.0, -d, 0.0)) for d in shifts]))
    assert _jitter(drawer) > LIMIT
    assert [p.name for p in _trackable([drawer], TIMES, VOXEL)] == ["drawer"]


@pytest.mark.parametrize("every", [2, 3])
def test_a_track_that_jumps_between_surfaces_is_dropped(every):
    """The door's track put, at every ``every``-th sample, on another surface: turned a quarter
    about its own long axis and 30 cm off."""
    door = _door([0, 0, 0, 0, 0, 0, 13, 57, 80, 92, 89, 86])
    jumped = door.Ts_delta.copy()
    elsewhere = motion_about((np.pi / 2, 0.0, 0.0), (0.0, 0.3, 0.0), DOOR.mean(axis=0))
    jumped[::every] = jumped[::every] @ elsewhere
    assert _trackable([Proposal("door", 0, DOOR, jumped)], TIMES, VOXEL) == []


def test_a_smooth_track_is_kept_and_a_short_one_dropped():
    smooth = _door(np.linspace(0.0, 90.0, 30))
    short = Proposal("short", 0, DOOR, np.concatenate([smooth.Ts_delta[:4], np.full((26, 4, 4), np.nan)]))
    times = np.arange(30) / 5.0
    assert _jitter(smooth) <= LIMIT
    assert [p.name for p in _trackable([smooth, short], times, VOXEL)] == ["door"]
