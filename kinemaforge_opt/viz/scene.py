"""A meshcat scene of an articulated model, built without a server and saved as static HTML.

meshcat-python normally talks to a zmq server that keeps the scene tree; here a
:class:`_RecordingWindow` stands in for it: it keeps the same tree (last ``set_object`` /
``set_transform`` per path wins, properties accumulate, one animation) and writes the same
self-contained HTML the server would (``main.min.js`` inlined, each command a base64 msgpack
blob), so ``scene.html`` opens from disk without a server.

Scene layout (meshcat paths)::

    /meshcat/clouds/<part>                         point cloud coloured by part
    /meshcat/<group>/<link>                        link frame, posed T_world_link (animated)
    /meshcat/<group>/<link>/visual_<i>             link geometry (mesh or primitive), or com
    /meshcat/<group>/<parent link>/joint_<j>/axis  joint axis arrow (shaft + head) at the joint frame
    /meshcat/<group>/<parent link>/joint_<j>/limit arc (revolute) or segment (prismatic) of the limits

``<group>`` names one copy of the model (e.g. ``recorded`` and ``simulated``).
"""

from __future__ import annotations

import base64
import os
from collections.abc import Mapping
from pathlib import Path

import meshcat
import meshcat.geometry as g
import numpy as np
import pinocchio as pin
import umsgpack
from meshcat.animation import Animation

from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..model import ArticulatedModel, Geometry, Joint
from ..model.pinocchio import build_pin_model

PALETTE = (0xE6194B, 0x3CB44B, 0x4363D8, 0xF58231, 0x911EB4, 0x42D4F4, 0xF032E6, 0xBFEF45, 0x9A6324, 0x800000)
AXIS_LENGTH_M = 0.2
LIMIT_RADIUS_M = 0.12
MAX_CLOUD_POINTS = 20000
"""Points shown per part cloud at most (see :meth:`Scene.add_point_clouds`)."""
_MESH_LOADERS = {".obj": g.ObjMeshGeometry, ".stl": g.StlMeshGeometry, ".dae": g.DaeMeshGeometry}


class _RecordingWindow:
    """Stands in for meshcat's ViewerWindow: records commands in a scene tree."""

    def __init__(self):
        self.nodes: dict[str, dict] = {}
        self.animation: bytes | None = None

    def send(self, command) -> None:
        data = command.lower()
        packed = umsgpack.packb(data)
        kind, path = data["type"], data.get("path", "")
        if kind == "set_animation":
            self.animation = packed
            return
        if kind == "delete":
            for p in [p for p in self.nodes if p == path or p.startswith(path + "/")]:
                del self.nodes[p]
            return
        node = self.nodes.setdefault(path, {"object": None, "transform": None, "properties": []})
        if kind == "set_object":
            node["object"], node["properties"] = packed, []
        elif kind == "set_transform":
            node["transform"] = packed
        elif kind == "set_property":
            node["properties"].append(packed)

    def blobs(self) -> list[bytes]:
        """The msgpack commands that rebuild the scene, parents before children."""
        out = []
        for path in sorted(self.nodes, key=lambda p: (p.count("/"), p)):
            node = self.nodes[path]
            out += [b for b in (node["object"], *node["properties"], node["transform"]) if b is not None]
        if self.animation is not None:
            out.append(self.animation)
        return out

    def get_scene(self) -> str:
        viewer_js = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
        commands = "".join(
            'fetch("data:application/octet-binary;base64,{}")\n'
            "    .then(res => res.arrayBuffer())\n"
            "    .then(buffer => viewer.handle_command_bytearray(new Uint8Array(buffer)));\n".format(
                base64.b64encode(b).decode("ascii")
            )
            for b in self.blobs()
        )
        return (
            "<!DOCTYPE html>\n<html>\n<head><meta charset=utf-8><title>kinemaforge scene</title></head>\n"
            '<body>\n<div id="meshcat-pane"></div>\n<script>\n'
            + viewer_js.read_text(encoding="utf-8")
            + '\n</script>\n<script>\nvar viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));\n'
            + commands
            + "</script>\n<style>body {margin: 0;} #meshcat-pane {width: 100vw; height: 100vh; overflow: hidden;}</style>\n"
            "</body>\n</html>\n"
        )


def decode_static_html(html: str) -> list[dict]:
    """The meshcat commands (decoded msgpack dicts) embedded in a static scene HTML, in order."""
    marker = "data:application/octet-binary;base64,"
    out = []
    for chunk in html.split(marker)[1:]:
        out.append(umsgpack.unpackb(base64.b64decode(chunk[: chunk.index('"')])))
    return out


class Scene:
    """A meshcat scene under construction; :meth:`save` writes it as static HTML."""

    def __init__(self):
        self._window = _RecordingWindow()
        self.vis = meshcat.Visualizer(window=self._window)

    # --- content -----------------------------------------------------------------------------
    def add_point_clouds(self, clouds: Mapping[str, np.ndarray], point_size_m: float = 0.005,
                         max_points: int = MAX_CLOUD_POINTS) -> None:
        """One point cloud per part, each (N, 3) world points [m], coloured by part.  A part with
        more than ``max_points`` points shows an evenly strided subset of them (every k-th point,
        deterministic), which keeps the static HTML small (~16 bytes per point, base64)."""
        for i, (part, points) in enumerate(clouds.items()):
            P = np.asarray(points, dtype=float)
            if P.ndim != 2 or P.shape[1] != 3:
                raise DataError(f"point cloud of part {part!r} must have shape (N, 3), got {P.shape}")
            if len(P) > max_points:
                P = P[np.linspace(0, len(P) - 1, max_points).astype(int)]
            rgb = np.array([(PALETTE[i % len(PALETTE)] >> s) & 0xFF for s in (16, 8, 0)]) / 255.0
            colors = np.tile(rgb, (len(P), 1))
            self.vis["clouds"][part].set_object(g.PointCloud(P.T.astype(np.float32), colors.T.astype(np.float32),
                                                             size=point_size_m))

    def add_model(
        self,
        model: ArticulatedModel,
        group: str = "model",
        q: np.ndarray | None = None,
        mesh_dir: str | os.PathLike | None = None,
        color: int | None = None,
        opacity: float = 1.0,
    ) -> None:
        """Links (meshes found under ``mesh_dir`` or primitives), joint axes and limits of
        ``model`` under ``/meshcat/<group>``, posed at ``q`` ((n,), default zeros).  Links without
        visuals but with mass show a sphere at their centre of mass.  ``color`` (0xRRGGBB)
        overrides the URDF colours."""
        root = self.vis[group]
        for li, link in enumerate(model.links):
            node = root[link.name]
            for i, geom in enumerate(link.visuals):
                rgba_color = color if color is not None else _hex(geom.rgba, PALETTE[li % len(PALETTE)])
                shape = _geometry(geom, mesh_dir)
                if shape is None:
                    continue
                material = g.MeshLambertMaterial(color=rgba_color, opacity=opacity, transparent=opacity < 1)
                node[f"visual_{i}"].set_object(shape, material)
                node[f"visual_{i}"].set_transform(_scaled(geom))
            if not link.visuals and link.inertial is not None and link.inertial.mass > 0:
                c = color if color is not None else PALETTE[li % len(PALETTE)]
                node["com"].set_object(g.Sphere(0.03), g.MeshLambertMaterial(color=c, opacity=opacity,
                                                                              transparent=opacity < 1))
                node["com"].set_transform(pin.SE3(np.eye(3), np.asarray(link.inertial.com)).homogeneous)
        for j in model.movable_joints:
            jn = root[j.parent][f"joint_{j.name}"]
            jn.set_transform(np.asarray(j.T_parent_joint))
            _add_axis(jn["axis"], np.asarray(j.axis))
            limit = _limit_polyline(j)
            if limit is not None:
                jn["limit"].set_object(g.Line(g.PointsGeometry(limit.T.astype(np.float32)),
                                              g.LineBasicMaterial(color=0xFFAA00)))
        q = np.zeros(model.nq) if q is None else np.asarray(q, dtype=float)
        for name, T in link_poses(model, q[None, :]).items():
            root[name].set_transform(T[0])

    def animate(self, model: ArticulatedModel, motions: Mapping[str, tuple[np.ndarray, np.ndarray]],
                fps: float = 30.0) -> None:
        """One meshcat animation moving each group's links: ``motions[group] = (t (T,) [s],
        q (T, n))``, resampled at ``fps`` from the earliest to the latest time."""
        t0 = min(float(t[0]) for t, _ in motions.values())
        t1 = max(float(t[-1]) for t, _ in motions.values())
        frames = np.arange(0.0, t1 - t0 + 0.5 / fps, 1.0 / fps)
        anim = Animation(default_framerate=fps)
        for group, (t, q) in motions.items():
            t, q = np.asarray(t, dtype=float), np.asarray(q, dtype=float)
            if q.shape != (len(t), model.nq):
                raise DataError(f"motion {group!r}: q must have shape ({len(t)}, {model.nq}), got {q.shape}")
            qs = np.column_stack([np.interp(frames + t0, t, q[:, k]) for k in range(model.nq)])
            poses = link_poses(model, qs)
            for k in range(len(frames)):
                with anim.at_frame(self.vis, k) as frame:
                    for name, Ts in poses.items():
                        frame[group][name].set_transform(Ts[k])
        self.vis.set_animation(anim, play=True, repetitions=0)

    # --- output ------------------------------------------------------------------------------
    def html(self) -> str:
        """The scene as one self-contained HTML page."""
        return self._window.get_scene()

    def serve(self, zmq_url: str | None = None) -> meshcat.Visualizer:
        """Send the scene to a live meshcat server and return its :class:`meshcat.Visualizer`
        (``.url()`` is the page to open).  zmq_url: a running ``meshcat-server``; None starts one
        as a subprocess, ``vis.window.server_proc``, which the caller ends (``.terminate()``)."""
        live = meshcat.Visualizer(zmq_url=zmq_url)
        sock = live.window.zmq_socket
        for blob in self._window.blobs():
            data = umsgpack.unpackb(blob)
            sock.send_multipart([data["type"].encode("utf-8"), data.get("path", "").encode("utf-8"), blob])
            sock.recv()
        return live

    def save(self, path: str | os.PathLike) -> Path:
        """Write :meth:`html` to ``path`` atomically."""
        path = Path(path)
        write_text_atomic(path, self.html())
        return path


def link_poses(model: ArticulatedModel, q: np.ndarray) -> dict[str, np.ndarray]:
    """Per link name, (T, 4, 4) T_world_link for q (T, n) (Pinocchio forward kinematics)."""
    pm = build_pin_model(model, check_dynamics=False)
    data = pm.createData()
    fids = {name: pm.getFrameId(name) for name in model.link_names}
    out = {name: np.empty((len(q), 4, 4)) for name in fids}
    for k, qk in enumerate(np.asarray(q, dtype=float)):
        pin.framesForwardKinematics(pm, data, qk)
        for name, fid in fids.items():
            out[name][k] = data.oMf[fid].homogeneous
    return out


def _hex(rgba, default: int) -> int:
    if rgba is None:
        return default
    r, gg, b = (int(round(255 * c)) for c in rgba[:3])
    return (r << 16) | (gg << 8) | b


def _scaled(geom: Geometry) -> np.ndarray:
    T = np.array(geom.T_link_geometry, dtype=float)
    if geom.kind == "mesh":
        T[:3, :3] = T[:3, :3] @ np.diag(geom.scale)
    elif geom.kind == "cylinder":  # URDF cylinders lie along z, meshcat's along y
        T[:3, :3] = T[:3, :3] @ np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    return T


def _geometry(geom: Geometry, mesh_dir) -> g.Geometry | None:
    if geom.kind == "box":
        return g.Box(list(geom.size))
    if geom.kind == "sphere":
        return g.Sphere(geom.size[0])
    if geom.kind == "cylinder":
        return g.Cylinder(geom.size[1], geom.size[0])
    if mesh_dir is None:
        return None
    path = Path(mesh_dir) / geom.filename
    loader = _MESH_LOADERS.get(path.suffix.lower())
    if loader is None or not path.is_file():
        return None
    return loader.from_file(str(path))


def _add_axis(vis, axis: np.ndarray) -> None:
    """An arrow from the joint origin along ``axis`` (unit, joint frame): shaft + cone head."""
    y = axis / np.linalg.norm(axis)
    x = np.cross(y, [1.0, 0, 0] if abs(y[0]) < 0.9 else [0, 1.0, 0])
    x /= np.linalg.norm(x)
    R = np.column_stack([x, y, np.cross(x, y)])  # meshcat cylinders lie along their y axis
    material = g.MeshLambertMaterial(color=0xFFFF00)
    shaft = 0.8 * AXIS_LENGTH_M
    vis["shaft"].set_object(g.Cylinder(shaft, 0.006), material)
    vis["shaft"].set_transform(pin.SE3(R, y * shaft / 2).homogeneous)
    vis["head"].set_object(g.Cylinder(AXIS_LENGTH_M - shaft, radiusTop=0.0, radiusBottom=0.018), material)
    vis["head"].set_transform(pin.SE3(R, y * (shaft + (AXIS_LENGTH_M - shaft) / 2)).homogeneous)


def _limit_polyline(j: Joint) -> np.ndarray | None:
    """(P, 3) points in the joint frame: an arc of the revolute limits (radius LIMIT_RADIUS_M,
    in the plane normal to the axis), or the segment of the prismatic limits along the axis."""
    lim = j.limits
    if lim is None or not (np.isfinite(lim.lower) and np.isfinite(lim.upper)):
        return None
    a = np.asarray(j.axis)
    if j.type == "prismatic":
        return np.array([lim.lower * a, lim.upper * a])
    if j.type not in ("revolute", "helical"):
        return None
    u = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    w = np.cross(a, u)
    th = np.linspace(lim.lower, lim.upper, 33)
    arc = LIMIT_RADIUS_M * (np.cos(th)[:, None] * u + np.sin(th)[:, None] * w)
    return np.vstack([[0.0, 0, 0], arc, [0.0, 0, 0]])
