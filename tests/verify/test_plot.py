"""The replay plot: a replay that runs far past its recording also shows the recorded span alone."""

from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np

from kinemaforge_opt.verify.plot import plot_trajectories
from kinemaforge_opt.verify.simulate import Trajectory


def _replay(duration_s: float) -> Trajectory:
    t = np.linspace(0.0, duration_s, 200)
    q = np.sin(t)[:, None]
    return Trajectory(t, ("j0",), q, np.cos(t)[:, None], 0.5 * np.cos(t) ** 2, 0.0)


def test_a_long_replay_gets_a_column_zoomed_on_the_recording(tmp_path):
    t_rec = np.linspace(0.0, 3.0, 20)
    q_rec = np.sin(t_rec)[:, None]
    short = mpimg.imread(plot_trajectories(tmp_path / "short.png", _replay(3.0), t_rec, q_rec))
    long = mpimg.imread(plot_trajectories(tmp_path / "long.png", _replay(50.0), t_rec, q_rec))
    assert short.shape[0] == long.shape[0]
    assert long.shape[1] > 1.4 * short.shape[1]  # the recorded span beside the whole replay
