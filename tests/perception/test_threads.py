"""The perception stages' thread pool: order, errors, and the same answer on one thread as on two."""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest

from kinemaforge_opt.io.sequence import load_sequence
from kinemaforge_opt.perception.threads import thread_map, workers


def test_thread_map_keeps_order_and_raises_the_first_error(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    assert workers() == 2
    assert thread_map(lambda x: x * x, range(50)) == [x * x for x in range(50)]

    def fail(x):
        if x == 7:
            raise ValueError("item 7 is bad")
        return x

    with pytest.raises(ValueError, match="item 7 is bad"):
        thread_map(fail, range(20))


def test_workers_read_openmp_settings(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "3,2")  # a nested OpenMP list: the first level counts
    assert workers() == 3
    monkeypatch.setenv("OMP_NUM_THREADS", "")  # unset in effect: the CPUs this process may use
    assert workers() >= 1
    monkeypatch.setenv("OMP_NUM_THREADS", "0")  # not a thread count: ignored the same way
    assert workers() >= 1


def test_one_thread_when_the_batch_runner_asks_for_it(monkeypatch):
    import threading

    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    main = threading.get_ident()
    assert set(thread_map(lambda _: threading.get_ident(), range(8))) == {main}


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
