"""PNG plot of recorded vs simulated joint trajectories (matplotlib, Agg backend, no display)."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..io.atomic import atomic_path  # noqa: E402
from .simulate import Trajectory  # noqa: E402


ZOOM_FACTOR = 1.5
"""A replay longer than this many times the recording gets a second column zoomed on the
recorded span (the 50-s horizons otherwise squeeze the recording into a sliver)."""


def plot_trajectories(
    path: str | os.PathLike,
    simulated: Trajectory,
    recorded_t: np.ndarray | None = None,
    recorded_q: np.ndarray | None = None,
    title: str = "",
) -> Path:
    """One panel per joint: simulated q(t) (line) over recorded q(t) (dots), times in s; a last
    panel shows the simulated energy.  When the replay runs on well past the recording, a left
    column shows the recorded span (5 % margin) and the right one the whole replay.  Written
    atomically to ``path`` (PNG)."""
    n = len(simulated.joint_names)
    zoom = recorded_t is not None and simulated.t[-1] > ZOOM_FACTOR * recorded_t[-1] > 0
    cols = 2 if zoom else 1
    fig, axes = plt.subplots(n + 1, cols, figsize=(8 + 4 * (cols - 1), 2.2 * (n + 1)), sharex="col", squeeze=False)
    for c in range(cols):
        for j, name in enumerate(simulated.joint_names):
            ax = axes[j, c]
            if recorded_q is not None:
                ax.plot(recorded_t, recorded_q[:, j], ".", ms=2 if c == cols - 1 else 4, color="0.3", label="recorded")
            ax.plot(simulated.t, simulated.q[:, j], "-", lw=1.2, color="tab:blue", label="Drake")
            ax.grid(alpha=0.3)
        ax = axes[n, c]
        ax.plot(simulated.t, simulated.energy - simulated.energy[0], color="tab:red")
        ax.set_xlabel("t [s]")
        ax.grid(alpha=0.3)
    for j, name in enumerate(simulated.joint_names):
        axes[j, 0].set_ylabel(f"q:{name}")
    axes[n, 0].set_ylabel("E − E(0) [J]")
    axes[0, cols - 1].legend(loc="upper right", fontsize=8)
    if zoom:
        span = float(recorded_t[-1] - recorded_t[0])
        axes[n, 0].set_xlim(recorded_t[0] - 0.05 * span, recorded_t[-1] + 0.05 * span)
        axes[0, 0].set_title("the recorded span", fontsize=10)
        axes[0, 1].set_title("the whole replay", fontsize=10)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return path
