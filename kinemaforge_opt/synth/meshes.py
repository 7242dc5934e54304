"""Mesh building blocks for procedural objects: axis-aligned panels, handles, and rigid-body
inertia from mesh volume × density (trimesh).

Every mesh is a union of *disjoint* closed boxes, so the signed-volume integrals trimesh uses
for mass properties add up exactly (no double-counted overlaps).  Coordinates in metres.
"""

from __future__ import annotations

import numpy as np
import trimesh

from ..model import Inertial


def box(lo, hi) -> trimesh.Trimesh:
    """Closed axis-aligned box spanning corners ``lo`` (3,) and ``hi`` (3,) [m]."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    if np.any(hi - lo <= 0):
        raise ValueError(f"box corners must satisfy lo < hi, got lo={lo.tolist()} hi={hi.tolist()}")
    return trimesh.creation.box(extents=hi - lo, transform=trimesh.transformations.translation_matrix((lo + hi) / 2))


def union(parts: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """Concatenate disjoint closed parts into one mesh."""
    return trimesh.util.concatenate(parts)


def open_box(width: float, depth: float, height: float, wall: float, front_open: bool = True) -> trimesh.Trimesh:
    """A carcass of ``wall``-thick panels spanning x ∈ [-w/2, w/2], y ∈ [0, depth], z ∈ [0, height]
    (front at y = 0, open when ``front_open``).  Panels are disjoint: sides full height, top and
    bottom between the sides, back between sides, top and bottom."""
    w2 = width / 2
    parts = [
        box([-w2, 0, 0], [-w2 + wall, depth, height]),  # left side
        box([w2 - wall, 0, 0], [w2, depth, height]),  # right side
        box([-w2 + wall, 0, 0], [w2 - wall, depth, wall]),  # bottom
        box([-w2 + wall, 0, height - wall], [w2 - wall, depth, height]),  # top
        box([-w2 + wall, depth - wall, wall], [w2 - wall, depth, height - wall]),  # back
    ]
    if not front_open:
        parts.append(box([-w2 + wall, 0, wall], [w2 - wall, wall, height - wall]))
    return union(parts)


def bar_handle(center, along: int, length: float, standoff: float, outward, thickness: float = 0.012) -> trimesh.Trimesh:
    """A bar handle: a bar of ``length`` along coordinate ``along`` (0, 1 or 2), held ``standoff``
    away from a surface by two posts.  ``center`` (3,) is the point on the surface under the bar's
    middle; ``outward`` (3,) is the unit surface normal (an axis direction)."""
    c = np.asarray(center, dtype=float)
    n = np.asarray(outward, dtype=float)
    t = thickness
    e_along = np.eye(3)[along]
    half = np.abs(e_along) * length / 2 + (1 - np.abs(e_along) - np.abs(n)) * t / 2
    bar_c = c + n * (standoff + t / 2)
    bar = box(bar_c - half - np.abs(n) * t / 2, bar_c + half + np.abs(n) * t / 2)
    posts = []
    for s in (-1.0, 1.0):
        pc = c + e_along * s * (length / 2 - t / 2) + n * standoff / 2
        ph = (1 - np.abs(n)) * t / 2 + np.abs(n) * standoff / 2
        posts.append(box(pc - ph, pc + ph))
    return union([bar, *posts])


def handle_grip_point(center, standoff: float, outward, thickness: float = 0.012) -> np.ndarray:
    """Where a hand grips the handle made by :func:`bar_handle` with the same arguments (3,) [m]."""
    return np.asarray(center, dtype=float) + np.asarray(outward, dtype=float) * (standoff + thickness / 2)


def inertial_from_mesh(mesh: trimesh.Trimesh, density: float) -> Inertial:
    """Mass [kg], centre of mass [m] and inertia about it [kg m²] of a closed mesh of uniform
    ``density`` [kg/m³], in the mesh's frame."""
    if not mesh.is_volume:
        raise ValueError("inertia needs a closed, consistently oriented mesh")
    props = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    props.density = float(density)
    I = np.asarray(props.moment_inertia, dtype=float)
    return Inertial(float(props.mass), np.asarray(props.center_mass, dtype=float), (I + I.T) / 2)
