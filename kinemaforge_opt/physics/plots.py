"""PNG plots of a diagnosis (matplotlib, Agg backend): where the residual sits and how the fit
improves."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..io.atomic import atomic_path  # noqa: E402
from .diagnose import Diagnosis  # noqa: E402
from .locate import inverse_dynamics_residual  # noqa: E402


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path


def _broken(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``y`` with NaN where the samples jump over a gap (> 1.5 median steps: the state window of
    a segment is fitted, not predicted), so that a line is not drawn across it."""
    gap = np.diff(t, prepend=t[0]) > 1.5 * np.median(np.diff(t))
    return np.where(gap, np.nan, y)


def _before_after(h, names, title: str, recorded: str, path: Path) -> Path:
    """One panel per joint: the recorded q of a :class:`~kinemaforge_opt.physics.predict.HeldOut`
    and the nominal and augmented predictions, broken where a piece's fitted state window was cut."""
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 2.6 * len(names)), squeeze=False)
    for k, ax in enumerate(axes[:, 0]):
        ax.plot(h.t, h.q_rec[:, k], "k.", ms=3, label=recorded)
        ax.plot(h.t, _broken(h.t, h.q_before[:, k]), lw=1.2, label=f"nominal (RMS {h.rms_before:.3g})")
        ax.plot(h.t, _broken(h.t, h.q_after[:, k]), lw=1.2, label=f"augmented (RMS {h.rms_after:.3g})")
        ax.set_ylabel(names[k])
        ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_diagnosis(d: Diagnosis, out_dir: str | Path) -> list[Path]:
    """Write residual_time.png, residual_state.png, fit_before_after.png (the held-out span) and
    other_<k>_before_after.png (each further recording's prediction); returns their paths."""
    out_dir = Path(out_dir)
    nom = d.nominal_fit
    rec = nom.recording
    names = rec.joint_names
    n = len(names)
    paths = []

    fig, axes = plt.subplots(n, 1, figsize=(9, 2.6 * n), squeeze=False)
    for k, (ax, m) in enumerate(zip(axes[:, 0], d.mismatch)):
        ax.plot(rec.t, _broken(rec.t, nom.q_fit[:, k] - rec.q[:, k]), lw=1, label="nominal fit − recorded")
        ax.plot(rec.t, _broken(rec.t, d.final_fit.q_fit[:, k] - rec.q[:, k]), lw=1, label="augmented fit − recorded")
        for a, b in m.windows_s:
            ax.axvspan(a, b, color="red", alpha=0.12)
        ax.set_ylabel(f"{names[k]} error")
        ax.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("t [s] (shaded: located windows, > 3σ)")
    fig.tight_layout()
    paths.append(_save(fig, out_dir / "residual_time.png"))

    force, q, v, _ = inverse_dynamics_residual(nom.model, rec)
    fig, axes = plt.subplots(n, 2, figsize=(9, 2.8 * n), squeeze=False)
    for k in range(n):
        axes[k, 0].plot(v[:, k], force[:, k], ".", ms=3)
        axes[k, 0].set_xlabel(f"v {names[k]}")
        axes[k, 0].set_ylabel("residual force")
        axes[k, 1].plot(q[:, k], force[:, k], ".", ms=3)
        axes[k, 1].set_xlabel(f"q {names[k]}")
    fig.suptitle("inverse-dynamics residual of the nominal model vs state")
    fig.tight_layout()
    paths.append(_save(fig, out_dir / "residual_state.png"))

    if d.held_out is not None and d.held_out.scored:
        paths.append(_before_after(d.held_out, names, "held-out span: recorded vs simulated, before and after",
                                   "recorded (held out)", out_dir / "fit_before_after.png"))
    for k, h in enumerate(d.held_out_others):
        if h.scored:
            role = "judged acceptance" if k == d.other_used_for_selection else "independent"
            paths.append(_before_after(h, names, f"other recording {k + 1} ({role}): recorded vs predicted, "
                                       "before and after", "recorded", out_dir / f"other_{k + 1}_before_after.png"))
    return paths
