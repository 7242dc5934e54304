"""The Drake verification of a reconstruction, on a "perfect" reconstruction made from the synthetic
world's ground truth (true tracks, the nominal or the true model): the true model must replay the
MuJoCo motion closely, the nominal one (its damping left out) must not."""

from __future__ import annotations

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
from kinemaforge_opt.synth.groundtruth import HandPlan
from kinemaforge_opt.verify.reconstruction import verify_reconstruction

HORIZONS = ("1", "5", "10", "20", "50")


@pytest.fixture(scope="module")
def door(tmp_path_factory):
    case = Case("small_door", "cabinet", 0, (ConcealedEffect("viscous_damping", "door_joint", 0.8),),
                views=1, frames=24, width=16, height=12)
    return generate_case(case, tmp_path_factory.mktemp("door"), workers=1)


def truth_folder(paths, out, urdf):
    """A reconstruct-style output folder whose model and tracks are the ground truth's."""
    out.mkdir(parents=True)
    shutil.copytree(paths.root / "meshes", out / "meshes")
    model = read_urdf(urdf)
    write_urdf(model, out / "model.urdf")
    for geom_link in read_urdf(out / "model.urdf").links:  # mesh paths resolve from OUT
        for g in geom_link.visuals:
            assert g.kind != "mesh" or (out / g.filename).is_file() or (out / "meshes" / g.filename.split("/")[-1]).is_file()
    shutil.copy(paths.tracks, out / "tracks.csv")
    links = [{"name": n, "tracks": [n]} for n in model.link_names]
    (out / "reconstruction.json").write_text(json.dumps({"joints": [], "links": links, "timing_s": {"total": 1.0}}))
    return out


def test_true_model_replays_mujoco_and_nominal_does_not(door, tmp_path):
    drift, energy = {}, {}
    for name, urdf in (("true", door.true_urdf), ("nominal", door.model_urdf)):
        out = truth_folder(door, tmp_path / name, urdf)
        v = verify_reconstruction(out, door.sequence)
        doc = json.loads((out / "reconstruction.json").read_text())
        assert doc["verification"] == json.loads(json.dumps(v))
        assert set(v["drift_m"]) == set(HORIZONS)
        assert [v["beyond_recording"][h] for h in HORIZONS] == [False, True, True, True, True]  # a 3 s recording
        assert v["forcing"] == "wrenches.csv" and v["contacts"][0]["link"] == "door"
        assert doc["timing_s"]["verify"] > 0 and doc["timing_s"]["total"] == pytest.approx(1.0 + doc["timing_s"]["verify"])
        for f in ("recording.csv", "replay.csv", "trajectories.png"):
            assert (out / f).is_file()
        drift[name], energy[name] = v["drift_m"], v["energy_residual"]
        if name == "true":  # MuJoCo starts the door at rest; the 8 Hz first difference says ~0.5 rad/s
            rec = read_recording(out / "recording.csv")
            assert (rec.q[1, 0] - rec.q[0, 0]) / (rec.t[1] - rec.t[0]) > 0.2
            assert abs(v["v0"][0]) < 0.03
    # Drake with the true physics follows MuJoCo under the same hand force
    assert drift["true"]["1"] < 0.005 and drift["true"]["50"] < 0.02
    # without its damper the door swings further: the verifier sees it
    assert drift["nominal"]["1"] > 3 * drift["true"]["1"] and drift["nominal"]["1"] > 0.02
    assert energy["true"] < 0.05 and energy["nominal"] > 5 * energy["true"]  # 0.019 vs 0.42 when written


def test_the_drift_range_is_reported_when_asked(door, tmp_path):
    out = truth_folder(door, tmp_path / "true", door.true_urdf)
    assert "drift_range_m" not in verify_reconstruction(out, door.sequence)
    v = verify_reconstruction(out, door.sequence, with_range=True)
    assert set(v["drift_range_m"]) == set(HORIZONS) and "1 ± 0.01" in v["drift_range_definition"]
    for h in HORIZONS:
        least, largest = v["drift_range_m"][h]
        assert 0.0 <= least <= largest < v["drift_m"][h] + 0.01  # a damped door: no knife edge


def test_missing_tracks_are_named(door, tmp_path):
    out = truth_folder(door, tmp_path / "r", door.model_urdf)
    (out / "tracks.csv").unlink()
    with pytest.raises(Exception, match=r"tracks\.csv: missing"):
        verify_reconstruction(out, door.sequence)


def test_diagnose_on_a_reconstruction_needs_the_sequence(door, tmp_path, capsys):
    out = truth_folder(door, tmp_path / "r", door.model_urdf)
    assert main(["diagnose", str(out), "-o", str(tmp_path / "d")]) == 2
    assert "--sequence SEQ" in capsys.readouterr().err
    assert main(["diagnose", str(out), str(door.recording), "-o", str(tmp_path / "d")]) == 2
    assert "give --sequence SEQ, not a recording" in capsys.readouterr().err
    assert main(["diagnose", str(door.model_urdf), "--sequence", str(door.sequence), "-o", str(tmp_path / "d")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    assert main(["diagnose", str(door.model_urdf), "-o", str(tmp_path / "d")]) == 2
    assert "needs a RECORDING.csv" in capsys.readouterr().err


def test_diagnose_on_a_reconstruction_finds_the_damper(tmp_path, capsys):
    """30 time steps of a stroke that stays off the stops, true tracks: only the damper is found."""
    plan = HandPlan(goals=(0.5,), push_s=0.8, free_s=1.7, release_speed=0.15)
    case = Case("small_door_30", "cabinet", 0, (ConcealedEffect("viscous_damping", "door_joint", 0.8),),
                views=1, frames=30, width=16, height=12, plan=plan)
    paths = generate_case(case, tmp_path / "case", workers=1)
    out = truth_folder(paths, tmp_path / "r", paths.model_urdf)
    d = tmp_path / "d"
    assert main(["diagnose", str(out), "--sequence", str(paths.sequence), "-o", str(d)]) == 0
    # the augmented model replays the MuJoCo motion in Drake (the nominal one misses the damper)
    after = json.loads((d / "verification.json").read_text())
    assert after["drift_m"]["1"] < 0.01
    assert (d / "recording.csv").is_file() and (d / "meshes" / "door.obj").is_file()
    model = read_urdf(d / "model.urdf")
    assert model.joint_names == ("door_joint",)
    assert model.joint("door_joint").limits.upper == read_urdf(paths.model_urdf).joint("door_joint").limits.upper
    effects = json.loads((d / "diagnosis.json").read_text())["effects"]
    assert [e["type"] for e in effects] == ["viscous_damping"]
    assert effects[0]["value"] == pytest.approx(0.8, rel=0.15)


def test_measured_joint_values_take_the_place_of_a_biased_track(door, tmp_path):
    """The door's track turned 0.03 rad about its hinge at the zero step (a shut door's pose,
    flush with its carcass, is what ICP fixes worst) puts that offset into every later value the
    tracks give: the true model's energy books go out.  The reconstruction's own measurement of
    the joint (``measured_q.csv``, here MuJoCo's q) replaces the tracks' values, and the books
    balance again."""
    import pinocchio as pin

    from kinemaforge_opt.io.recording import Recording, write_recording
    from kinemaforge_opt.io.tracks import PoseTracks, read_tracks, write_tracks
    from kinemaforge_opt.model.pinocchio import build_pin_model
    from kinemaforge_opt.spatial import exp_so3

    model = read_urdf(door.true_urdf)
    pm = build_pin_model(model)
    data = pm.createData()
    pin.forwardKinematics(pm, data, np.zeros(model.nq))
    hinge = data.oMi[pm.getJointId("door_joint")]
    a, o = hinge.rotation @ model.joint("door_joint").axis, hinge.translation
    tracks = read_tracks(door.tracks)
    k = tracks.names.index("door")
    R, P = tracks.Rs_world_track.copy(), tracks.positions.copy()
    turn = exp_so3(a * 0.03)
    R[k, 0], P[k, 0] = turn @ R[k, 0], turn @ (P[k, 0] - o) + o
    truth = read_recording(door.recording)
    residual = {}
    for name in ("biased", "measured"):
        out = truth_folder(door, tmp_path / name, door.true_urdf)
        write_tracks(out / "tracks.csv", PoseTracks(tracks.times, tracks.names, P, R))
        if name == "measured":
            q = np.interp(tracks.times, truth.t, truth.q[:, 0])
            write_recording(out / "measured_q.csv", Recording(tracks.times, ("door_joint",), q[:, None]))
        v = verify_reconstruction(out, door.sequence)
        residual[name] = v["energy_residual"]
        assert v["joint_values"].startswith("measured_q.csv" if name == "measured" else "tracks.csv")
        rec = read_recording(out / "recording.csv")
        q_true = np.interp(rec.t, truth.t, truth.q[:, 0])
        offset = rec.q[1:, 0] - q_true[1:]
        assert np.abs(offset).max() < 1e-9 if name == "measured" else np.abs(offset + 0.03).max() < 1e-6
    assert residual["measured"] < 0.005 and residual["biased"] > 5 * residual["measured"]  # 0.0009, 0.011 when written
