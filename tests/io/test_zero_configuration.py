"""The zero configuration of a tree from its tracks when no time step sees every part
(``io.tracks.zero_configuration``): each link's zero pose is its parent's composed with the
two tracks' relative pose at one real time step."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinemaforge_opt.errors import DataError
from kinemaforge_opt.io.tracks import PoseTracks, zero_configuration

STEPS = 10


def _tracks(seen: dict[str, range]) -> PoseTracks:
    """Random full-pose tracks, one per name, observed only at the steps ``seen[name]``."""
    rng = np.random.default_rng(3)
    names = tuple(seen)
    P = rng.normal(size=(len(names), STEPS, 3))
    R = Rotation.random(len(names) * STEPS, random_state=4).as_matrix().reshape(len(names), STEPS, 3, 3)
    for k, name in enumerate(names):
        hidden = np.ones(STEPS, dtype=bool)
        hidden[list(seen[name])] = False
        P[k, hidden] = np.nan
        R[k, hidden] = np.nan
    return PoseTracks(np.arange(STEPS, dtype=float), names, P, R)


def _reps(tracks: PoseTracks) -> dict[str, int | None]:
    return {"base": None, **{n: k for k, n in enumerate(tracks.names)}}


def test_every_link_seen_at_one_step_takes_its_pose_there():
    tracks = _tracks({"door": range(2, 10), "drawer": range(4, 10)})
    zero = zero_configuration(tracks, _reps(tracks), {"door": "base", "drawer": "base"})
    assert zero.step == 4 and zero.steps == {"door": 4, "drawer": 4}
    for k, name in enumerate(tracks.names):
        np.testing.assert_array_equal(zero.poses[name], tracks.Ts_world_track(k)[4])


def test_a_link_unseen_at_the_zero_step_takes_its_pose_at_the_nearest_step_it_is_seen():
    """Two drawers never seen at once (one track ends at step 4, the other starts at 6)."""
    tracks = _tracks({"upper": range(0, 5), "lower": range(6, 10)})
    zero = zero_configuration(tracks, _reps(tracks), {"upper": "base", "lower": "base"})
    assert zero.step == 0 and zero.steps == {"upper": 0, "lower": 6}
    np.testing.assert_array_equal(zero.poses["lower"], tracks.Ts_world_track(1)[6])


def test_a_child_takes_its_relative_pose_at_the_step_its_parent_was_placed():
    """A lid (on a body part seen at steps 5-9) seen at every step, and a door seen at 0-4: the
    zero step is 0, where the body is not seen.  The body's pose comes from step 5, and so does
    the lid's relative to it, so that q = 0 is a configuration the object took, not the lid at
    step 0 on the body at step 5."""
    tracks = _tracks({"body": range(5, 10), "lid": range(0, 10), "door": range(0, 5)})
    zero = zero_configuration(tracks, _reps(tracks), {"body": "base", "lid": "body", "door": "base"})
    assert zero.step == 0 and zero.steps == {"body": 5, "lid": 5, "door": 0}
    np.testing.assert_allclose(zero.poses["lid"], tracks.Ts_world_track(1)[5], atol=1e-12)
    np.testing.assert_allclose(np.linalg.inv(zero.poses["body"]) @ zero.poses["lid"],
                               np.linalg.inv(tracks.Ts_world_track(0)[5]) @ tracks.Ts_world_track(1)[5], atol=1e-12)


def test_a_link_never_seen_with_its_parent_is_a_named_error():
    tracks = _tracks({"body": range(0, 5), "lid": range(5, 10)})
    with pytest.raises(DataError, match="link 'lid' is never seen together with its parent 'body'"):
        zero_configuration(tracks, _reps(tracks), {"body": "base", "lid": "body"})
