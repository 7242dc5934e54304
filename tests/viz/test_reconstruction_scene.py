"""The scene of a reconstruction folder, decoded from the static scene.html: every part's cloud and
mesh, every joint's axis and limits, and the animation of the measured motion vs the verified Drake
replay (the replay shown is the one verification stored)."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from kinemaforge_opt.cli import main
from kinemaforge_opt.io.recording import read_recording
from kinemaforge_opt.model import read_urdf, write_urdf
from kinemaforge_opt.synth.case import Case
from kinemaforge_opt.synth.effects import ConcealedEffect
from kinemaforge_opt.synth.generate import generate_case
from kinemaforge_opt.verify.reconstruction import verify_reconstruction
from kinemaforge_opt.viz import Scene, decode_static_html, link_poses


def _obj_vertices(path) -> np.ndarray:
    return np.array([[float(x) for x in line.split()[1:4]] for line in path.read_text().splitlines()
                     if line.startswith("v ")])


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A reconstruct-style folder from the synthetic world's truth: nominal model + meshes, true
    tracks, clouds = mesh vertices, verified against the sequence's wrenches."""
    root = tmp_path_factory.mktemp("scene")
    case = Case("small_door", "cabinet", 0, (ConcealedEffect("viscous_damping", "door_joint", 0.8),),
                views=1, frames=24, width=16, height=12)
    paths = generate_case(case, root / "case", workers=1)
    out = root / "r"
    out.mkdir()
    shutil.copytree(paths.root / "meshes", out / "meshes")
    model = read_urdf(paths.model_urdf)
    write_urdf(model, out / "model.urdf")
    shutil.copy(paths.tracks, out / "tracks.csv")
    (out / "reconstruction.json").write_text(json.dumps(
        {"joints": [], "links": [{"name": n, "tracks": [n]} for n in model.link_names]}))
    clouds = {}
    for link in model.links:  # the mesh vertices at q = 0, in the world
        T = link_poses(model, np.zeros((1, model.nq)))[link.name][0]
        V = _obj_vertices(out / "meshes" / f"{link.name}.obj")
        clouds[link.name] = V @ T[:3, :3].T + T[:3, 3]
    np.savez(out / "clouds.npz", **clouds)
    verify_reconstruction(out, paths.sequence)
    return out


def test_scene_has_every_part_axis_limit_and_the_animation(folder, capsys):
    assert main(["view", str(folder)]) == 0
    assert capsys.readouterr().out.strip() == str(folder / "scene.html")
    cmds = decode_static_html((folder / "scene.html").read_text())
    objects = {c["path"]: c for c in cmds if c["type"] == "set_object"}
    model = read_urdf(folder / "model.urdf")
    for link in model.links:
        assert objects[f"/meshcat/clouds/{link.name}"]["object"]["object"]["type"] == "Points"
        for group in ("recorded", "simulated"):
            mesh = objects[f"/meshcat/{group}/{link.name}/visual_0"]["object"]
            assert mesh["geometries"][0]["type"] == "_meshfile"
            assert mesh["geometries"][0]["format"] == "obj"
    for j in model.movable_joints:
        for group in ("recorded", "simulated"):
            base = f"/meshcat/{group}/{j.parent}/joint_{j.name}"
            assert {f"{base}/axis/shaft", f"{base}/axis/head", f"{base}/limit"} <= set(objects)
    (anim,) = [c for c in cmds if c["type"] == "set_animation"]
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    rec = read_recording(folder / "recording.csv")
    replay = read_recording(folder / "replay.csv")
    n_frames = int(round(30 * (rec.t[-1] - rec.t[0] + 2.0))) + 1  # the recording + 2 s of the replay, 30 fps
    for group in ("recorded", "simulated"):
        keys = clips[f"/meshcat/{group}/door"]["tracks"][1]["keys"]  # quaternion track
        assert len(keys) == n_frames
    # frame 30 (t = 1 s): the door's rotation about z equals the stored q of each motion
    for group, src in (("recorded", rec), ("simulated", replay)):
        q1 = np.interp(rec.t[0] + 1.0, src.t, src.q[:, 0])
        quat = clips[f"/meshcat/{group}/door"]["tracks"][1]["keys"][30]["value"]
        assert abs(quat[2]) == pytest.approx(abs(np.sin(q1 / 2)), abs=1e-4)
    # the nominal model (no damper) swings away from the measured motion: the two differ
    q_rec = np.interp(rec.t[0] + 1.0, rec.t, rec.q[:, 0])
    q_sim = np.interp(rec.t[0] + 1.0, replay.t, replay.q[:, 0])
    assert abs(q_sim - q_rec) > 0.05


def test_large_clouds_are_strided_to_a_cap():
    scene = Scene()
    P = np.random.default_rng(0).normal(size=(50_000, 3))
    scene.add_point_clouds({"part": P}, max_points=1000)
    (cloud,) = [c for c in decode_static_html(scene.html()) if c["path"] == "/meshcat/clouds/part"]
    pos = cloud["object"]["geometries"][0]["data"]["attributes"]["position"]
    shown = np.frombuffer(pos["array"].data, dtype=np.float32).reshape(-1, 3)
    assert len(shown) == 1000
    np.testing.assert_allclose(shown[0], P[0], rtol=1e-6)
    np.testing.assert_allclose(shown[-1], P[-1], rtol=1e-6)


def test_a_live_meshcat_server_gets_the_same_scene():
    """serve() replays the scene into a real meshcat server; the server's own static HTML then
    holds the same objects and the animation."""
    scene = Scene()
    model = read_urdf_door()
    scene.add_point_clouds({"leaf": np.ones((10, 3))})
    scene.add_model(model, "recorded")
    t = np.linspace(0, 1, 11)
    scene.animate(model, {"recorded": (t, t[:, None])})
    live = scene.serve()
    try:
        served = decode_static_html(live.window.get_scene())
    finally:
        live.window.server_proc.terminate()
        live.window.server_proc.wait(timeout=10)
    ours = decode_static_html(scene.html())
    paths = lambda cmds: {c["path"] for c in cmds if c["type"] == "set_object"}  # noqa: E731
    assert paths(served) == paths(ours) and "/meshcat/recorded/frame/joint_hinge/axis/head" in paths(ours)
    assert any(c["type"] == "set_animation" for c in served)


def read_urdf_door():
    from kinemaforge_opt.model import ArticulatedModel, Geometry, Inertial, Joint, JointLimits, Link

    T = np.eye(4)
    T[:3, 3] = [0.5, 0.0, 0.0]
    leaf = Link("leaf", Inertial(3.0, [0.4, 0.0, 0.0], np.diag([0.2, 0.2, 0.2])),
                visuals=(Geometry("box", np.eye(4), size=(0.8, 0.02, 1.0)),))
    hinge = Joint("hinge", "revolute", "frame", "leaf", T_parent_joint=T, axis=[0, 0, 1], limits=JointLimits(0.0, 1.5))
    return ArticulatedModel("door", (Link("frame"), leaf), (hinge,))
