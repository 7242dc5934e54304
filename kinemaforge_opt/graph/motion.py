"""Relative motion of one track (the child) seen from another (the parent) and its noise level.

The noise level is estimated from the data alone, independently of any joint model: a local
quadratic (Savitzky–Golay) smoother removes the smooth motion, and the robust spread (MAD) of
what is left, corrected for the smoother's own variance, is the sensor noise σ.  Orientations
enter as their frame-to-frame increments summed up (:func:`rotation_signal`): a continuous
signal, where an orientation registered flipped by π is one step per flip, not a run of frames
near π where the rotation vector's axis — and its noise — is ill-defined.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lstsq
from scipy.spatial.transform import Rotation

from ..errors import DataError
from ..io.tracks import PoseTracks

WORLD = "world"
# Savitzky–Golay window used only to estimate noise (7 samples, quadratic: the motion's
# curvature is removed, its jerk over 7 samples is far below sensor noise at video rates).
NOISE_WINDOW = 7
# Floor for σ on noise-free (synthetic) data, far above float64 round-off at metre scale and far
# below any real sensor noise: keeps normalised residuals finite.
SIGMA_FLOOR = 1e-9
MIN_SAMPLES = 5


@dataclass(frozen=True, eq=False)
class RelativeMotion:
    """The child's motion in the parent's frame at the N samples both are observed.

    times: (N,) [s].  positions: (N, 3) child origin in the parent frame [m].
    Rs: (N, 3, 3) child orientation in the parent frame, or None (position-only child).
    sigma_position [m], sigma_rotation [rad]: estimated noise per coordinate.
    Ts_world_parent0: (4, 4) the parent's world pose at the first sample (maps fitted axes to world).
    """

    times: np.ndarray
    positions: np.ndarray
    Rs: np.ndarray | None
    sigma_position: float
    sigma_rotation: float
    T_world_parent0: np.ndarray

    @property
    def n(self) -> int:
        return int(self.times.size)


def savgol_smoothing(window: int) -> np.ndarray:
    """(window,) Savitzky–Golay coefficients of a quadratic fit's centre value, for an odd
    ``window``: ``scipy.signal.savgol_coeffs(window, 2)``, computed the same way (least squares
    on the same design matrix, the same cut-off), bit for bit.  Written out because importing
    scipy.signal imports scipy.stats, 0.75 s at the start of every command that fits joints."""
    x = np.arange(-(window // 2), window - window // 2, dtype=float)[::-1]
    A = x ** np.arange(3, dtype=float).reshape(-1, 1)
    return lstsq(A, np.array([1.0, 0.0, 0.0]), cond=np.finfo(float).eps * window)[0]


def noise_sigma(signal: np.ndarray) -> float:
    """Robust noise σ per coordinate of a (N, d) sampled signal (see module doc); SIGMA_FLOOR
    when the signal is exactly smooth or too short to tell."""
    x = np.asarray(signal, dtype=float)
    w = NOISE_WINDOW
    if x.shape[0] < w:
        return SIGMA_FLOOR
    c = savgol_smoothing(w)  # symmetric: convolution == correlation
    smooth = np.stack([np.convolve(x[:, j], c, mode="valid") for j in range(x.shape[1])], axis=1)
    e = x[w // 2 : x.shape[0] - w // 2] - smooth
    # Residual of one sample = (1 - c0) n_0 - sum_{j != 0} c_j n_j  =>  variance factor below.
    factor = (1 - c[w // 2]) ** 2 + np.sum(np.delete(c, w // 2) ** 2)
    mad = np.median(np.abs(e - np.median(e, axis=0)), axis=0)
    sigma = float(np.sqrt(np.mean((1.4826 * mad) ** 2) / factor))
    return max(sigma, SIGMA_FLOOR)


def relative_motion(tracks: PoseTracks, parent: int | None, child: int) -> RelativeMotion:
    """The motion of track ``child`` in the frame of track ``parent`` (None = the static world).

    Raises DataError when the parent is position-only (a point has no frame) or when the two
    tracks share fewer than MIN_SAMPLES observed samples."""
    obs = tracks.observed()
    both = obs[child] if parent is None else obs[child] & obs[parent]
    if both.sum() < MIN_SAMPLES:
        raise DataError(
            f"track {tracks.names[child]!r} has {int(both.sum())} samples in common with "
            f"{WORLD if parent is None else tracks.names[parent]!r}; at least {MIN_SAMPLES} are needed"
        )
    p_c = tracks.positions[child, both]
    R_c = tracks.Rs_world_track[child, both] if tracks.has_orientation else None
    T0 = np.eye(4)
    if parent is None:
        pos, Rs = p_c, R_c
    else:
        if not tracks.has_orientation:
            raise DataError(f"track {tracks.names[parent]!r} is position-only and cannot be a parent frame")
        R_p = tracks.Rs_world_track[parent, both]
        p_p = tracks.positions[parent, both]
        pos = np.einsum("nji,nj->ni", R_p, p_c - p_p)
        Rs = np.einsum("nji,njk->nik", R_p, R_c)
        T0[:3, :3], T0[:3, 3] = R_p[0], p_p[0]
    sigma_r = SIGMA_FLOOR
    if Rs is not None:
        Rs = _project_so3(Rs)
        sigma_r = noise_sigma(rotation_signal(Rs))
    return RelativeMotion(tracks.times[both], pos, Rs, noise_sigma(pos), sigma_r, T0)


def rotation_signal(Rs: np.ndarray) -> np.ndarray:
    """(N, 3) running sum of the rotation vectors of the increments R_tᵀ R_{t+1} [rad] of
    (N, 3, 3) orientations, 0 at the first sample (equals the rotation vector of R_0ᵀ R_t for a
    rotation about a fixed axis; its noise is the orientations' noise)."""
    inc = Rotation.from_matrix(np.einsum("nji,njk->nik", Rs[:-1], Rs[1:])).as_rotvec()
    return np.vstack([np.zeros((1, 3)), np.cumsum(inc, axis=0)])


def _project_so3(Rs: np.ndarray) -> np.ndarray:
    """Nearest rotation matrices (N, 3, 3) to (N, 3, 3) inputs (removes round-off drift)."""
    U, _, Vt = np.linalg.svd(Rs)
    D = np.ones(Rs.shape[:-1])
    D[:, -1] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[:, None, :]) @ Vt
