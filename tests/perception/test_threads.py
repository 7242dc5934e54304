"""The perception stages on one thread and on two give the same answer."""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest

from kinemaforge_opt.io.sequence import load_sequence


@pytest.mark.parametrize("case", ["tiny_door_clean", "tiny_moving"])  # static cameras; a moving camera
def test_perception_is_the_same_on_one_thread_and_on_two(case, tmp_path, monkeypatch):
    """The threaded stages map independent frames, steps and cameras: the clouds, statuses and
    tracks must not depend on how many threads ran them (static cameras take the per-pixel status
    path, a moving camera the free-space tests between time steps)."""
    from kinemaforge_opt.perception.perceive import static_cameras
    from kinemaforge_opt.synth import generate_case
    from problems.catalogue import get_case

    perceive = sys.modules["kinemaforge_opt.perception.perceive"].perceive
    paths = generate_case(dataclasses.replace(get_case(case), frames=10), tmp_path / case)
    seq = load_sequence(paths.sequence)
    assert static_cameras(seq, seq.times) == (case == "tiny_door_clean")
    runs = []
    for n in ("1", "2"):
        monkeypatch.setenv("OMP_NUM_THREADS", n)
        runs.append(perceive(seq))
    one, two = runs
    assert len(one.proposals) == len(two.proposals) >= 1
    for a, b in zip(one.proposals, two.proposals):
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.Ts_delta, b.Ts_delta)
    for ca, cb, sa, sb in zip(one.clouds, two.clouds, one.status, two.status):
        np.testing.assert_array_equal(ca.points, cb.points)
        np.testing.assert_array_equal(sa, sb)
