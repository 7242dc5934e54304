"""Per-part surfaces from fused points and their mass properties (trimesh).

A part is seen only from the cameras' side, so its points do not enclose a volume; the convex
hull is the closed surface used for visual and collision geometry (Drake needs closed convex
collision meshes anyway) and for the mass properties at a uniform density.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from ..errors import DataError


@dataclass(frozen=True, eq=False)
class PartSurface:
    """mesh: closed convex surface in the link frame [m].  mass [kg], com (3,) [m] and inertia
    (3, 3) about the com [kg m²], link-frame axes, at the given density."""

    mesh: trimesh.Trimesh
    mass: float
    com: np.ndarray
    inertia: np.ndarray


def part_surface(points_link: np.ndarray, density: float, name: str) -> PartSurface:
    """Convex hull of (N, 3) link-frame points [m] and its mass properties at ``density`` [kg/m³]."""
    if len(points_link) < 4:
        raise DataError(f"part {name!r} has {len(points_link)} points; a surface needs at least 4")
    try:
        hull = trimesh.convex.convex_hull(points_link)
    except Exception as e:  # qhull refuses flat or degenerate point sets
        raise DataError(f"part {name!r}: its points span no volume ({e})") from None
    hull.density = float(density)
    inertia = np.asarray(hull.moment_inertia, dtype=float)
    return PartSurface(hull, float(hull.mass), np.asarray(hull.center_mass, dtype=float), (inertia + inertia.T) / 2)


def obj_text(mesh: trimesh.Trimesh) -> str:
    """Wavefront OBJ text of ``mesh`` (vertices and faces only)."""
    return trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=False)
