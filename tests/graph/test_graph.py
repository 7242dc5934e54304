"""Each graph stage alone on exact synthetic tracks, then the real Sturm logs."""

from factories import shared_data_dir
import glob
import json
from pathlib import Path

import numpy as np
import pytest

from kinemaforge_opt.cli import main
from kinemaforge_opt.errors import DataError
from kinemaforge_opt.graph import fit_all, infer_tree, relative_motion, score_pair
from kinemaforge_opt.io.tracks import PoseTracks, read_sturm_log, read_tracks, write_tracks
from kinemaforge_opt.spatial import axis_angle_error, line_distance, make_transform, screw_motion, translation_motion

STURM = str(shared_data_dir() / "real" / "articulation" / "mechanisms_iros_2010")
T = 30
ANGLES = np.linspace(0.0, 1.2, T)
AXIS = np.array([0.0, 0.1, 1.0]) / np.linalg.norm([0.0, 0.1, 1.0])
POINT = np.array([0.5, 0.2, 0.0])


def _tracks(poses: dict, full=True) -> PoseTracks:
    names = tuple(poses)
    P = np.array([[X[:3, 3] for X in poses[n]] for n in names])
    R = np.array([[X[:3, :3] for X in poses[n]] for n in names])
    return PoseTracks(np.arange(T) * 0.1, names, P, R if full else None)


def _door(offset=(0.9, 0.2, 0.5), pitch=0.0):
    return [screw_motion(AXIS, POINT, a, pitch) @ make_transform(p=offset) for a in ANGLES]


def _best(hyps):
    return max(hyps.values(), key=lambda h: h.confidence)


@pytest.mark.parametrize("full", [True, False])
def test_exact_revolute_axis(full):
    h = score_pair(fit_all(relative_motion(_tracks({"door": _door()}, full), None, 0)))
    best = _best(h)
    assert best.type == "revolute"
    assert axis_angle_error(best.axis_world, AXIS) < 1e-6
    assert line_distance(best.axis_world, best.origin_world, AXIS, POINT) < 1e-6
    np.testing.assert_allclose(np.abs(best.q[-1]), 1.2, atol=1e-6)


def test_exact_helical_pitch():
    best = _best(score_pair(fit_all(relative_motion(_tracks({"screw": _door(pitch=0.05)}), None, 0))))
    assert best.type == "helical" and abs(best.pitch - 0.05) < 1e-6
    assert axis_angle_error(best.axis_world, AXIS) < 1e-6


@pytest.mark.parametrize("full", [True, False])
def test_prismatic_pair_is_prismatic(full):
    axis = np.array([1.0, 0.5, 0.0]) / np.linalg.norm([1.0, 0.5, 0.0])
    poses = {"drawer": [translation_motion(axis, 0.3 * a) @ make_transform(p=(0, 1, 0.3)) for a in ANGLES]}
    best = _best(score_pair(fit_all(relative_motion(_tracks(poses, full), None, 0))))
    assert best.type == "prismatic" and axis_angle_error(best.axis_world, axis) < 1e-6


def test_rigid_pair_gives_rigid_edge_and_merges():
    door = _door()
    tracks = _tracks({"door": door, "handle": [X @ make_transform(p=(0.1, 0, 0.3)) for X in door], "body": [np.eye(4)] * T})
    hyps = score_pair(fit_all(relative_motion(tracks, 0, 1)))
    assert _best(hyps).type == "rigid" and hyps["rigid"].confidence > 0.95
    res = infer_tree(tracks)
    assert res.best.parts == {"base": ("world", "body"), "door": ("door", "handle")}
    (j,) = res.best.joints
    assert (j.parent, j.child, j.type) == ("base", "door", "revolute")


def test_tree_topology_and_kbest():
    tracks = _tracks({
        "door": _door(),
        "drawer": [translation_motion([1, 0, 0], 0.3 * a) @ make_transform(p=(0, 1, 0.3)) for a in ANGLES],
    })
    res = infer_tree(tracks, k_best=3)
    assert {(j.parent, j.child, j.type) for j in res.best.joints} == {
        ("base", "door", "revolute"), ("base", "drawer", "prismatic")}
    assert len(res.alternatives) == 2
    assert all(t.log_score <= res.best.log_score for t in res.alternatives)
    greedy = infer_tree(tracks, method="greedy")
    assert greedy.method == "greedy" and len(greedy.best.joints) == 2


def test_no_motion_is_refused(tmp_path):
    rng = np.random.default_rng(0)
    P = np.array([0.3, 0.1, 0.2]) + 1e-3 * rng.normal(size=(1, 50, 3))
    tracks = PoseTracks(np.arange(50.0), ("still",), P)
    with pytest.raises(DataError, match="no motion"):
        infer_tree(tracks)
    write_tracks(tmp_path / "tracks.csv", tracks)
    assert main(["reconstruct", str(tmp_path / "tracks.csv"), "-o", str(tmp_path / "out")]) == 2


def test_missing_input_exit_2(tmp_path, capsys):
    assert main(["reconstruct", str(tmp_path / "none.csv"), "-o", str(tmp_path / "o")]) == 2
    assert "none.csv" in capsys.readouterr().err


EXPECTED = {"left_door": ("revolute", 0.32, 0.40), "right_door": ("revolute", 0.32, 0.40),
            "dishwasher": ("revolute", 0.62, 0.70), "drawer": ("prismatic", None, None)}


@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_real_sturm_logs(kind):
    want, r_lo, r_hi = EXPECTED[kind]
    for log in sorted(glob.glob(f"{STURM}/{kind}/*.log")):
        (j,) = infer_tree(read_sturm_log(log)).best.joints
        assert j.type == want, log
        if r_lo is not None:
            assert r_lo < j.hypothesis.radius < r_hi, (log, j.hypothesis.radius)


def test_reconstruct_command_writes_json(tmp_path):
    out = tmp_path / "out"
    assert main(["reconstruct", f"{STURM}/right_door/003.log", "-o", str(out)]) == 0
    (j,) = json.loads((out / "reconstruction.json").read_text())["joints"]
    assert j["type"] == "revolute" and 0.32 < j["radius"] < 0.40 and len(j["axis_world"]) == 3


def test_fast_rotation_maps_match_scipy():
    from scipy.spatial.transform import Rotation

    from kinemaforge_opt.graph.fit import _log, _rot

    rng = np.random.default_rng(3)
    w = np.concatenate([rng.normal(size=(200, 3)), 1e-7 * rng.normal(size=(20, 3)), [[0.0, 0.0, np.pi - 1e-6]]])
    R = Rotation.from_rotvec(w).as_matrix()
    np.testing.assert_allclose(_rot(w), R, atol=1e-12)
    np.testing.assert_allclose(_log(R), Rotation.from_matrix(R).as_rotvec(), atol=1e-9)


def test_turning_lid_with_origin_near_its_axis_is_revolute():
    """A lid whose track frame sits 2 cm from the hinge turns 80°: its position barely moves (a
    prismatic joint fits the positions to a few mm) but only a revolute joint explains the
    rotation."""
    rng = np.random.default_rng(4)
    angles = np.linspace(0.0, 1.4, T)
    axis = np.array([1.0, 0.0, 0.0])
    poses = [screw_motion(axis, np.zeros(3), a) @ make_transform(p=(0.0, 0.02, 0.0)) for a in angles]
    P = np.array([[X[:3, 3] for X in poses]]) + 1e-3 * rng.normal(size=(1, T, 3))
    R = np.array([[X[:3, :3] for X in poses]])
    best = _best(score_pair(fit_all(relative_motion(PoseTracks(np.arange(T) * 0.1, ("lid",), P, R), None, 0))))
    assert best.type == "revolute" and axis_angle_error(best.axis_world, axis) < np.radians(3)


def test_rarely_seen_track_is_left_out():
    door = _door()
    P = np.array([[X[:3, 3] for X in door], [X[:3, 3] for X in door]])
    R = np.array([[X[:3, :3] for X in door]] * 2)
    P[1, 3:] = np.nan
    R[1, 3:] = np.nan
    res = infer_tree(PoseTracks(np.arange(T) * 0.1, ("door", "glimpse"), P, R))
    assert [(j.parent, j.child, j.type) for j in res.best.joints] == [("base", "door", "revolute")]


def _hyp(kind, confidence, residual_rms, noise_sigma=1e-3):
    from kinemaforge_opt.graph.fit import JointHypothesis

    axis = None if kind == "rigid" else np.array([0.0, 0.0, 1.0])
    return JointHypothesis(kind, axis, None if axis is None else np.zeros(3), axis, None if axis is None else np.zeros(3),
                           0.0, None, np.zeros(T), residual_rms, 0.0, noise_sigma, 0.0, 0, 0, T, 0.0, confidence)


def test_rigid_tree_edges_join_the_parent_part():
    """The arborescence picks base->door (revolute), door->knob (rigid, residual at the noise
    level) and base->sticker (rigid, misfitting by 20σ: a track that moves but that no joint type
    explains).  Both rigid children join their parent's link: the tree's joints are moving ones
    only, no fixed joint to the base."""
    from kinemaforge_opt.graph.tree import _tree

    parts = {"base": ("world",), "door": ("door",), "knob": ("knob",), "sticker": ("sticker",)}
    edges = {("base", "door"): {"revolute": _hyp("revolute", 0.9, 1e-3)},
             ("door", "knob"): {"rigid": _hyp("rigid", 0.7, 2e-3)},
             ("base", "sticker"): {"rigid": _hyp("rigid", 0.6, 2e-2)}}
    tree = _tree("base", parts, edges, [("base", "door"), ("door", "knob"), ("base", "sticker")])
    assert tree.parts == {"base": ("world", "sticker"), "door": ("door", "knob")}
    assert [(j.parent, j.child, j.type) for j in tree.joints] == [("base", "door", "revolute")]
    assert tree.log_score == pytest.approx(np.log(0.9) + np.log(0.7) + np.log(0.6))
    # the sticker moves (20σ) yet is kept rigid: a warning; the knob is rigid within the noise
    assert [(w.track, w.part, w.best_moving) for w in tree.loose] == [("sticker", "base", None)]
    assert tree.loose[0].message().startswith("track sticker is kept rigid with part base although it moves")


@pytest.mark.parametrize("window", [3, 5, 7, 9, 21])
def test_savgol_smoothing_equals_scipy_signal(window):
    """The noise estimate's written-out Savitzky–Golay coefficients are scipy.signal's, bit for bit."""
    from scipy.signal import savgol_coeffs

    from kinemaforge_opt.graph.motion import savgol_smoothing

    assert np.array_equal(savgol_smoothing(window), savgol_coeffs(window, 2))


CHEST_THREE_VIEWS = Path(__file__).parent / "data" / "chest_three_views_424x240_tracks.csv"


def test_a_moving_track_kept_rigid_is_a_warning(tmp_path, capsys):
    """Perception's tracks of a three-drawer chest seen by three cameras at 424×240
    (protocol_drawer_1@s8,v3,f40,424x240): track p0 is drawer_1 (its seed points are drawer_1's
    pixels in the synthetic world's labels), which the truth's recording pulls out 0.26 m.  While
    it is shut, flush with the body, its track slides and turns, no joint type fits its
    orientations, and the tree keeps it rigid with the base: a lost joint, which the tree must
    report rather than hide."""
    res = infer_tree(read_tracks(CHEST_THREE_VIEWS))
    assert "p0" in res.best.parts["base"]  # the lost drawer (what the warning is about)
    (loose,) = res.best.loose
    assert (loose.track, loose.part, loose.best_moving.type) == ("p0", "base", "prismatic")
    assert loose.rigid.residual_rms > 0.1 > 3 * loose.best_moving.residual_rms  # it moves, along a line
    assert main(["reconstruct", str(CHEST_THREE_VIEWS), "-o", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert "warning: track p0 is kept rigid with part base although it moves relative to it" in err
    (w,) = json.loads((tmp_path / "reconstruction.json").read_text())["graph_warnings"]
    assert w["track"] == "p0" and w["best_moving_type"] == "prismatic" and w["rigid_rms_m"] > 0.1


def test_a_folder_of_logs_names_the_log_of_each_warning(tmp_path, capsys):
    """In a folder of Sturm logs each log is its own mechanism and its parts are named after it
    (``<log>_base``); a warning names the same parts.  003.log is a real right door; wobble.log a
    gripper wandering 3 mm per sample at random, which no joint type explains."""
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "003.log").write_text(Path(f"{STURM}/right_door/003.log").read_text())
    np.savetxt(logs / "wobble.log", np.cumsum(np.random.default_rng(0).normal(0.0, 0.003, (300, 3)), axis=0), fmt="%.5f")
    assert main(["reconstruct", str(logs), "-o", str(tmp_path / "out")]) == 0
    doc = json.loads((tmp_path / "out" / "reconstruction.json").read_text())
    (w,) = doc["graph_warnings"]
    assert w["part"] == "wobble_base" and w["part"] in {link["name"] for link in doc["links"]}
    assert f"warning: track {w['track']} is kept rigid with part wobble_base" in capsys.readouterr().err
    (door,) = doc["joints"]  # the wobble is no joint: the door's alone
    assert door["parent"] == "003_base" and door["type"] == "revolute"
