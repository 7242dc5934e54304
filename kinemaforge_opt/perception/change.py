"""Which points move: free-space tests of a point against the depth images of other times.

A world point p is projected into a depth image taken at another time.  Against the readings in
the 3×3 pixel window around its projection (the window absorbs resampling between views):

* +1 *consistent*: some reading in the window is within τ of p's depth — a surface is still there;
* −1 *violated*: p lies in front of every reading by more than τ — the camera saw through the
  place where p was, so whatever was at p has moved;
*  0 *unknown*: out of view, no readings, or p is behind the surface (occluded).

τ = TEST_SIGMAS · √2 · σ_z(z) (two noisy readings compared).  A point is *moving* when it is
violated in at least two tests, or in one test and consistent in none (a single violation among
consistent tests is the signature of a noise outlier, ~0.1–0.5 % per test, while two independent
3σ violations have odds ~1e-5); *static* when it is consistent somewhere and never violated;
*unknown* otherwise (e.g. a surface only uncovered at one time).  This works for moving
cameras (every image carries its own pose) and finds the static background instead of
assuming it.
"""

from __future__ import annotations

import numpy as np

from ..io.sequence import CameraInfo
from .clouds import DepthNoise, TimeCloud

# Two-sided test level: a 3σ band keeps 99.7 % of noise-only differences consistent.
TEST_SIGMAS = 3.0
STATIC, UNKNOWN, MOVING = 0, 1, 2


def window_stack(depth: np.ndarray) -> np.ndarray:
    """(9, H, W) the readings [m] of each pixel's 3×3 window (NaN = no reading or off-image)."""
    pad = np.pad(depth, 1, constant_values=np.nan)
    h, w = depth.shape
    return np.stack([pad[i : i + h, j : j + w] for i in range(3) for j in range(3)])


def free_space_test(points_world: np.ndarray, camera: CameraInfo, T_world_camera: np.ndarray,
                    window: np.ndarray, noise: DepthNoise) -> np.ndarray:
    """(N,) int8 verdicts (+1 consistent, −1 violated, 0 unknown) of (N, 3) world points [m]
    against one depth image, given as its :func:`window_stack` (9, H, W) [m]."""
    R, p = T_world_camera[:3, :3], T_world_camera[:3, 3]
    pc = (points_world - p) @ R
    z = pc[:, 2]
    out = np.zeros(len(points_world), dtype=np.int8)
    front = z > 1e-9
    u = np.full(z.shape, -1)
    v = np.full(z.shape, -1)
    u[front] = np.round(camera.fx * pc[front, 0] / z[front] + camera.cx).astype(int)
    v[front] = np.round(camera.fy * pc[front, 1] / z[front] + camera.cy).astype(int)
    inside = front & (u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)
    idx = np.flatnonzero(inside)
    readings = window[:, v[idx], u[idx]]  # (9, n)
    seen = np.isfinite(readings).any(axis=0)
    idx, readings = idx[seen], readings[:, seen]
    zi = z[idx]
    tau = TEST_SIGMAS * np.sqrt(2.0) * noise.sigma(zi)
    nearest = np.nanmin(np.abs(readings - zi), axis=0)
    out[idx[zi < np.nanmin(readings, axis=0) - tau]] = -1
    out[idx[nearest <= tau]] = 1
    return out


def motion_status(clouds: list[TimeCloud], cameras: dict[str, CameraInfo], noise: DepthNoise) -> list[np.ndarray]:
    """Per time step, (M_t,) int8 status of its fused points: STATIC, UNKNOWN or MOVING (module doc)."""
    ranges = [[window_stack(v.depth) for v in c.views] for c in clouds]
    status = []
    for i, c in enumerate(clouds):
        violated = np.zeros(len(c.points), dtype=int)
        consistent = np.zeros(len(c.points), dtype=int)
        for j, other in enumerate(clouds):
            if j == i:
                continue
            for view, rng in zip(other.views, ranges[j]):
                verdict = free_space_test(c.points, cameras[view.frame.camera], view.frame.T_world_camera, rng, noise)
                violated += verdict < 0
                consistent += verdict > 0
        s = np.full(len(c.points), UNKNOWN, dtype=np.int8)
        s[(violated == 0) & (consistent > 0)] = STATIC
        s[(violated >= 2) | ((violated == 1) & (consistent == 0))] = MOVING
        status.append(s)
    return status
