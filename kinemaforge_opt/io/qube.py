"""Reader of the Quanser Qube-Servo 2 free-swing recordings (``../shared/data/real/qube``).

CSV columns ``id,alpha,theta,alpha_dot,theta_dot,time`` (rad, rad/s, s; ~4 ms a sample, zero motor
voltage).  ``alpha`` is the pendulum angle wrapped to (-pi, pi] with 0 upright; the Furuta model in
``models/furuta`` measures it from hanging down, so q:alpha = unwrap(alpha) - pi·k with k chosen so
that the recording ends near 0.  The arm angle ``theta`` is used as is.  Only positions are
returned (the recorded rates are finite differences of the encoders).
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from ..errors import InputFileError
from .recording import Recording

COLUMNS = ("alpha", "theta", "time")


def read_qube_csv(path: str | os.PathLike, decimate: int = 1, alpha_sign: float = 1.0) -> Recording:
    """Recording with joints ("theta", "alpha") of one Qube CSV, keeping every ``decimate``-th
    sample; ``alpha_sign`` flips the pendulum angle's sign convention."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"Qube recording {str(path)!r} does not exist")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise InputFileError(f"{path}: missing column(s) {missing}; expected {', '.join(COLUMNS)}")
        try:
            rows = [(float(r["time"]), float(r["theta"]), float(r["alpha"])) for r in reader]
        except (TypeError, ValueError) as e:
            raise InputFileError(f"{path}: non-numeric value ({e})") from None
    data = np.asarray(rows)[::decimate]
    t = data[:, 0] - data[0, 0]
    alpha = np.unwrap(data[:, 2])
    alpha = alpha - np.pi * np.round(alpha[-1] / np.pi)
    q = np.stack([data[:, 1], alpha_sign * alpha], axis=1)
    return Recording(t, ("theta", "alpha"), q)
