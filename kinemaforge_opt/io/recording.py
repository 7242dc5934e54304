"""Joint-space recordings (``recording.csv``): ``t`` then, per joint, ``q:<joint>`` and optionally
``v:<joint>``, ``tau:<joint>`` (applied generalised force, N·m or N; a joint without one is driven
by nothing, 0).  Velocities are given for every joint or for none.  SI units, time-major."""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataError, InputFileError, UnknownNameError
from .atomic import write_numeric_csv_atomic


@dataclass(frozen=True, eq=False)
class Recording:
    """A joint-space recording.

    t: (T,) strictly increasing times [s].  joint_names: the n recorded joints.
    q: (T, n) positions [rad or m]; v: (T, n) velocities or None; tau: (T, n) applied forces or None.
    held: (T, n) True where a joint rests on a stop of the model that holds it still while others
    move, or None (none is): an annotation of the fit span
    (:func:`~kinemaforge_opt.nlp.joint_space.between_nominal_stops`), not a column of the file;
    fits and simulations hold such a joint still with the stop's force, whatever it is.
    """

    t: np.ndarray
    joint_names: tuple[str, ...]
    q: np.ndarray
    v: np.ndarray | None = None
    tau: np.ndarray | None = None
    held: np.ndarray | None = None

    def __post_init__(self):
        t = np.asarray(self.t, dtype=float)
        n = len(self.joint_names)
        if t.ndim != 1 or t.size < 2:
            raise DataError(f"recording time t must be a 1-D array of at least 2 samples, got shape {t.shape}")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise DataError("recording time t must be finite and strictly increasing")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        for field in ("q", "v", "tau"):
            a = getattr(self, field)
            if a is None:
                continue
            a = np.asarray(a, dtype=float).reshape(t.size, -1) if np.ndim(a) == 1 and n == 1 else np.asarray(a, dtype=float)
            if a.shape != (t.size, n):
                raise DataError(f"recording {field} must have shape ({t.size}, {n}), got {a.shape}")
            bad = ~np.isfinite(a)
            if bad.any():
                r, c = np.argwhere(bad)[0]
                raise DataError(
                    f"recording {field}:{self.joint_names[c]} is not finite at row {r} (t={t[r]:.4g} s)"
                )
            object.__setattr__(self, field, a)
        if self.held is not None:
            held = np.asarray(self.held, dtype=bool).reshape(t.size, -1)
            if held.shape != (t.size, n):
                raise DataError(f"recording held must have shape ({t.size}, {n}), got {held.shape}")
            object.__setattr__(self, "held", held if held.any() else None)

    @property
    def dt(self) -> float:
        """Median sample period [s]."""
        return float(np.median(np.diff(self.t)))

    def select(self, joint_names) -> "Recording":
        """The same recording restricted/reordered to ``joint_names``."""
        idx = []
        for name in joint_names:
            if name not in self.joint_names:
                raise UnknownNameError("recorded joint", name, self.joint_names)
            idx.append(self.joint_names.index(name))
        pick = lambda a: None if a is None else a[:, idx]  # noqa: E731
        return Recording(self.t, tuple(joint_names), self.q[:, idx], pick(self.v), pick(self.tau), pick(self.held))

    def window(self, t_start: float, t_end: float) -> "Recording":
        """Samples with t_start <= t <= t_end."""
        return self.rows((self.t >= t_start) & (self.t <= t_end))

    def rows(self, keep: np.ndarray) -> "Recording":
        """The samples where the (T,) mask ``keep`` is true."""
        pick = lambda a: None if a is None else a[keep]  # noqa: E731
        return Recording(self.t[keep], self.joint_names, self.q[keep], pick(self.v), pick(self.tau), pick(self.held))

    def locks(self) -> np.ndarray:
        """(T - 1, n) True for each sample interval over which a joint is held (:attr:`held` at
        both its ends): the interval's dynamics hold that joint still."""
        if self.held is None:
            return np.zeros((self.t.size - 1, len(self.joint_names)), dtype=bool)
        return self.held[:-1] & self.held[1:]


def read_recording(path: str | os.PathLike) -> Recording:
    """Read ``recording.csv``; errors name the file, the column and the row at fault."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"recording file {str(path)!r} does not exist")
    with open(path, newline="") as f:
        reader = csv.reader(f)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise InputFileError(f"{path}: empty file, expected a header 't,q:<joint>,…'") from None
        rows = [r for r in reader if r and any(c.strip() for c in r)]
    if not header or header[0] != "t":
        raise InputFileError(f"{path}: first column must be 't', got {header[:1]}")
    joints: list[str] = []
    cols: dict[tuple[str, str], int] = {}
    for i, h in enumerate(header[1:], start=1):
        kind, sep, name = h.partition(":")
        if not sep or kind not in ("q", "v", "tau") or not name:
            raise InputFileError(f"{path}: column {i} {h!r} is not one of q:<joint>, v:<joint>, tau:<joint>")
        if (kind, name) in cols:
            raise InputFileError(f"{path}: column {h!r} appears twice")
        cols[(kind, name)] = i
        if kind == "q":
            joints.append(name)
    for kind, name in cols:
        if kind != "q" and ("q", name) not in cols:
            raise InputFileError(f"{path}: column {kind}:{name} has no matching q:{name}")
    if not joints:
        raise InputFileError(f"{path}: no q:<joint> column")
    try:
        data = np.array([[float(c) for c in r] for r in rows], dtype=float)
    except ValueError as e:
        raise InputFileError(f"{path}: non-numeric value ({e})") from None
    if data.ndim != 2 or data.shape[1] != len(header):
        raise InputFileError(f"{path}: every row must have {len(header)} values")

    def block(kind):
        if not any((kind, j) in cols for j in joints):
            return None
        if kind == "tau":  # a joint without a tau column is driven by nothing: its applied force is 0
            return np.stack([data[:, cols[(kind, j)]] if (kind, j) in cols else np.zeros(len(data))
                             for j in joints], axis=1)
        missing = [j for j in joints if (kind, j) not in cols]
        if missing:
            raise InputFileError(f"{path}: {kind} columns missing for joints {missing} (velocities are measured "
                                 "for every joint or for none)")
        return data[:, [cols[(kind, j)] for j in joints]]

    try:
        return Recording(data[:, 0], tuple(joints), block("q"), block("v"), block("tau"))
    except DataError as e:
        raise InputFileError(f"{path}: {e}") from None


def write_recording(path: str | os.PathLike, rec: Recording) -> Path:
    """Write ``rec`` as ``recording.csv`` atomically (full float precision)."""
    path = Path(path)
    header = ["t"]
    blocks = [rec.t[:, None]]
    for kind, arr in (("q", rec.q), ("v", rec.v), ("tau", rec.tau)):
        if arr is not None:
            header += [f"{kind}:{j}" for j in rec.joint_names]
            blocks.append(arr)
    return write_numeric_csv_atomic(path, header, np.hstack(blocks))
