"""Procedural articulated objects: cabinet, drawer, laptop, refrigerator, microwave and a
cabinet with a door and a drawer.  Seeded, with dimension ranges of real furniture/appliances.

World frame: z up, the object stands on z = 0 with its front face in the plane y = 0 and its
body behind it (y > 0); cameras look from y < 0.  Every moving part is a child of the root link
``body``; its joint frame has identity rotation, so the joint axis is also the world axis.
Masses come from mesh volume × density (see :func:`meshes.inertial_from_mesh`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from ..errors import UnknownNameError
from ..io.atomic import atomic_path
from ..model import ArticulatedModel, Geometry, Joint, JointLimits, Link
from ..spatial import inverse, make_transform
from .meshes import bar_handle, box, handle_grip_point, inertial_from_mesh, open_box, union

ROOT = "body"


@dataclass(frozen=True)
class Handle:
    """Where the hand grips a part: ``link`` and the grip point ``p_link`` (3,) in its frame [m]."""

    link: str
    p_link: tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class SynthObject:
    """A procedural object.

    model: the nominal ArticulatedModel; each link's visual/collision mesh is
    ``meshes/<link>.obj`` relative to the URDF folder.  meshes: link name -> mesh in the link
    frame [m].  handles: movable joint name -> :class:`Handle`.  colors: link name -> RGB in [0, 1].
    category: e.g. "cabinet".  seed: the generator seed.
    """

    category: str
    seed: int
    model: ArticulatedModel
    meshes: dict[str, trimesh.Trimesh]
    handles: dict[str, Handle]
    colors: dict[str, tuple[float, float, float]]


@dataclass
class _Part:
    """A moving part built in world coordinates at q = 0."""

    link: str
    joint_type: str
    p_world_joint: np.ndarray
    axis: np.ndarray
    limits: tuple[float, float]
    mesh_world: trimesh.Trimesh
    grip_world: np.ndarray
    density: float
    color: tuple[float, float, float]


def mesh_path(link: str) -> str:
    """Mesh filename of ``link`` relative to the URDF folder."""
    return f"meshes/{link}.obj"


def write_meshes(obj: SynthObject, urdf_dir: str | Path) -> list[Path]:
    """Write every link mesh as ``<urdf_dir>/meshes/<link>.obj`` atomically; returns the paths."""
    out = []
    for link, mesh in obj.meshes.items():
        path = Path(urdf_dir) / mesh_path(link)
        with atomic_path(path) as tmp:
            tmp.write_text(trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=False))
        out.append(path)
    return out


def _assemble(name: str, category: str, seed: int, body_mesh, body_density, body_color, parts: list[_Part]) -> SynthObject:
    def link(lname, mesh, density, color):
        g = Geometry("mesh", filename=mesh_path(lname), rgba=(*color, 1.0))
        return Link(lname, inertial_from_mesh(mesh, density), (g,), (g,))

    links = [link(ROOT, body_mesh, body_density, body_color)]
    joints, meshes, handles = [], {ROOT: body_mesh}, {}
    colors = {ROOT: body_color}
    for p in parts:
        T_world_joint = make_transform(None, p.p_world_joint)
        mesh_link = p.mesh_world.copy()
        mesh_link.apply_transform(inverse(T_world_joint))
        links.append(link(p.link, mesh_link, p.density, p.color))
        jname = f"{p.link}_joint"
        joints.append(
            Joint(jname, p.joint_type, ROOT, p.link, T_world_joint, p.axis,
                  limits=JointLimits(p.limits[0], p.limits[1], effort=200.0, velocity=10.0))
        )
        meshes[p.link] = mesh_link
        colors[p.link] = p.color
        handles[jname] = Handle(p.link, tuple(float(x) for x in p.grip_world - p.p_world_joint))
    model = ArticulatedModel(name, tuple(links), tuple(joints))
    return SynthObject(category, seed, model, meshes, handles, colors)


def _hinged_door(link, x0, x1, z0, z1, t, hinge_left, rng, density, color, handle_z=None, handle_len=None, standoff=0.03):
    """A door slab x ∈ [x0, x1], y ∈ [-t, 0], z ∈ [z0, z1] hinged about a vertical axis at its
    outer front edge; opening (q > 0) swings it towards -y."""
    slab = box([x0, -t, z0], [x1, 0.0, z1])
    hz = (z0 + z1) / 2 if handle_z is None else handle_z
    hlen = handle_len if handle_len is not None else min(0.8 * (z1 - z0), rng.uniform(0.10, 0.20))
    hx = x1 - 0.05 if hinge_left else x0 + 0.05
    centre = np.array([hx, -t, hz])
    out = np.array([0.0, -1.0, 0.0])
    mesh = union([slab, bar_handle(centre, 2, hlen, standoff, out)])
    hinge_x = x0 if hinge_left else x1
    axis = np.array([0.0, 0.0, -1.0 if hinge_left else 1.0])
    upper = float(rng.uniform(1.6, 2.0))
    return _Part(link, "revolute", np.array([hinge_x, -t, z0]), axis, (0.0, upper), mesh,
                 handle_grip_point(centre, standoff, out), density, color)


def _drawer(link, W, D, wall, z0, h, t, gap, rng, density, color):
    """A drawer in a carcass of inner width W - 2 wall and depth D, slot z ∈ [z0, z0 + h];
    it slides out along -y (q > 0 = open)."""
    xi = W / 2 - wall - 0.006  # tray half-width with running clearance
    zb = z0 + gap + 0.01
    ht = 0.7 * (h - 2 * gap)
    depth = D - wall - 0.02
    tw = 0.012
    front = box([-W / 2 + gap, -t, z0 + gap], [W / 2 - gap, 0.0, z0 + h - gap])
    tray = [
        box([-xi, 0.0, zb], [-xi + tw, depth, zb + ht]),
        box([xi - tw, 0.0, zb], [xi, depth, zb + ht]),
        box([-xi + tw, 0.0, zb], [xi - tw, depth - tw, zb + tw]),
        box([-xi + tw, depth - tw, zb], [xi - tw, depth, zb + ht]),
    ]
    centre = np.array([0.0, -t, z0 + h / 2])
    out = np.array([0.0, -1.0, 0.0])
    standoff = 0.03
    handle = bar_handle(centre, 0, min(0.5 * W, rng.uniform(0.10, 0.25)), standoff, out)
    mesh = union([front, *tray, handle])
    upper = float(0.75 * depth)
    return _Part(link, "prismatic", np.array([0.0, -t, z0]), np.array([0.0, -1.0, 0.0]), (0.0, upper), mesh,
                 handle_grip_point(centre, standoff, out), density, color)


def _wood(rng) -> tuple[float, float, float]:
    base = np.array([0.72, 0.55, 0.38]) * rng.uniform(0.85, 1.15)
    return tuple(float(c) for c in np.clip(base, 0, 1))


def _shade(rgb, f) -> tuple[float, float, float]:
    return tuple(float(c) for c in np.clip(np.asarray(rgb) * f, 0, 1))


def make_cabinet(seed: int) -> SynthObject:
    """A cabinet with 1 or 2 hinged doors (single door hinged left or right; a pair hinged outwards).
    Width 0.40–1.00 m, height 0.60–0.95 m, depth 0.35–0.60 m, MDF panels 18 mm at 650–750 kg/m³."""
    rng = np.random.default_rng(seed)
    W, H, D = rng.uniform(0.40, 1.00), rng.uniform(0.60, 0.95), rng.uniform(0.35, 0.60)
    wall, t, gap = 0.018, 0.018, 0.003
    rho = rng.uniform(650, 750)
    color = _wood(rng)
    n_doors = 2 if W > 0.7 and rng.random() < 0.7 else 1
    parts = []
    if n_doors == 1:
        left = bool(rng.random() < 0.5)
        parts.append(_hinged_door("door", -W / 2 + gap, W / 2 - gap, gap, H - gap, t, left, rng, rho, _shade(color, 0.9)))
    else:
        parts.append(_hinged_door("door_left", -W / 2 + gap, -gap, gap, H - gap, t, True, rng, rho, _shade(color, 0.9)))
        parts.append(_hinged_door("door_right", gap, W / 2 - gap, gap, H - gap, t, False, rng, rho, _shade(color, 0.85)))
    return _assemble(f"cabinet_{seed}", "cabinet", seed, open_box(W, D, H, wall), rho, color, parts)


def make_drawer(seed: int) -> SynthObject:
    """A chest with 1–3 prismatic drawers stacked vertically.  Width 0.40–0.80 m, depth
    0.35–0.55 m, drawer heights 0.12–0.25 m, 18 mm MDF."""
    rng = np.random.default_rng(seed)
    W, D = rng.uniform(0.40, 0.80), rng.uniform(0.35, 0.55)
    wall, t, gap = 0.018, 0.018, 0.003
    rho = rng.uniform(650, 750)
    color = _wood(rng)
    n = int(rng.integers(1, 4))
    heights = rng.uniform(0.12, 0.25, size=n)
    H = float(heights.sum() + 2 * wall)
    body = [open_box(W, D, H, wall)]
    parts, z = [], wall
    for i, h in enumerate(heights):
        if i > 0:  # divider between slots, 10 mm, disjoint from the carcass panels
            body.append(box([-W / 2 + wall, 0.0, z - 0.005], [W / 2 - wall, D - wall, z + 0.005]))
        parts.append(_drawer(f"drawer_{i}", W, D, wall, z, h, t, gap, rng, rho, _shade(color, 0.9 - 0.05 * i)))
        z += h
    return _assemble(f"drawer_{seed}", "drawer", seed, union(body), rho, color, parts)


def make_laptop(seed: int) -> SynthObject:
    """A laptop: base 0.30–0.38 m × 0.21–0.26 m, lid hinged about a horizontal (x) axis at the back
    edge; q = 0 is closed and opening (q > 0) lifts the lid against gravity."""
    rng = np.random.default_rng(seed)
    W, D = rng.uniform(0.30, 0.38), rng.uniform(0.21, 0.26)
    tb, tl = rng.uniform(0.012, 0.018), rng.uniform(0.006, 0.009)
    base = box([-W / 2, 0.0, 0.0], [W / 2, D, tb])
    lid = box([-W / 2, 0.0, tb], [W / 2, D, tb + tl])
    grey = float(rng.uniform(0.35, 0.75))
    part = _Part("lid", "revolute", np.array([0.0, D, tb]), np.array([-1.0, 0.0, 0.0]),
                 (0.0, float(rng.uniform(2.0, 2.4))), lid, np.array([0.0, 0.0, tb + tl / 2]),
                 float(rng.uniform(900, 1300)), (grey * 0.9, grey * 0.9, grey))
    return _assemble(f"laptop_{seed}", "laptop", seed, base, float(rng.uniform(1000, 1400)), (grey, grey, grey), [part])


def make_refrigerator(seed: int) -> SynthObject:
    """A refrigerator 1.50–1.90 m tall with one full-height door or a freezer door above a fridge
    door, hinged on the same side; doors 50–70 mm thick, effective density 200–320 kg/m³."""
    rng = np.random.default_rng(seed)
    W, D, H = rng.uniform(0.55, 0.80), rng.uniform(0.60, 0.72), rng.uniform(1.50, 1.90)
    wall, t, gap = 0.04, rng.uniform(0.05, 0.07), 0.004
    rho_door = rng.uniform(200, 320)
    white = tuple(float(c) for c in np.clip(rng.uniform(0.85, 0.97) * np.ones(3), 0, 1))
    left = bool(rng.random() < 0.5)
    hl = lambda: rng.uniform(0.25, 0.40)  # noqa: E731
    parts = []
    if rng.random() < 0.5:
        parts.append(_hinged_door("door", -W / 2 + gap, W / 2 - gap, gap, H - gap, t, left, rng, rho_door,
                                  _shade(white, 0.95), handle_z=0.6 * H, handle_len=hl(), standoff=0.04))
    else:
        zs = H * rng.uniform(0.60, 0.70)
        parts.append(_hinged_door("freezer_door", -W / 2 + gap, W / 2 - gap, zs + gap, H - gap, t, left, rng,
                                  rho_door, _shade(white, 0.95), handle_z=zs + 0.15, handle_len=0.2, standoff=0.04))
        parts.append(_hinged_door("fridge_door", -W / 2 + gap, W / 2 - gap, gap, zs - gap, t, left, rng,
                                  rho_door, _shade(white, 0.92), handle_z=zs - 0.25, handle_len=hl(), standoff=0.04))
    return _assemble(f"refrigerator_{seed}", "refrigerator", seed, open_box(W, D, H, wall), 300.0, white, parts)


def make_microwave(seed: int) -> SynthObject:
    """A microwave 0.45–0.55 m wide, 0.26–0.33 m tall: a box with a fixed control panel on the
    right and a door hinged on the left side."""
    rng = np.random.default_rng(seed)
    W, H, D = rng.uniform(0.45, 0.55), rng.uniform(0.26, 0.33), rng.uniform(0.33, 0.42)
    wall, t, gap, panel = 0.01, 0.03, 0.003, rng.uniform(0.10, 0.14)
    body = union([open_box(W, D, H, wall),
                  box([W / 2 - panel, -t, 0.0], [W / 2, 0.0, H])])  # control panel flush with the door
    dark = tuple(float(c) for c in rng.uniform(0.15, 0.3) * np.ones(3))
    door = _hinged_door("door", -W / 2, W / 2 - panel - gap, gap, H - gap, t, True, rng,
                        rng.uniform(400, 550), _shade(dark, 1.3), handle_len=0.6 * H, standoff=0.025)
    return _assemble(f"microwave_{seed}", "microwave", seed, body, 900.0, dark, [door])


def make_cabinet_multi(seed: int) -> SynthObject:
    """A cabinet with a drawer above a hinged door (two joints).  Width 0.45–0.70 m, depth
    0.40–0.55 m; drawer 0.15–0.20 m, door 0.45–0.60 m tall."""
    rng = np.random.default_rng(seed)
    W, D = rng.uniform(0.45, 0.70), rng.uniform(0.40, 0.55)
    wall, t, gap = 0.018, 0.018, 0.003
    hd, hdoor = rng.uniform(0.15, 0.20), rng.uniform(0.45, 0.60)
    H = float(wall + hdoor + hd + wall)
    rho = rng.uniform(650, 750)
    color = _wood(rng)
    z_div = wall + hdoor
    body = union([open_box(W, D, H, wall), box([-W / 2 + wall, 0.0, z_div - 0.005], [W / 2 - wall, D - wall, z_div + 0.005])])
    left = bool(rng.random() < 0.5)
    door = _hinged_door("door", -W / 2 + gap, W / 2 - gap, gap, z_div - gap, t, left, rng, rho, _shade(color, 0.9),
                        handle_z=z_div - 0.12)
    drawer = _drawer("drawer", W, D, wall, z_div, hd, t, gap, rng, rho, _shade(color, 0.85))
    return _assemble(f"cabinet_multi_{seed}", "cabinet_multi", seed, body, rho, color, [door, drawer])


GENERATORS = {
    "cabinet": make_cabinet,
    "drawer": make_drawer,
    "laptop": make_laptop,
    "refrigerator": make_refrigerator,
    "microwave": make_microwave,
    "cabinet_multi": make_cabinet_multi,
}


def make_object(category: str, seed: int) -> SynthObject:
    """The procedural object of ``category`` (one of :data:`GENERATORS`) for ``seed``."""
    if category not in GENERATORS:
        raise UnknownNameError("object category", category, GENERATORS)
    return GENERATORS[category](seed)
