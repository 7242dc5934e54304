"""Noisy pose tracks built from true poses, shared by the graph tests."""

import numpy as np
from scipy.spatial.transform import Rotation


def noisy_track(poses, rng: np.random.Generator, sigma_p: float, sigma_r: float, flip=None):
    """(T, 4, 4) true poses -> (P (T, 3), R (T, 3, 3)) with white noise of ``sigma_p`` [m] per
    coordinate on positions and ``sigma_r`` [rad] per coordinate on orientations; ``flip``:
    (mask (T,), body-frame rotation vector) applied on the masked frames, as a registration turned
    by a shape symmetry about the part's centroid (the position is unchanged)."""
    P = np.array([X[:3, 3] for X in poses]) + sigma_p * rng.normal(size=(len(poses), 3))
    R = np.array([X[:3, :3] @ Rotation.from_rotvec(sigma_r * rng.normal(size=3)).as_matrix() for X in poses])
    if flip is not None:
        mask, w = flip
        R[mask] = R[mask] @ Rotation.from_rotvec(w).as_matrix()
    return P, R
