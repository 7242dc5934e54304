"""Pixel labels where the object meets the environment, decided by colour.

Depth cannot tell an object's lowest centimetre or two from the floor it stands on: those points
lie inside the environment plane's band (3 σ of the depth noise, at most the inlier distance),
and at the fused cloud's voxel they share cells with the floor.  On the held-out 640×480
instances that strip was most of what the part IoU lost outside the drawers: a cabinet's body
and a laptop's base labelled environment along their bottom edges.  The RGB image still tells
them apart, as a rule: the object is painted or lit differently from the floor beside it.

Per image, on the grid of kept pixels (the depth stride): every pixel labelled environment within
``reach`` cells of a pixel labelled object (the base or a part) is a *candidate*.  References are
the object pixels within 2·reach cells of the environment and the environment pixels in the ring
reach < d ≤ 3·reach around the object (both sides of the boundary, near enough to share its
lighting).  A candidate takes the object's side when all its ``k`` nearest references in CIELAB
colour are object pixels, and then the label of the nearest object pixel in the image; any
disagreement leaves it environment, so where the object is painted like its floor the depth-only
labels mostly stand.  Colour alone, not colour and image position: on the ten held-out instances
weighing in the position (2 Lab units per grid cell) took the mean part IoU to 0.953 against
0.957 without it — a pixel of the strip lies nearer, in the image, to the floor's references just
below it than to the object's above.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

CONTACT_REACH = 4
"""Grid cells (kept pixels) from the object within which environment pixels are candidates (the
strip is 1–2 cm; mean part IoU on the ten held-out instances 0.9544 / 0.9568 / 0.9568 at 2 / 4 / 6)."""
COLOUR_NEIGHBOURS = 15
"""References consulted per candidate; all must be object pixels.  Where object and floor share
a colour the references a candidate finds are a mix, and all of k = 5 are the object's for ~3 %
of such floor pixels (≈ 0.5⁵); at 15 for none in practice.  A distinct colour finds 15 as easily:
the ten held-out instances' mean part IoU reads 0.9568 at k = 5 and 0.9565 at 15."""


def relabel_contact_by_colour(pixels: np.ndarray, labels: np.ndarray, stride: int, rgb: np.ndarray,
                              environment: str, reach: int = CONTACT_REACH,
                              k: int = COLOUR_NEIGHBOURS) -> np.ndarray:
    """(N,) ``labels`` of the kept ``pixels`` (N, 2) (row, column in the full image, on a grid of
    step ``stride``) with the environment pixels next to the object that colour puts on the
    object relabelled (module doc).  ``rgb``: (H, W, 3) uint8 image of the same frame;
    ``environment``: the environment's label.  Returns a new array; ``labels`` is unchanged."""
    labels = np.asarray(labels)
    env = labels == environment
    if env.all() or not env.any():
        return labels.copy()
    r, c = pixels[:, 0] // stride, pixels[:, 1] // stride
    shape = (int(r.max()) + 1, int(c.max()) + 1)
    to_object = _grid_distance(r[~env], c[~env], shape)[r, c]
    to_environment = _grid_distance(r[env], c[env], shape)[r, c]
    candidate = env & (to_object <= reach)
    ref_object = ~env & (to_environment <= 2 * reach)
    ref_environment = env & (to_object > reach) & (to_object <= 3 * reach)
    if not candidate.any() or ref_object.sum() < k or ref_environment.sum() < k:
        return labels.copy()
    lab = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2LAB)[pixels[:, 0], pixels[:, 1]].astype(float)
    refs = np.concatenate([lab[ref_object], lab[ref_environment]])
    ref_is_object = np.r_[np.ones(ref_object.sum(), bool), np.zeros(ref_environment.sum(), bool)]
    nearest = cKDTree(refs).query(lab[candidate], k, workers=-1)[1].reshape(-1, k)
    take = np.flatnonzero(candidate)[ref_is_object[nearest].all(axis=1)]
    out = labels.copy()
    if take.size:
        obj = np.flatnonzero(~env)
        owner = cKDTree(np.stack([r[obj], c[obj]], axis=1)).query(np.stack([r[take], c[take]], axis=1))[1]
        out[take] = labels[obj[owner]]
    return out


def _grid_distance(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) Euclidean distance [grid cells] of every cell to the nearest of the given cells."""
    mask = np.ones(shape, dtype=bool)
    mask[rows, cols] = False
    return distance_transform_edt(mask)
