"""The reconstruction benchmark's wiring: ground truth read from a generated case agrees with
MuJoCo, a reconstruction with known errors is scored with those errors, failures become records,
and the tables and plots are written (including "not available" for missing options)."""

from __future__ import annotations

import dataclasses
import json
import types

import cv2
import mujoco
import numpy as np
import pytest

from kinemaforge_opt.bench import reconstruction as R
from kinemaforge_opt.bench.reco_report import NOT_AVAILABLE, reconstruction_tables
from kinemaforge_opt.bench.report import write_report
from kinemaforge_opt.errors import DataError
from kinemaforge_opt.io.sequence import load_sequence
from kinemaforge_opt.model import Inertial, read_urdf
from kinemaforge_opt.spatial import exp_so3, line_distance
from kinemaforge_opt.synth.case import Case
from kinemaforge_opt.synth.groundtruth import mjcf_string
from kinemaforge_opt.synth.objects import make_object

TINY = Case("bench_tiny_cabinet", "cabinet", 0, views=2, frames=4, width=64, height=48)


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    return R.cached_case(TINY, tmp_path_factory.mktemp("cache"))


def test_cache_reuses_a_generated_case(tiny_root):
    stamp = (tiny_root / "ground_truth" / "case.json").stat().st_mtime_ns
    assert R.cached_case(TINY, tiny_root.parent) == tiny_root
    assert (tiny_root / "ground_truth" / "case.json").stat().st_mtime_ns == stamp
    other = R.case_key(Case("bench_tiny_cabinet", "cabinet", 0, views=3, frames=4, width=64, height=48))
    assert other != tiny_root.name  # any field change is a new cache entry


def test_true_joint_lines_agree_with_mujoco(tiny_root):
    obj = make_object("cabinet", 0)
    mj = mujoco.MjModel.from_xml_string(mjcf_string(obj.model))
    data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, data)  # q = 0: the synthetic episode starts there
    joints = R.true_joints(tiny_root)
    assert {j.name for j in joints} == set(obj.model.joint_names)
    for j in joints:
        jid = mj.joint(j.name).id
        assert abs(abs(np.dot(j.axis_world, data.xaxis[jid])) - 1.0) < 1e-6
        assert line_distance(j.axis_world, j.origin_world, data.xaxis[jid], data.xanchor[jid]) < 1e-6


def _fake_reconstruction(root, tilt_deg: float, offset_m: float, drop_share: float, mass_scale: float = 1.3):
    """A stand-in for reconstruct_sequence built from the ground truth: every joint's axis tilted
    by ``tilt_deg`` and its line moved ``offset_m`` sideways, parts renamed, the first
    ``drop_share`` of each frame's pixels of the first moving part labelled environment, and a
    model that is the true one with its joints renamed and every moving part ``mass_scale`` times
    as heavy (a rigid body scaled whole)."""
    seq = load_sequence(root / "sequence")
    legend = json.loads((root / "ground_truth" / "case.json").read_text())["label_legend"]
    truth = R.true_joints(root)
    rename = {"body": "base", **{j.child: f"p{k}" for k, j in enumerate(truth)}}
    joints = []
    for j in truth:
        perp = np.cross(j.axis_world, [1.0, 0.0, 0.0] if abs(j.axis_world[0]) < 0.9 else [0.0, 1.0, 0.0])
        perp /= np.linalg.norm(perp)
        axis = exp_so3(np.radians(tilt_deg) * perp) @ j.axis_world
        joints.append({"name": "e_" + j.name, "type": j.type, "parent": rename[j.parent], "child": rename[j.child],
                       "axis_world": axis.tolist(), "origin_world": (j.origin_world + offset_m * perp).tolist()})
    pixels, counts = {}, {"kept": 0, "dropped": 0}
    for f in seq.frames:
        img = cv2.imread(str(root / "ground_truth" / "labels" / f.camera / f"{f.index:06d}.png"), cv2.IMREAD_UNCHANGED)
        rows, cols = np.nonzero(img >= 0)
        names = np.array([rename.get(legend[str(v)], "environment") for v in img[rows, cols]], dtype=object)
        door = np.flatnonzero(names == "p0")
        drop = door[: int(drop_share * door.size)]
        names[drop] = "environment"
        counts["kept"] += door.size - drop.size
        counts["dropped"] += drop.size
        pixels[f.index] = (np.column_stack([rows, cols]), names)
    doc = {"joints": joints, "timing_s": {"graph": 0.5, "total": 1.0},
           "verification": {"drift_m": {"1": 0.01, "50": 0.05}, "energy_residual": 0.02}}
    true = read_urdf(root / "ground_truth" / "true_model.urdf")
    model = dataclasses.replace(true, joints=tuple(dataclasses.replace(j, name="e_" + j.name) for j in true.joints))
    for j in true.movable_joints:
        inert = model.link(j.child).inertial
        model = model.with_link(j.child, inertial=Inertial(mass_scale * inert.mass, inert.com, mass_scale * inert.inertia))
    return types.SimpleNamespace(document=doc, perception=None, labels=None, model=model), pixels, counts


def test_known_errors_are_measured(tiny_root, tmp_path, monkeypatch):
    import kinemaforge_opt.perception as perception

    fake, pixels, counts = _fake_reconstruction(tiny_root, tilt_deg=2.0, offset_m=0.01, drop_share=0.25)
    monkeypatch.setattr(perception, "reconstruct_sequence", lambda *a, **k: fake)
    monkeypatch.setattr(perception, "pixel_labels", lambda per, labels, seq=None: pixels)
    rec = R.evaluate_case(TINY, tiny_root, tmp_path / "out", verify=False)
    assert rec["ok"], rec["error"]
    assert rec["axis_error_deg"] == pytest.approx(2.0, abs=1e-9)
    assert rec["origin_error_m"] == pytest.approx(0.01, abs=1e-9)
    truth = R.true_joints(tiny_root)
    assert rec["part_match"] == {"base": "body", **{f"p{k}": j.child for k, j in enumerate(truth)}}
    door_iou = counts["kept"] / (counts["kept"] + counts["dropped"])
    assert 0.7 < door_iou < 0.8
    assert rec["iou_per_part"][truth[0].child] == pytest.approx(door_iou)
    assert rec["part_iou"] == pytest.approx((door_iou + len(truth)) / (len(truth) + 1))
    assert rec["moving_part_iou"] == pytest.approx((door_iou + len(truth) - 1) / len(truth))
    assert rec["type_accuracy"] == 1.0 and rec["topology_correct"] and rec["joints_found"] == 1.0
    assert rec["drift_1s_m"] == 0.01 and rec["drift_50s_m"] == 0.05 and rec["energy_residual"] == 0.02
    assert rec["inertia_error"] == pytest.approx(0.3)


def test_a_failing_reconstruction_is_a_record(tiny_root, tmp_path, monkeypatch):
    import kinemaforge_opt.perception as perception

    def boom(*a, **k):
        raise DataError("no motion: nothing moved")

    monkeypatch.setattr(perception, "reconstruct_sequence", boom)
    rec = R.evaluate_case(TINY, tiny_root, tmp_path / "out", verify=False)
    assert not rec["ok"] and rec["error"] == "DataError: no motion: nothing moved"
    s = R.summarise([rec, {**rec, "ok": True, "error": None, "type_accuracy": 1.0, "topology_correct": True,
                           "joints_found": 1.0, "axis_error_deg": 3.0}])
    assert s["failed"] == 1 and s["errors"] == ["DataError: no motion: nothing moved"]
    assert s["type_accuracy"] == {"mean": 0.5, "std": 0.5, "n": 2}  # the failure counts as wrong
    assert s["axis_error_deg"] == {"mean": 3.0, "std": 0.0, "n": 1}  # and is left out of the errors


def test_time_budget_skips_new_runs_and_tables_leave_them_out(tmp_path):
    runs = R._Runs(tmp_path / "out", tmp_path / "cache", lambda s: None, budget_s=0.0)
    rec = runs(TINY)
    assert rec["skipped"] and "time budget of 0 s" in rec["error"]
    assert not (tmp_path / "cache").exists()  # nothing generated, nothing reconstructed
    s = R.summarise([rec])
    assert (s["cases"], s["failed"], s["skipped"]) == (0, 0, 1)


def test_stage_times_fit_the_exponent_over_complete_runs():
    def rec(x, t, found=True):
        return {"ok": True, "frames": x, "cpu_s": t, "timing_s": {"total": t, "graph": 0.1 * x},
                "estimated_joints": [["base", "p0", "revolute" if found else "fixed"]]}

    recs = [rec(10, 2.0), rec(20, 8.0), rec(40, 32.0), rec(80, 0.5, found=False)]  # t ∝ frames²
    st = R._stage_times(recs, "frames")
    assert st["total"]["x"] == [10, 20, 40] and st["total"]["exponent"] == pytest.approx(2.0)
    assert st["graph"]["exponent"] == pytest.approx(1.0)


def test_option_support_names_missing_options():
    assert R.option_support({"method": "greedy"}) is None
    assert "no_such_switch" in R.option_support({"no_such_switch": False})


def test_switches_reach_the_nlp_options(monkeypatch):
    import kinemaforge_opt.perception as perception
    from kinemaforge_opt.nlp.reconstruction import ScrewOptions

    def fake(seq_path, out=None, method="graph", refine=True, screw_options=None, show_progress=None):
        raise AssertionError("not called")

    monkeypatch.setattr(perception, "reconstruct_sequence", fake)
    assert R.resolve_options({"nlp": False}) == ({"refine": False}, None)
    kw, _ = R.resolve_options({"energy": False})
    assert kw["screw_options"] == ScrewOptions(energy="off")
    kw, _ = R.resolve_options({"coarse_to_fine": False, "method": "greedy"})
    assert kw == {"method": "greedy", "screw_options": ScrewOptions(coarse_to_fine=False)}
    assert R.resolve_options({R.ENERGY_WEIGHT_OPTION: 10.0})[0]["screw_options"].energy_weight == 10.0
    assert R.resolve_options({"jitter": 1})[1] == "reconstruct_sequence has no option jitter"


def test_parts_of_the_cli_match_the_runner():
    from kinemaforge_opt.bench.run import PARTS
    from kinemaforge_opt.commands.bench import PARTS as CLI_PARTS

    assert CLI_PARTS == PARTS


def _stat(mean, n=1):
    return {"mean": mean, "std": 0.0, "n": n}


def _summary(**vals):
    s = {"cases": 1, "failed": 0, "errors": [], "mean_wall_s": 2.0}
    s.update({k: _stat(vals.get(k)) if vals.get(k) is not None else _stat(None, 0) for k in R.METRICS})
    return s


def test_tables_and_plots(tmp_path):
    size = R.RECO_QUICK
    ok = _summary(axis_error_deg=1.5, origin_error_m=0.01, inertia_error=0.05, part_iou=0.9, drift_1s_m=0.02, drift_50s_m=0.06,
                  energy_residual=0.1, joints_found=1.0, type_accuracy=1.0, topology_correct=1.0)
    record = {"case": "c", "options": {}, "ok": True, "drift_m": {"1": 0.02, "5": 0.04, "50": 0.06}}
    reco = {
        "size": {**R.asdict(size)}, "seed_paper": R.SEED_TABLE1,
        "table1": {"cabinet": ok, "average": ok},
        "table2": {"full": {"available": True, **ok},
                   "w/o energy": {"available": False, "reason": "reconstruct_sequence has no option energy"}},
        "drift_vs_horizon": {"1": _stat(0.02), "5": _stat(0.04), "10": _stat(None, 0), "20": _stat(None, 0),
                             "50": _stat(0.06)},
        "sensitivity": {"energy_weight": {"available": False, "reason": "no option energy_weight", "points": []},
                        "views": [{"views": 2, **ok}, {"views": 4, **ok}]},
        "scaling": {"frames": {"total": {"x": [8, 16], "time_s": [1.0, 4.0], "exponent": 2.0},
                               "cpu": {"x": [8, 16], "time_s": [1.0, 2.0], "exponent": 1.0}}},
        "records": [record], "generation_s": 1.0, "total_s": 10.0,
    }
    md = reconstruction_tables(reco)
    assert "| cabinet | 1 | 1.50 ± 0.00 (1) | 0.010 ± 0.000 (1) | 0.050 ± 0.000 (1) | 0.900 ± 0.000 (1) | n/a |" in md
    assert "| **seed paper (average)** | – | 2.83 | 0.024 | – | 0.910 | – | 0.041 | 0.104 | 0.019 |" in md
    assert f"{NOT_AVAILABLE} (reconstruct_sequence has no option energy)" in md
    assert "| total | 2.00 |" in md
    paths = write_report({"size": "test", "machine": "m", "total_s": 1.0, "reconstruction": reco}, tmp_path)
    for k in ("drift_horizon", "sensitivity", "stage_scaling"):
        assert paths[k].stat().st_size > 0
    assert "Table 1 — reconstruction per category" in paths["markdown"].read_text()


def test_resume_reuses_the_runs_an_interrupted_run_left_and_makes_the_others(tmp_path):
    import json
    from types import SimpleNamespace

    from kinemaforge_opt.bench.reconstruction import _Runs

    out = tmp_path / "reconstruction"
    out.mkdir()
    done = {"case": "protocol_cabinet_0", "options": {"nlp": False}, "ok": True, "axis_error_deg": 0.5}
    (out / "records.jsonl").write_text(json.dumps(done) + "\n")
    said = []
    runs = _Runs(out, tmp_path / "cache", said.append, resume=True)
    case = SimpleNamespace(name="protocol_cabinet_0", category="cabinet", views=4, frames=12)
    assert runs(case, {"nlp": False}) == done
    assert "1 finished runs" in said[0]
    fresh = _Runs(out, tmp_path / "cache", said.append, budget_s=0.0)  # without resume: made again
    assert fresh(case, {"nlp": False})["skipped"]
