"""Part pose tracks (``tracks.csv``) and the real Sturm articulation logs.

``tracks.csv``: header ``t,track,x,y,z,qx,qy,qz,qw`` (full pose) or ``t,track,x,y,z`` (position
only); one row per observed (time, track); world frame, metres, seconds, quaternion order xyzw.
A track that is not observed at a time simply has no row there (NaN in :class:`PoseTracks`).

Sturm logs (Sturm et al., JAIR 2011, ``mechanisms_iros_2010/<kind>/NNN.log``): one ``x y z`` line
per sample, metres, no time stamps.  :func:`read_sturm_log` uses the sample index as time
(``t = 0, 1, 2, …`` "seconds"), so only the ordering of samples carries meaning.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import DataError, InputFileError
from .atomic import atomic_path

FULL_HEADER = ("t", "track", "x", "y", "z", "qx", "qy", "qz", "qw")
POSITION_HEADER = FULL_HEADER[:5]
# A stored unit quaternion is accepted when its norm is within this of 1 (text rounding to
# ~6 significant digits keeps the norm within 1e-5; anything further off is not a rotation).
QUAT_NORM_TOL = 1e-3


@dataclass(frozen=True, eq=False)
class PoseTracks:
    """World-frame pose tracks of K parts (or proposals) sampled at T common times.

    times: (T,) strictly increasing [s].  names: K track names.
    positions: (K, T, 3) track origin in the world [m], NaN where a track is unobserved.
    Rs_world_track: (K, T, 3, 3) track orientation in the world, NaN where unobserved, or None
    for position-only tracks (e.g. a gripper path).
    """

    times: np.ndarray
    names: tuple[str, ...]
    positions: np.ndarray
    Rs_world_track: np.ndarray | None = None

    def __post_init__(self):
        t = np.asarray(self.times, dtype=float)
        names = tuple(str(n) for n in self.names)
        P = np.asarray(self.positions, dtype=float)
        if t.ndim != 1 or t.size < 1 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise DataError(f"track times must be a finite, strictly increasing 1-D array, got shape {t.shape}")
        if len(set(names)) != len(names):
            raise DataError(f"track names must be unique, got {names}")
        if P.shape != (len(names), t.size, 3):
            raise DataError(f"track positions must have shape ({len(names)}, {t.size}, 3), got {P.shape}")
        if np.any(np.isinf(P)):
            raise DataError("track positions hold inf values (use NaN for unobserved samples)")
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "positions", P)
        if self.Rs_world_track is not None:
            R = np.asarray(self.Rs_world_track, dtype=float)
            if R.shape != (len(names), t.size, 3, 3):
                raise DataError(
                    f"Rs_world_track must have shape ({len(names)}, {t.size}, 3, 3), got {R.shape}"
                )
            if np.any(np.isnan(R).any(axis=(-1, -2)) != np.isnan(P).any(axis=-1)):
                raise DataError("Rs_world_track and positions must be unobserved (NaN) at the same samples")
            object.__setattr__(self, "Rs_world_track", R)

    @property
    def has_orientation(self) -> bool:
        """True for full-pose tracks, False for position-only ones."""
        return self.Rs_world_track is not None

    def observed(self) -> np.ndarray:
        """(K, T) bool: where each track has a sample."""
        return np.isfinite(self.positions).all(axis=-1)

    def Ts_world_track(self, k: int) -> np.ndarray:
        """(T, 4, 4) poses of track ``k`` (NaN where unobserved); needs full-pose tracks."""
        if self.Rs_world_track is None:
            raise DataError(f"track {self.names[k]!r} is position-only: it has no orientation")
        T = np.zeros((self.times.size, 4, 4))
        T[:, :3, :3] = self.Rs_world_track[k]
        T[:, :3, 3] = self.positions[k]
        T[:, 3, 3] = 1.0
        return T


@dataclass(frozen=True, eq=False)
class ZeroConfiguration:
    """Where a kinematic tree's links are at q = 0, from the tracks that follow them.

    step: the time step the zero configuration is taken at (the first at which the most moving
    links are seen).  poses: link -> (4, 4) pose T_world_track of its track at q = 0 (identity
    for the root).  steps: link -> the time step at which its pose relative to its parent was
    taken: ``step`` where it and its parent are seen then, else the nearest step at which both
    are (its joint's q is 0 at that step, not at ``step``)."""

    step: int
    poses: dict[str, np.ndarray]
    steps: dict[str, int]


def zero_configuration(tracks: PoseTracks, reps: dict[str, int | None], parent: dict[str, str]) -> ZeroConfiguration:
    """The :class:`ZeroConfiguration` of a tree whose links follow the tracks ``reps`` (link ->
    track index, None for the root, which is the world) with ``parent`` (moving link -> parent link).

    Every link's zero pose is its parent's composed with the relative pose of the two tracks at
    one time step, so q = 0 is always a configuration the object took.  Where every moving link
    is seen at one step this is simply their poses at the first such step.  Where none sees them
    all (a part tracked in two halves, a drawer hidden while another is seen) a link unseen at
    ``step`` takes its relative pose at the nearest step that sees it with its parent
    (protocol_drawer_0@s6: five tracks for three drawers, two of them seen at steps 0-9 and
    10-19 only, had stopped the reconstruction).  Raises :class:`DataError` naming the link when
    it is never seen together with its parent."""
    obs = tracks.observed()
    T = tracks.times.size
    moving = [link for link, k in reps.items() if k is not None]
    count = sum(obs[reps[link]].astype(int) for link in moving) if moving else np.zeros(T, dtype=int)
    step = int(np.argmax(count))
    poses = {link: np.eye(4) for link, k in reps.items() if k is None}
    steps: dict[str, int] = {}
    todo = list(moving)
    while todo:
        ready = [link for link in todo if parent[link] in poses]
        if not ready:
            raise DataError(f"link(s) {', '.join(map(repr, todo))}: no path of tracked parents to the root")
        for link in ready:
            kp = reps[parent[link]]
            both = obs[reps[link]] & (obs[kp] if kp is not None else True)
            if not both.any():
                raise DataError(f"link {link!r} is never seen together with its parent {parent[link]!r}: "
                                "their relative pose, and so the joint between them, is unknown")
            together = np.flatnonzero(both)
            s = int(together[np.argmin(np.abs(together - step))])
            T_link = tracks.Ts_world_track(reps[link])[s]
            if s == step and (kp is None or steps[parent[link]] == step):
                poses[link] = T_link  # the parent is where its track was at this step
            else:
                T_parent = np.eye(4) if kp is None else tracks.Ts_world_track(kp)[s]
                poses[link] = poses[parent[link]] @ np.linalg.inv(T_parent) @ T_link
            steps[link] = s
            todo.remove(link)
    return ZeroConfiguration(step, poses, steps)


def _field_float(path: Path, row: int, field: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputFileError(f"{path}: row {row}, field {field!r}: expected a number, got {text!r}") from None
    if not np.isfinite(value):
        raise InputFileError(f"{path}: row {row}, field {field!r}: expected a finite number, got {text!r}")
    return value


def read_tracks(path: str | os.PathLike) -> PoseTracks:
    """Read ``tracks.csv`` (full pose or position only).  Rows are numbered from 1 = header;
    every error names the file, the row and the field at fault."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"tracks file {str(path)!r} does not exist or is not a file")
    try:
        with open(path, newline="", encoding="utf-8") as f:
            lines = list(csv.reader(f))
    except (OSError, UnicodeDecodeError) as e:
        raise InputFileError(f"{path}: cannot be read as UTF-8 text ({e})") from None
    if not lines:
        raise InputFileError(f"{path}: empty file, expected the header {','.join(FULL_HEADER)}")
    header = tuple(h.strip() for h in lines[0])
    if header not in (FULL_HEADER, POSITION_HEADER):
        raise InputFileError(
            f"{path}: row 1 (header) must be {','.join(FULL_HEADER)} or {','.join(POSITION_HEADER)}, "
            f"got {','.join(header)}"
        )
    full = header == FULL_HEADER
    samples: dict[tuple[float, str], tuple[np.ndarray, np.ndarray | None]] = {}
    for row, cells in enumerate(lines[1:], start=2):
        if not cells or not any(c.strip() for c in cells):
            continue
        if len(cells) != len(header):
            raise InputFileError(f"{path}: row {row}: expected {len(header)} fields, got {len(cells)}")
        t = _field_float(path, row, "t", cells[0])
        name = cells[1].strip()
        if not name:
            raise InputFileError(f"{path}: row {row}, field 'track': empty track name")
        xyz = np.array([_field_float(path, row, f, c) for f, c in zip("xyz", cells[2:5])])
        R = None
        if full:
            q = np.array([_field_float(path, row, f, c) for f, c in zip(FULL_HEADER[5:], cells[5:9])])
            norm = np.linalg.norm(q)
            if abs(norm - 1.0) > QUAT_NORM_TOL:
                raise InputFileError(
                    f"{path}: row {row}, fields 'qx,qy,qz,qw': expected a unit quaternion, norm is {norm:.6g}"
                )
            R = Rotation.from_quat(q / norm).as_matrix()
        if (t, name) in samples:
            raise InputFileError(f"{path}: row {row}: track {name!r} appears twice at t={t!r}")
        samples[(t, name)] = (xyz, R)
    if not samples:
        raise InputFileError(f"{path}: no data rows after the header")
    times = np.array(sorted({t for t, _ in samples}))
    names = tuple(dict.fromkeys(n for _, n in samples))
    t_index = {t: i for i, t in enumerate(times)}
    P = np.full((len(names), times.size, 3), np.nan)
    Rs = np.full((len(names), times.size, 3, 3), np.nan) if full else None
    for (t, name), (xyz, R) in samples.items():
        k, i = names.index(name), t_index[t]
        P[k, i] = xyz
        if full:
            Rs[k, i] = R
    return PoseTracks(times, names, P, Rs)


def write_tracks(path: str | os.PathLike, tracks: PoseTracks) -> None:
    """Write ``tracks.csv`` atomically (full pose when ``tracks`` has orientations); unobserved
    samples get no row.  Values are written with 17 significant digits (exact round trip)."""
    header = FULL_HEADER if tracks.has_orientation else POSITION_HEADER
    obs = tracks.observed()
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(header)
            for i, t in enumerate(tracks.times):
                for k, name in enumerate(tracks.names):
                    if not obs[k, i]:
                        continue
                    values = list(tracks.positions[k, i])
                    if tracks.has_orientation:
                        values += list(Rotation.from_matrix(tracks.Rs_world_track[k, i]).as_quat())
                    w.writerow([f"{t:.17g}", name] + [f"{v:.17g}" for v in values])


def read_sturm_log(path: str | os.PathLike, name: str | None = None) -> PoseTracks:
    """Read one Sturm articulation log (``x y z`` per line, metres) as a position-only PoseTracks
    with one track (named ``name``, default ``<kind>_<stem>`` from the path); time = sample index."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"Sturm log {str(path)!r} does not exist or is not a file")
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise InputFileError(f"{path}: cannot be read as text ({e})") from None
    rows = []
    for row, line in enumerate(lines, start=1):
        cells = line.split()
        if not cells:
            continue
        if len(cells) != 3:
            raise InputFileError(f"{path}: line {row}: expected 3 fields 'x y z', got {len(cells)}")
        rows.append([_field_float(path, row, f, c) for f, c in zip("xyz", cells)])
    if len(rows) < 2:
        raise InputFileError(f"{path}: expected at least 2 samples 'x y z', got {len(rows)}")
    P = np.array(rows)[None]
    return PoseTracks(np.arange(P.shape[1], dtype=float), (name or f"{path.parent.name}_{path.stem}",), P)
