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


def plot_trajectories(
    path: str | os.PathLike,
    simulated: Trajectory,
    recorded_t: np.ndarray | None = None,
    recorded_q: np.ndarray | None = None,
    title: str = "",
) -> Path:
    """One panel per joint: simulated q(t) (line) over recorded q(t) (dots), times in s; a last
    panel shows the simulated energy.  Written atomically to ``path`` (PNG)."""
    n = len(simulated.joint_names)
    fig, axes = plt.subplots(n + 1, 1, figsize=(8, 2.2 * (n + 1)), sharex=True, squeeze=False)
    for j, name in enumerate(simulated.joint_names):
        ax = axes[j, 0]
        if recorded_q is not None:
            ax.plot(recorded_t, recorded_q[:, j], ".", ms=2, color="0.3", label="recorded")
        ax.plot(simulated.t, simulated.q[:, j], "-", lw=1.2, color="tab:blue", label="Drake")
        ax.set_ylabel(f"q:{name}")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[0, 0].set_title(title, fontsize=10)
    ax = axes[n, 0]
    ax.plot(simulated.t, simulated.energy - simulated.energy[0], color="tab:red")
    ax.set_ylabel("E − E(0) [J]")
    ax.set_xlabel("t [s]")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return path
