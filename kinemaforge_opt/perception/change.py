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

Fast path for static cameras (:func:`pixel_status`): the same test needs no reprojection — each
reading is compared with the same pixel at every other time, and pixels whose readings all agree
within τ (most of the background) are settled at once.  Moving cameras use
:func:`motion_status` on the fused points against up to MAX_OTHER_STEPS other time steps.
"""

from __future__ import annotations

import numpy as np

from ..io.sequence import CameraInfo
from ..parallel import thread_map
from .clouds import DepthNoise, TimeCloud

# Two-sided test level: a 3σ band keeps 99.7 % of noise-only differences consistent.
TEST_SIGMAS = 3.0
STATIC, UNKNOWN, MOVING = 0, 1, 2
# A moving reading needs at least this many moving readings in its 3×3 window (itself included).
MIN_MOVING_NEIGHBOURS = 3
# Free-space tests of moving cameras compare each time step with at most this many others.
MAX_OTHER_STEPS = 10


def padded_depth(depth: np.ndarray) -> np.ndarray:
    """(H+2, W+2) depth image [m] padded with one pixel on each side, +inf where there is no
    reading (NaN in the image, and the padding): the form in which :func:`free_space_test` reads
    each pixel's 3×3 window (one gather of nine per tested point, instead of stacking nine shifted
    copies of the whole image; with +inf for "no reading" the window's minima need no NaN
    handling, and a missing reading is neither near a point nor in front of it)."""
    padded = np.pad(np.asarray(depth, dtype=float), 1, constant_values=np.inf)
    padded[np.isnan(padded)] = np.inf
    return padded


def free_space_test(points_world: np.ndarray, camera: CameraInfo, T_world_camera: np.ndarray,
                    padded: np.ndarray, noise: DepthNoise) -> np.ndarray:
    """(N,) int8 verdicts (+1 consistent, −1 violated, 0 unknown) of (N, 3) world points [m]
    against one depth image, given as its :func:`padded_depth` (H+2, W+2) [m]: each point is
    compared with the readings of the 3×3 window around the pixel it projects to."""
    R, p = T_world_camera[:3, :3], T_world_camera[:3, 3]
    pc = (points_world - p) @ R
    z = pc[:, 2]
    out = np.zeros(len(points_world), dtype=np.int8)
    front = np.flatnonzero(z > 1e-9)
    u = np.round(camera.fx * pc[front, 0] / z[front] + camera.cx).astype(int)
    v = np.round(camera.fy * pc[front, 1] / z[front] + camera.cy).astype(int)
    inside = (u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)
    idx = front[inside]
    # the window of pixel (v, u) is padded[v:v+3, u:u+3]: flat offsets from its corner
    width = padded.shape[1]
    window = (np.arange(3)[:, None] * width + np.arange(3)[None, :]).ravel()
    readings = padded.ravel()[(v[inside] * width + u[inside])[:, None] + window]  # (n, 9), +inf = none
    front_reading = readings.min(axis=1)
    seen = front_reading < np.inf
    idx, readings, front_reading = idx[seen], readings[seen], front_reading[seen]
    zi = z[idx]
    tau = TEST_SIGMAS * np.sqrt(2.0) * noise.sigma(zi)
    nearest = np.abs(readings - zi[:, None]).min(axis=1)
    out[idx[zi < front_reading - tau]] = -1
    out[idx[nearest <= tau]] = 1
    return out


def verdict_status(violated: np.ndarray, consistent: np.ndarray) -> np.ndarray:
    """Status from per-point counts of violated and consistent tests (module doc)."""
    s = np.full(violated.shape, UNKNOWN, dtype=np.int8)
    s[(violated == 0) & (consistent > 0)] = STATIC
    s[(violated >= 2) | ((violated == 1) & (consistent == 0))] = MOVING
    return s


def despeckle(status: np.ndarray) -> np.ndarray:
    """(h, w) pixel status with isolated MOVING pixels (fewer than MIN_MOVING_NEIGHBOURS moving
    pixels in their 3×3 window, themselves included) set to UNKNOWN: a single noisy reading in
    front of the surface is violated by every other time, but a moving surface covers a patch."""
    m = (status == MOVING).astype(np.int16)
    pad = np.pad(m, 1)
    h, w = m.shape
    count = sum(pad[i : i + h, j : j + w] for i in range(3) for j in range(3))
    out = status.copy()
    out[(status == MOVING) & (count < MIN_MOVING_NEIGHBOURS)] = UNKNOWN
    return out


def pixel_status(depths: np.ndarray, noise: DepthNoise) -> np.ndarray:
    """(T, h, w) int8 status of every reading of one *static* camera from its own (T, h, w)
    depth images [m] (NaN = no reading): the free-space test of each reading against the same
    pixel at every other time (no reprojection needed).  Pixels whose readings all agree within
    τ at the nearest depth are static at once; only the others are compared pairwise."""
    D = np.asarray(depths, dtype=np.float32)
    T = D.shape[0]
    out = np.full(D.shape, UNKNOWN, dtype=np.int8)
    valid = np.isfinite(D)
    n_valid = valid.sum(axis=0)
    with np.errstate(invalid="ignore", all="ignore"):
        lo = np.where(n_valid > 0, np.nanmin(np.where(valid, D, np.inf), axis=0), np.nan)
        hi = np.nanmax(np.where(valid, D, -np.inf), axis=0)
        tau_lo = TEST_SIGMAS * np.sqrt(2.0) * noise.sigma(lo)
        calm = (n_valid >= 2) & (hi - lo <= tau_lo)
    out[:, calm] = np.where(valid[:, calm], STATIC, UNKNOWN)
    busy = np.flatnonzero(~calm.ravel() & (n_valid.ravel() >= 2))
    if busy.size:
        d = D.reshape(T, -1)[:, busy]  # (T, n)
        tau = (TEST_SIGMAS * np.sqrt(2.0) * noise.sigma(d)).astype(np.float32)
        viol = np.zeros(d.shape, dtype=np.int16)
        cons = np.zeros(d.shape, dtype=np.int16)
        with np.errstate(invalid="ignore"):
            for j in range(T):
                diff = d[j][None] - d
                viol += diff > tau
                cons += np.abs(diff) <= tau
        cons -= np.isfinite(d)  # the reading itself
        st = verdict_status(viol, cons)
        st[~np.isfinite(d)] = UNKNOWN
        flat = out.reshape(T, -1)
        flat[:, busy] = st
    for t in range(T):
        out[t] = despeckle(out[t])
    return out


def motion_status(clouds: list[TimeCloud], cameras: dict[str, CameraInfo], noise: DepthNoise,
                  points: list[np.ndarray] | None = None, max_other_steps: int = MAX_OTHER_STEPS) -> list[np.ndarray]:
    """Per time step, (M_t,) int8 status of its points (``points``, default the fused points):
    STATIC, UNKNOWN or MOVING from free-space tests against the views of up to
    ``max_other_steps`` other time steps spread over the sequence (module doc).  Works for any
    camera motion; :func:`pixel_status` is the fast path for static cameras."""
    n = len(clouds)
    # each image padded once (it is read from up to max_other_steps other steps)
    padded = thread_map(lambda c: [padded_depth(v.depth) for v in c.views], clouds)

    def status_of(i: int) -> np.ndarray:
        pts = clouds[i].points if points is None else points[i]
        others = [j for j in range(n) if j != i]
        if len(others) > max_other_steps:
            others = [others[k] for k in np.unique(np.round(np.linspace(0, len(others) - 1, max_other_steps)).astype(int))]
        violated = np.zeros(len(pts), dtype=int)
        consistent = np.zeros(len(pts), dtype=int)
        for j in others:
            for view, window in zip(clouds[j].views, padded[j]):
                cam = view.camera or cameras[view.frame.camera]
                verdict = free_space_test(pts, cam, view.frame.T_world_camera, window, noise)
                violated += verdict < 0
                consistent += verdict > 0
        return verdict_status(violated, consistent)

    return thread_map(status_of, range(n))
