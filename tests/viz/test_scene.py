"""meshcat scene checked without a browser: decode the commands embedded in the static HTML."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.cli import main
from kinemaforge_opt.io.recording import Recording, write_recording
from kinemaforge_opt.model import ArticulatedModel, Geometry, Inertial, Joint, JointLimits, Link, write_urdf
from kinemaforge_opt.viz import Scene, build_view, decode_static_html


def door() -> ArticulatedModel:
    """A 0.8 m box door hinged about world z at x = 0.5, limits 0..1.5 rad."""
    T = np.eye(4)
    T[:3, 3] = [0.5, 0.0, 0.0]
    G = np.eye(4)
    G[:3, 3] = [0.4, 0.0, 0.0]
    leaf = Link("leaf", Inertial(3.0, [0.4, 0.0, 0.0], np.diag([0.2, 0.2, 0.2])),
                visuals=(Geometry("box", G, size=(0.8, 0.02, 1.0)),))
    hinge = Joint("hinge", "revolute", "frame", "leaf", T_parent_joint=T, axis=[0, 0, 1],
                  limits=JointLimits(0.0, 1.5))
    return ArticulatedModel("door", (Link("frame"), leaf), (hinge,))


def _by_path(commands, kind):
    return {c["path"]: c for c in commands if c["type"] == kind}


def test_static_pose_axes_and_limits():
    scene = Scene()
    scene.add_model(door(), "model", q=np.array([np.pi / 2]))
    cmds = decode_static_html(scene.html())
    objects, poses = _by_path(cmds, "set_object"), _by_path(cmds, "set_transform")
    assert {"/meshcat/model/leaf/visual_0", "/meshcat/model/frame/joint_hinge/axis/shaft",
            "/meshcat/model/frame/joint_hinge/axis/head", "/meshcat/model/frame/joint_hinge/limit"} <= set(objects)
    T_world_leaf = np.array(poses["/meshcat/model/leaf"]["matrix"]).reshape(4, 4).T  # meshcat is column-major
    np.testing.assert_allclose(T_world_leaf[:3, 3], [0.5, 0, 0], atol=1e-12)
    np.testing.assert_allclose(T_world_leaf[:3, 0], [0, 1, 0], atol=1e-12)  # leaf x turned to world y
    head = np.array(poses["/meshcat/model/frame/joint_hinge/axis/head"]["matrix"]).reshape(4, 4).T
    assert head[2, 3] > 0.1 and np.allclose(head[:2, 3], 0)  # the arrow points along +z
    assert objects["/meshcat/model/frame/joint_hinge/limit"]["object"]["object"]["type"] == "Line"


def test_view_has_clouds_both_models_and_an_animation():
    t = np.linspace(0, 2, 61)
    q_rec = (0.7 * np.sin(t))[:, None]
    scene = build_view(door(), recorded=(t, q_rec), simulated=(t, 1.01 * q_rec),
                       clouds={"frame": np.zeros((10, 3)), "leaf": np.ones((20, 3))})
    html = scene.html()
    assert "new MeshCat.Viewer" in html
    cmds = decode_static_html(html)
    objects = _by_path(cmds, "set_object")
    assert {"/meshcat/clouds/frame", "/meshcat/clouds/leaf", "/meshcat/recorded/leaf/visual_0",
            "/meshcat/simulated/leaf/visual_0"} <= set(objects)
    colors = [objects[f"/meshcat/clouds/{p}"]["object"]["geometries"][0]["data"]["attributes"]["color"]
              for p in ("frame", "leaf")]
    assert colors[0]["array"] != colors[1]["array"]  # coloured by part
    (anim,) = [c for c in cmds if c["type"] == "set_animation"]
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    assert {"/meshcat/recorded/leaf", "/meshcat/simulated/leaf"} <= set(clips)
    keys = clips["/meshcat/recorded/leaf"]["tracks"][1]["keys"]  # quaternion track
    assert len(keys) == 61
    half = np.sin(0.7 * np.sin(1.0) / 2)  # frame 30 is t = 1 s: rotation about z, quat z component
    assert keys[30]["value"][2] == pytest.approx(half, abs=1e-6)


def test_bad_cloud_shape_is_named():
    with pytest.raises(Exception, match="part 'leaf'"):
        Scene().add_point_clouds({"leaf": np.zeros((5, 2))})


def test_view_command_writes_scene_html(tmp_path, capsys):
    write_urdf(door(), tmp_path / "model.urdf")
    t = np.linspace(0, 1, 31)
    write_recording(tmp_path / "recording.csv", Recording(t, ("hinge",), (0.5 + 0.2 * t)[:, None]))
    (tmp_path / "tracks.csv").write_text("t,track,x,y,z\n0,leaf,0,0,0\n")  # not a recording: skipped
    assert main(["view", str(tmp_path)]) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "scene.html")
    cmds = decode_static_html((tmp_path / "scene.html").read_text())
    assert "/meshcat/simulated/leaf/visual_0" in _by_path(cmds, "set_object")
    assert any(c["type"] == "set_animation" for c in cmds)


def test_view_of_missing_folder_is_named(tmp_path, capsys):
    assert main(["view", str(tmp_path / "nothing")]) == 2
    assert "nothing" in capsys.readouterr().err
