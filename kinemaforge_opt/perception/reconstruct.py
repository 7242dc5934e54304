"""The RGB-D flow: sequence -> perception (``perceive``) -> kinematic tree -> URDF, meshes,
reconstruction.json, clouds.npz.  ``reconstruct_sequence(SEQ, OUT)`` is the whole flow with outputs.

Model conventions: the base link is the world frame.  The *zero configuration* is the first
time step at which every part is observed; every joint's q is measured from it (so limits are
the observed range relative to it).  Each moving link's frame is its joint frame at q = 0:
placed on the joint line (the fitted origin), oriented like its parent link.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from tqdm import tqdm

from ..errors import DataError
from ..graph import infer_tree
from ..graph.tree import GraphResult
from ..io.atomic import atomic_path, write_text_atomic
from ..io.sequence import load_sequence
from ..io.tracks import PoseTracks
from ..model import ArticulatedModel, Geometry, Inertial, Joint, JointLimits, Link, write_urdf
from ..spatial import inverse, make_transform
from .change import STATIC
from .perceive import Perception, perceive
from .surface import obj_text, part_surface

BASE, ENVIRONMENT = "base", "environment"
# Default density [kg/m³] of the convex part volumes: light wood / particle board, the material
# of typical furniture (a user who knows better passes --density).
DEFAULT_DENSITY = 300.0


def point_labels(per: Perception, part_of: dict[str, str]) -> list[np.ndarray]:
    """Per time step, (M_t,) part names of its fused points: a non-static point within the
    inlier distance of a tracked proposal takes the proposal's part (``part_of``: track name ->
    part name; the nearest proposal wins); static points on a background plane are ENVIRONMENT;
    the rest is BASE."""
    out = []
    for s, (c, st) in enumerate(zip(per.clouds, per.status)):
        labels = np.full(len(c.points), BASE, dtype=object)
        for plane in per.environment:
            labels[np.abs(plane.distance(c.points)) <= per.inlier_distance] = ENVIRONMENT
        best = np.full(len(c.points), np.inf)
        for p in per.proposals:
            moved = p.points_at(s)
            if moved is None:
                continue
            d = cKDTree(moved).query(c.points, distance_upper_bound=per.inlier_distance)[0]
            take = (d < best) & (st != STATIC)
            labels[take] = part_of[p.name]
            best[take] = d[take]
        out.append(labels)
    return out


def pixel_labels(per: Perception, labels: list[np.ndarray]) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Frame index -> ((N, 2) kept pixel (row, column) indices, (N,) part names), each kept pixel
    taking the label of its nearest fused point."""
    out = {}
    for c, lab in zip(per.clouds, labels):
        tree = cKDTree(c.points)
        for v in c.views:
            out[v.frame.index] = (v.pixels, lab[tree.query(v.points_world)[1]])
    return out


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """Result of :func:`reconstruct_sequence`.  perception, graph: the stage results.
    model: the ArticulatedModel written as URDF.  document: reconstruction.json's content.
    clouds_world: part name -> (N, 3) fused points at the zero configuration [m].
    labels: per time step the part name of each fused point."""

    perception: Perception
    graph: GraphResult
    model: ArticulatedModel
    document: dict
    clouds_world: dict[str, np.ndarray]
    labels: list[np.ndarray]


def _zero_step(tracks: PoseTracks, reps: list[int]) -> int:
    obs = tracks.observed()[reps].all(axis=0)
    if not obs.any():
        raise DataError("no time step sees every moving part at once; a zero configuration needs one")
    return int(np.argmax(obs))


def _representative(members: tuple[str, ...], tracks: PoseTracks) -> int:
    """Index of the member track observed most often (the graph's part representative)."""
    obs = tracks.observed().sum(axis=1)
    return max((tracks.names.index(m) for m in members), key=lambda k: obs[k])


def build_model(per: Perception, graph: GraphResult, density: float, name: str = "reconstruction"):
    """Kinematic tree + fused points -> (ArticulatedModel, joint records, part clouds at zero,
    meshes, point labels).  Joint records follow the reconstruction.json contract."""
    tracks, tree = per.tracks, graph.best
    part_of = {m: p for p, members in tree.parts.items() for m in members if m in tracks.names}
    reps = {p: _representative(m, tracks) for p, m in tree.parts.items() if p != tree.root}
    s0 = _zero_step(tracks, list(reps.values()))
    T_world_link0 = {tree.root: np.eye(4)}  # link frames at the zero configuration
    T_world_track0 = {p: tracks.Ts_world_track(k)[s0] for p, k in reps.items()}
    T_world_track0[tree.root] = np.eye(4)
    joints, records = [], []
    for j in tree.joints:
        h = j.hypothesis
        jtype = "fixed" if h.type == "rigid" else h.type
        T_wp = T_world_track0[j.parent]
        axis = T_wp[:3, :3] @ h.axis_parent if h.axis_parent is not None else np.array([1.0, 0.0, 0.0])
        origin = (T_wp[:3, :3] @ h.origin_parent + T_wp[:3, 3]) if h.origin_parent is not None else T_world_track0[j.child][:3, 3]
        T_world_joint = make_transform(T_world_link0[j.parent][:3, :3], origin)
        T_world_link0[j.child] = T_world_joint
        T_parent_joint = inverse(T_world_link0[j.parent]) @ T_world_joint
        axis_joint = T_world_joint[:3, :3].T @ axis
        # q from the graph is 0 at the pair's first common sample; shift it to the zero step
        common = tracks.observed()[reps[j.child]] & (
            tracks.observed()[reps[j.parent]] if j.parent in reps else True)
        q_times = tracks.times[common]
        q = np.asarray(h.q, dtype=float) - np.interp(tracks.times[s0], q_times, h.q)
        limits = JointLimits(float(q.min()), float(q.max())) if jtype != "fixed" else None
        joints.append(Joint(j.name, jtype, j.parent, j.child, T_parent_joint, axis_joint,
                            h.pitch if jtype == "helical" else 0.0, limits))
        records.append({
            "name": j.name, "type": jtype, "parent": j.parent, "child": j.child,
            "axis_world": axis.tolist(), "origin_world": origin.tolist(), "pitch": float(h.pitch),
            "limits": None if limits is None else [limits.lower, limits.upper],
            "confidence": float(h.confidence), "residual_rms_m": float(h.residual_rms),
            **({"radius": float(h.radius)} if h.radius is not None else {}),
        })
    labels = point_labels(per, part_of)
    # every point of every time step, moved to the zero configuration and into its link frame
    T_link_world = {}
    for p, k in reps.items():
        T_track0_link = inverse(T_world_track0[p]) @ T_world_link0[p]
        T_link_world[p] = [None if not tracks.observed()[k, s] else inverse(tracks.Ts_world_track(k)[s] @ T_track0_link)
                           for s in range(tracks.times.size)]
    points_link: dict[str, list[np.ndarray]] = {p: [] for p in tree.parts}
    for s, (c, lab) in enumerate(zip(per.clouds, labels)):
        points_link[tree.root].append(c.points[lab == BASE])
        for p in reps:
            if T_link_world[p][s] is not None:
                T = T_link_world[p][s]
                points_link[p].append(c.points[lab == p] @ T[:3, :3].T + T[:3, 3])
    links, clouds_world, meshes = [], {}, {}
    for p in [tree.root] + [j.child for j in tree.joints]:
        pts = np.concatenate(points_link[p])
        surf = part_surface(pts, density, p)
        meshes[p] = surf.mesh
        g = Geometry("mesh", filename=f"meshes/{p}.obj")
        links.append(Link(p, Inertial(surf.mass, surf.com, surf.inertia), (g,), (g,)))
        T = T_world_link0[p]
        clouds_world[p] = pts @ T[:3, :3].T + T[:3, 3]
    model = ArticulatedModel(name, tuple(links), tuple(joints))
    return model, records, clouds_world, meshes, labels


def reconstruct_sequence(seq_path: str | Path, out: str | Path | None = None, method: str = "graph",
                         k_best: int = 3, density: float = DEFAULT_DENSITY, show_progress: bool | None = None) -> Reconstruction:
    """RGB-D sequence folder -> :class:`Reconstruction`; with ``out``, also writes
    OUT/reconstruction.json, OUT/model.urdf, OUT/meshes/<link>.obj and OUT/clouds.npz.
    ``show_progress``: tqdm bar on stderr (None = only on a terminal)."""
    start = time.perf_counter()
    seq = load_sequence(seq_path)
    with tqdm(total=5, desc="load", disable=None if show_progress is None else not show_progress,
              unit="stage") as bar:
        per = perceive(seq, bar)
        t0 = time.perf_counter()
        graph = infer_tree(per.tracks, method=method, k_best=k_best)
        per.timing_s["graph"] = time.perf_counter() - t0
        bar.update(1)
        bar.set_description("graph")
        t0 = time.perf_counter()
        model, records, clouds_world, meshes, labels = build_model(per, graph, density)
        per.timing_s["model"] = time.perf_counter() - t0
        bar.update(1)
        bar.set_description("model")
    doc = {
        "joints": records,
        "links": [{"name": l.name, "mass": l.inertial.mass, "density": density,
                   "tracks": list(graph.best.parts[l.name])} for l in model.links],
        "alternatives": [{"log_score": t.log_score, "joints": [[j.parent, j.child, j.type] for j in t.joints]}
                         for t in graph.alternatives],
        "method": method,
        "perception": {"depth_noise_k_per_m": per.noise.k, "voxel_m": per.voxel,
                       "proposals": len(per.proposals), "environment_planes": len(per.environment)},
        "timing_s": {**per.timing_s, "total": time.perf_counter() - start},
    }
    if out is not None:
        out = Path(out)
        for p, mesh in meshes.items():
            write_text_atomic(out / "meshes" / f"{p}.obj", obj_text(mesh))
        write_urdf(model, out / "model.urdf")
        with atomic_path(out / "clouds.npz") as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **clouds_world)
        doc["timing_s"]["total"] = time.perf_counter() - start
        write_text_atomic(out / "reconstruction.json", json.dumps(doc, indent=2))
    return Reconstruction(per, graph, model, doc, clouds_world, labels)
