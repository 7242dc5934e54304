"""End-to-end: a tiny case written to disk, read back through every entry-level reader, and
checked for consistency between depth, labels, tracks, recording and ground truth."""

import json

import cv2
import numpy as np
import pytest

from kinemaforge_opt.cli import main
from kinemaforge_opt.io.recording import read_recording
from kinemaforge_opt.io.sequence import load_sequence
from kinemaforge_opt.io.tracks import read_tracks
from kinemaforge_opt.model import read_urdf
from kinemaforge_opt.spatial import inverse
from kinemaforge_opt.synth.effects import EFFECT_TYPES
from kinemaforge_opt.synth.generate import generate_case
from problems.catalogue import CASES, PROTOCOL_CATEGORIES, PROTOCOL_INSTANCES, PROTOCOL_VIEWS


@pytest.fixture(scope="module")
def clean_door(tmp_path_factory):
    return generate_case(CASES["tiny_door_clean"], tmp_path_factory.mktemp("tiny_door_clean"))


def test_layout_and_readers(clean_door):
    p = clean_door
    case = CASES["tiny_door_clean"]
    seq = load_sequence(p.sequence)
    assert len(seq.frames) == case.views * case.frames and len(seq.times) == case.frames
    assert not any(x.name in ("ground_truth", "recording.csv", "tracks.csv") for x in p.sequence.iterdir())
    assert seq.cameras["cam0"].width == case.width
    assert seq.wrenches is not None and seq.wrenches.forces_world.shape[1] == 3
    rec = read_recording(p.recording)
    assert rec.joint_names == ("door_joint",) and rec.tau is not None
    tracks = read_tracks(p.tracks)
    np.testing.assert_allclose(tracks.times, seq.times)
    assert set(tracks.names) == {"body", "door"}
    assert read_urdf(p.model_urdf).joint_names == read_urdf(p.true_urdf).joint_names
    assert (p.root / "meshes" / "door.obj").is_file()
    legend = json.loads(p.case_json.read_text())["label_legend"]
    assert legend["2"] == "body" and legend["3"] == "door"


def test_depth_labels_and_tracks_agree(clean_door):
    """Back-project the clean depth of 'door' pixels with the track pose: the points must lie on
    the door (the rendered geometry, the labels and the tracks are one ground truth)."""
    from kinemaforge_opt.synth.objects import make_object

    p = clean_door
    seq = load_sequence(p.sequence)
    tracks = read_tracks(p.tracks)
    door_mesh = make_object("cabinet", 0).meshes["door"]
    k = tracks.names.index("door")
    checked = 0
    for f in seq.frames:
        depth = seq.read_depth(f)
        labels = cv2.imread(str(p.labels / f.camera / f"{f.index:06d}.png"), cv2.IMREAD_UNCHANGED)
        assert np.all(np.isnan(depth) == (labels == 0))
        v, u = np.nonzero(labels == 3)
        if u.size == 0:
            continue
        cam = seq.cameras[f.camera]
        z = depth[v, u]
        p_cam = np.stack([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z], axis=1)
        i = int(np.argmin(np.abs(tracks.times - f.t)))
        T_world_door = np.eye(4)
        T_world_door[:3, :3] = tracks.Rs_world_track[k, i]
        T_world_door[:3, 3] = tracks.positions[k, i]
        T = inverse(T_world_door) @ f.T_world_camera
        p_door = p_cam @ T[:3, :3].T + T[:3, 3]
        lo, hi = door_mesh.bounds
        assert np.all((p_door > lo - 0.002) & (p_door < hi + 0.002))  # 1 mm depth quantisation
        checked += 1
    assert checked >= 4


def test_ground_truth_effects_use_the_design_names(tmp_path):
    p = generate_case(CASES["tiny_door"], tmp_path)
    doc = json.loads(p.effects.read_text())
    assert [(e["type"], e["joint"], e["value"], e["unit"]) for e in doc["effects"]] == [
        ("viscous_damping", "door_joint", 0.8, "N*m*s/rad")]
    assert read_urdf(p.true_urdf).joint("door_joint").dynamics.damping == pytest.approx(0.8)
    assert read_urdf(p.model_urdf).joint("door_joint").dynamics.damping == 0.0  # concealed


def test_moving_camera_and_multi_joint(tmp_path):
    p = generate_case(CASES["tiny_moving"], tmp_path / "moving")
    seq = load_sequence(p.sequence)
    assert set(seq.cameras) == {"cam0"}
    eyes = np.array([f.T_world_camera[:3, 3] for f in seq.frames])
    assert np.linalg.norm(eyes[-1] - eyes[0]) > 0.5
    p = generate_case(CASES["tiny_multi"], tmp_path / "multi")
    assert read_recording(p.recording).joint_names == ("door_joint", "drawer_joint")


def test_catalogue_protocol_and_effects_set():
    protocol = [c for n, c in CASES.items()
                if n.startswith("protocol_") and c.category in PROTOCOL_CATEGORIES and not c.moving_camera]
    assert len(protocol) == len(PROTOCOL_CATEGORIES) * PROTOCOL_INSTANCES
    assert sorted({c.category for c in protocol}) == sorted(PROTOCOL_CATEGORIES)
    assert all(c.views == PROTOCOL_VIEWS for c in protocol)
    singles = {c.effects[0].type for n, c in CASES.items() if n.startswith("effect_door_") and len(c.effects) == 1}
    assert singles == set(EFFECT_TYPES)
    assert any(len(c.effects) == 2 for c in CASES.values())
    assert any(n.startswith("null_") for n in CASES)
    assert all(c.expected for c in CASES.values())


def test_catalogue_effects_name_existing_joints():
    from kinemaforge_opt.synth.effects import check_effects
    from kinemaforge_opt.synth.objects import make_object

    objects = {}
    for case in CASES.values():
        key = (case.category, case.seed)
        if key not in objects:
            objects[key] = make_object(*key).model
        check_effects(objects[key], case.effects)


def test_command_lists_generates_and_rejects_unknown_cases(tmp_path, capsys):
    assert main(["synth", "--list"]) == 0
    assert "tiny_door" in capsys.readouterr().out
    assert main(["synth", "tiny_drawer", "-o", str(tmp_path / "d")]) == 0
    assert (tmp_path / "d" / "sequence" / "sequence.json").is_file()
    assert main(["synth", "no_such_case", "-o", str(tmp_path / "x")]) == 2
    assert "benchmark case 'no_such_case' does not exist" in capsys.readouterr().err


def test_images_do_not_depend_on_the_number_of_workers(tmp_path):
    one = generate_case(CASES["tiny_door"], tmp_path / "one", workers=1)
    two = generate_case(CASES["tiny_door"], tmp_path / "two", workers=2)
    files = sorted(p.relative_to(one.root) for p in one.root.rglob("*.png"))
    assert files and files == sorted(p.relative_to(two.root) for p in two.root.rglob("*.png"))
    for f in files:
        assert (one.root / f).read_bytes() == (two.root / f).read_bytes(), f
