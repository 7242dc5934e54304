"""Exact synthetic worlds for the screw-axis NLP: a box-shaped part on a known joint, its exact
surface at the zero configuration, exact observed points along a known trajectory, and, for the
dynamics, a trajectory integrated independently (scipy ``solve_ivp`` on pinocchio's numeric ABA)
under a known pushing force."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.integrate import solve_ivp

from kinemaforge_opt.io.sequence import Wrenches
from kinemaforge_opt.model import ArticulatedModel, Inertial, Joint, JointDynamics, JointLimits, Link
from kinemaforge_opt.model.pinocchio import build_pin_model
from kinemaforge_opt.nlp.reconstruction import ScrewData
from kinemaforge_opt.nlp.visual import SurfaceModel
from kinemaforge_opt.spatial import exp_so3, make_transform, normalize

BOX = np.array([0.4, 0.04, 0.6])  # door slab size [m]


def box_surface(size: np.ndarray, center: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on the faces of an axis-aligned box on a regular grid, with exact outward normals."""
    pts, nrm = [], []
    half = size / 2
    for axis in range(3):
        u, w = [a for a in range(3) if a != axis]
        gu = np.arange(-half[u], half[u] + 1e-12, spacing)
        gw = np.arange(-half[w], half[w] + 1e-12, spacing)
        U, W = np.meshgrid(gu, gw, indexing="ij")
        for sign in (-1.0, 1.0):
            p = np.zeros((U.size, 3))
            p[:, u], p[:, w], p[:, axis] = U.ravel(), W.ravel(), sign * half[axis]
            nn = np.zeros_like(p)
            nn[:, axis] = sign
            pts.append(p + center)
            nrm.append(nn)
    return np.concatenate(pts), np.concatenate(nrm)


def box_inertial(mass: float, size: np.ndarray, com: np.ndarray) -> Inertial:
    """A uniform box of ``mass`` [kg] and ``size`` (3,) [m] centred at ``com`` (link frame)."""
    sx, sy, sz = np.asarray(size, float) ** 2
    return Inertial(mass, np.asarray(com, float), mass / 12 * np.diag([sy + sz, sx + sz, sx + sy]))


def door_model(axis_world, origin_world, kind: str = "revolute", damping: float = 0.0, pitch: float = 0.0,
               gravity=(0.0, 0.0, -9.81), inertial: Inertial | None = None, body_origin=None) -> ArticulatedModel:
    """Base (the world) + one box door on a joint through ``origin_world`` along ``axis_world``.
    The door's link frame is the joint frame at q = 0 (world-aligned, at the origin).  Its mass
    properties: a uniform 3 kg slab of size BOX beside ``body_origin`` (default the joint origin;
    a closed form whose joint is off keeps the measured slab where it is) unless ``inertial`` says
    otherwise.  With gravity along −y (the slab's face normal) the door is a lid: the hinge is
    horizontal."""
    body_origin = origin_world if body_origin is None else body_origin
    center = np.asarray(body_origin) + np.array([BOX[0] / 2 + 0.01, 0.0, 0.0])
    inertial = box_inertial(3.0, BOX, center - origin_world) if inertial is None else inertial
    links = (Link("base"), Link("door", inertial))
    joint = Joint("hinge", kind, "base", "door", make_transform(np.eye(3), np.asarray(origin_world, float)),
                  normalize(np.asarray(axis_world, float)), pitch, JointLimits(-2.0, 2.0), JointDynamics(damping=damping))
    return ArticulatedModel("door", links, (joint,), np.asarray(gravity, float))


def door_surface_world(model: ArticulatedModel, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """The door's exact surface at q = 0 (world)."""
    j = model.joint("hinge")
    center = j.T_parent_joint[:3, 3] + model.link("door").inertial.com
    return box_surface(BOX, center, spacing)


def moved(model: ArticulatedModel, q: float, pts: np.ndarray, nrm: np.ndarray | None = None):
    """Points (and normals) of the door at joint value q (world)."""
    j = model.joint("hinge")
    a = j.axis
    o = j.T_parent_joint[:3, 3]
    if j.type == "prismatic":
        return pts + q * a, nrm
    R = exp_so3(a * q)
    out = (pts - o) @ R.T + o + (j.pitch * q * a if j.type == "helical" else 0.0)
    return out, (None if nrm is None else nrm @ R.T)


def exact_data(true: ArticulatedModel, init: ArticulatedModel, times: np.ndarray, q_true: np.ndarray,
               q_init: np.ndarray, spacing: float = 0.01, wrenches: Wrenches | None = None, rng=None) -> ScrewData:
    """ScrewData with the exact surface of ``true`` and exact observed points (a random subset
    of a finer surface sampling, different at each step) of it moved to ``q_true``."""
    rng = rng or np.random.default_rng(0)
    S, Nrm = door_surface_world(true, spacing)
    fine, _ = door_surface_world(true, spacing / 2.3)
    obs = []
    for q in q_true:
        pts = fine[rng.choice(len(fine), 400, replace=False)]
        obs.append(moved(true, q, pts)[0])
    pushed = None if wrenches is None else np.array(["door"] * wrenches.t.size, dtype=object)
    return ScrewData(init, times, q_init[:, None], {"door": obs}, {"door": SurfaceModel("door", S, Nrm)},
                     delta=0.002, gate=0.05, wrenches=wrenches, pushed_link=pushed)


def noisy_door_data(true: ArticulatedModel, init: ArticulatedModel, sigma: float, seed: int = 0,
                    surface_faces=None, delta: float = 0.002, opening: float = 1.4) -> tuple[ScrewData, np.ndarray]:
    """The door ``true`` opening to ``opening`` [rad, or m for a drawer] over 8 frames, 400
    observed points per frame from every face with isotropic Gaussian noise ``sigma`` [m], the
    closed form ``init`` (its q with 0.03 noise); the surface model holds the faces where
    ``surface_faces(normals)`` is True (default: all).  Returns (ScrewData, true q (8,))."""
    times = np.linspace(0.0, 2.0, 8)
    q = opening * np.sin(0.7 * times)
    rng = np.random.default_rng(seed)
    S, N = door_surface_world(true, 0.01)
    fine, _ = door_surface_world(true, 0.01 / 2.3)
    obs = [moved(true, qk, fine[rng.choice(len(fine), 400, replace=False)])[0] + rng.normal(0, sigma, (400, 3)) for qk in q]
    keep = np.ones(len(N), bool) if surface_faces is None else surface_faces(N)
    data = ScrewData(init, times, (q + rng.normal(0, 0.03, q.size))[:, None], {"door": obs},
                     {"door": SurfaceModel("door", S[keep], N[keep])}, delta=delta, gate=0.05)
    return data, q


def pushed_trajectory(model: ArticulatedModel, duration: float, hz: float, push_s: float, force: float):
    """Integrate the door pushed at its far edge by a force of ``force`` [N] normal to the door for
    ``push_s`` [s] (then released), with pinocchio's numeric ABA and the model's damping.  Returns
    (t (N,), q (N,), wrenches sampled at ``hz``)."""
    pm = build_pin_model(model)
    pd = pm.createData()
    j = model.joint("hinge")
    o, a = j.T_parent_joint[:3, 3], j.axis
    grip0 = o + np.array([BOX[0], -BOX[1] / 2, 0.0])  # far edge, front face
    b = model.joint("hinge").dynamics.damping

    def wrench(t, q):
        R = exp_so3(a * q)
        p = (grip0 - o) @ R.T + o
        f = (R @ np.array([0.0, 1.0, 0.0])) * (force if t < push_s else 0.0)
        return p, f

    def rhs(t, x):
        p, f = wrench(t, x[0])
        tau = a @ np.cross(p - o, f) - b * x[1]
        return [x[1], pin.aba(pm, pd, np.array([x[0]]), np.array([x[1]]), np.array([tau]))[0]]

    t = np.arange(0.0, duration + 1e-9, 1.0 / hz)
    sol = solve_ivp(rhs, (0, duration), [0.0, 0.0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=0.01)
    q = sol.y[0]
    pf = [wrench(tt, qq) for tt, qq in zip(t, q)]
    return t, q, sol.y[1], Wrenches(t, np.array([p for p, _ in pf]), np.array([f for _, f in pf]))


def two_doors(axis_world, origin_a, origin_b, damping_a: float) -> ArticulatedModel:
    """Base + two box doors on their own hinges ("hinge_a" -> "door_a", "hinge_b" -> "door_b"),
    each like :func:`door_model`'s door; only hinge_a has damping."""
    links, joints = [Link("base")], []
    for name, origin, b in (("a", origin_a, damping_a), ("b", origin_b, 0.0)):
        origin = np.asarray(origin, float)
        links.append(Link(f"door_{name}", box_inertial(3.0, BOX, [BOX[0] / 2 + 0.01, 0.0, 0.0])))
        joints.append(Joint(f"hinge_{name}", "revolute", "base", f"door_{name}", make_transform(np.eye(3), origin),
                            normalize(np.asarray(axis_world, float)), 0.0, JointLimits(-2.0, 2.0), JointDynamics(damping=b)))
    return ArticulatedModel("doors", tuple(links), tuple(joints))


def two_door_data(true: ArticulatedModel, init: ArticulatedModel, times: np.ndarray, q_true: np.ndarray,
                  q_init: np.ndarray, wrenches: Wrenches, point_sigma: float, rng=None) -> ScrewData:
    """ScrewData for :func:`two_doors`: per door its exact surface and 400 surface points per step
    moved to ``q_true`` (T, 2), with Gaussian noise of ``point_sigma`` [m]; the force acts on door_a."""
    rng = rng or np.random.default_rng(0)
    observed, surfaces = {}, {}
    for k, j in enumerate(true.joints):
        o, a = j.T_parent_joint[:3, 3], j.axis
        center = o + true.link(j.child).inertial.com
        S, Nrm = box_surface(BOX, center, 0.01)
        fine, _ = box_surface(BOX, center, 0.01 / 2.3)
        obs = []
        for q in q_true[:, k]:
            pts = fine[rng.choice(len(fine), 400, replace=False)]
            obs.append((pts - o) @ exp_so3(a * q).T + o + rng.normal(0.0, point_sigma, pts.shape))
        observed[j.child], surfaces[j.child] = obs, SurfaceModel(j.child, S, Nrm)
    pushed = np.array(["door_a"] * wrenches.t.size, dtype=object)
    return ScrewData(init, times, q_init, observed, surfaces, delta=0.002, gate=0.05, wrenches=wrenches, pushed_link=pushed)


def seen_door_data(true: ArticulatedModel, init: ArticulatedModel, cameras: np.ndarray, sigma: float,
                   seed: int = 0, sightlines: bool = True) -> tuple[ScrewData, np.ndarray]:
    """The door ``true`` opening to 1.4 rad over 8 frames as the ``cameras`` (C, 3) [m] see it: of
    each face only the steps it faces a camera (a convex slab hides nothing else), 400 points per
    step with Gaussian noise ``sigma`` [m], each with its sightline (the mean unit vector towards
    the cameras it faces).  The surface model is what the zero step shows, its normals facing the
    cameras, as perception builds it.  With ``sightlines`` False the data carry none (no far-side
    test).  Returns (ScrewData, true q (8,))."""
    times = np.linspace(0.0, 2.0, 8)
    q = 1.4 * np.sin(0.7 * times)
    rng = np.random.default_rng(seed)
    fine, fine_n = door_surface_world(true, 0.01 / 2.3)

    def seen(qk):
        pts, nrm = moved(true, qk, fine, fine_n)
        to_cam = cameras[None] - pts[:, None]  # (N, C, 3)
        faces = np.einsum("nk,nck->nc", nrm, to_cam) > 0
        unit = to_cam / np.linalg.norm(to_cam, axis=2, keepdims=True)
        sight = (unit * faces[..., None]).sum(axis=1)
        keep = faces.any(axis=1)
        return pts[keep], sight[keep] / np.linalg.norm(sight[keep], axis=1, keepdims=True), nrm[keep]

    obs, sights = [], []
    for qk in q:
        pts, sight, _ = seen(qk)
        pick = rng.choice(len(pts), 400, replace=False)
        obs.append(pts[pick] + rng.normal(0, sigma, (400, 3)))
        sights.append(sight[pick])
    S, _, N = seen(0.0)
    S, N = S[::5], N[::5]
    data = ScrewData(init, times, (q + rng.normal(0, 0.03, q.size))[:, None], {"door": obs},
                     {"door": SurfaceModel("door", S, N, oriented=sightlines)}, delta=max(sigma, 0.002), gate=0.05,
                     sightlines={"door": sights} if sightlines else None)
    return data, q
