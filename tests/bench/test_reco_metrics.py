"""Table 1 metrics against analytic answers: known axis pairs and joint lines, label
permutations and hand-counted overlaps for the part IoU, hand-built trees for topology."""

import numpy as np
import pytest

from kinemaforge_opt.bench.metrics import (
    JointRecord,
    axis_error_deg,
    loglog_exponent,
    match_joints,
    mean_std,
    origin_error_m,
    part_iou,
    part_iou_from_counts,
    topology_correct,
)
from kinemaforge_opt.errors import DataError


@pytest.mark.parametrize("a, b, deg", [
    ([0, 0, 1], [0, 0, 1], 0.0),
    ([0, 0, 1], [0, 0, -1], 0.0),  # sign-agnostic
    ([0, 0, 2], [0, 1, 0], 90.0),
    ([1, 0, 0], [1, 1, 0], 45.0),
    ([1, 0, 0], [-1, 1, 0], 45.0),  # 135° between the directed vectors
    ([0, 0, 1], [0, np.sin(np.radians(3)), np.cos(np.radians(3))], 3.0),
])
def test_axis_error_known_pairs(a, b, deg):
    assert axis_error_deg(np.array(a, float), np.array(b, float)) == pytest.approx(deg, abs=1e-6)


def test_axis_error_refuses_zero_axis():
    with pytest.raises(DataError, match="non-zero 3-vectors"):
        axis_error_deg([0, 0, 0], [0, 0, 1])


def test_origin_error_is_the_estimated_lines_distance_from_the_true_origin():
    z = np.array([0.0, 0.0, 1.0])
    # parallel vertical lines 5 cm apart, origins at different heights along the line
    assert origin_error_m(z, [0.3, 0.2, 0.0], [0.3, 0.25, 0.7]) == pytest.approx(0.05)
    # the same line given by two different points and opposite directions
    assert origin_error_m(z, [1.0, 1.0, 0.0], [1.0, 1.0, 5.0]) == pytest.approx(0.0, abs=1e-12)
    # skew lines: the estimate (the x-axis) passes 1 m beside the true origin (2, -1, 0.1), although
    # the two lines come within 0.1 m of each other at x = 2
    assert origin_error_m([1, 0, 0], [0, 0, 0], [2.0, -1.0, 0.1]) == pytest.approx(np.hypot(1.0, 0.1))
    # a hinge 5.6 mm off along y and 0.04 deg askew: 5.6 mm at the part, although the lines meet
    # (to within 0.9 mm) about 8 m away
    tilt = np.radians(0.04)
    est = np.array([np.cos(tilt), np.sin(tilt), 0.0])
    assert origin_error_m(est, [0.0, 0.2518, 0.0145], [0.0, 0.2574, 0.0136]) == pytest.approx(
        np.hypot(0.0056, 0.0009), rel=1e-3)


def test_origin_error_refuses_zero_axis():
    with pytest.raises(DataError, match="non-zero 3-vector axis"):
        origin_error_m([0, 0, 0], [0, 0, 0], [0, 0, 0])


def test_part_iou_is_invariant_to_label_names_and_order():
    true = np.array(["body"] * 6 + ["door"] * 4 + ["environment"] * 2, dtype=object)
    rng = np.random.default_rng(0)
    perm = rng.permutation(true.size)
    rename = {"body": "p7", "door": "p2", "environment": "environment"}
    pred = np.array([rename[x] for x in true], dtype=object)
    m = part_iou(pred[perm], true[perm], pred_ignore=("environment",), true_ignore=("environment",))
    assert m.mean_iou == pytest.approx(1.0)
    assert m.pred_to_true == {"p7": "body", "p2": "door"}


def test_part_iou_hand_counted():
    # 10 samples: true door = 0..3, body = 4..9; predicted part A = 0..4 (door + one body sample),
    # part B = 5..8, sample 9 predicted environment.
    true = ["door"] * 4 + ["body"] * 6
    pred = ["A"] * 5 + ["B"] * 4 + ["env"]
    m = part_iou(pred, true, pred_ignore=("env",))
    assert m.pred_to_true == {"A": "door", "B": "body"}
    assert m.iou["door"] == pytest.approx(4 / 5)  # |A∩door| = 4, |A∪door| = 5
    assert m.iou["body"] == pytest.approx(4 / 6)  # |B∩body| = 4, |B∪body| = 6
    assert m.mean_iou == pytest.approx((4 / 5 + 4 / 6) / 2)


def test_part_iou_unmatched_true_part_scores_zero_and_spill_counts():
    true = ["body"] * 4 + ["door"] * 4 + ["floor"] * 2
    pred = ["X"] * 10  # one part covering everything, including the floor
    m = part_iou(pred, true, true_ignore=("floor",))
    assert m.iou == {"body": pytest.approx(0.4), "door": 0.0} or m.iou == {"body": 0.0, "door": pytest.approx(0.4)}
    assert m.mean_iou == pytest.approx(0.2)


def test_part_iou_from_counts_matches_the_hand_count_and_checks_shapes():
    # the hand-counted case above as a confusion matrix: rows A, B, env; columns door, body
    m = part_iou_from_counts(np.array([[4, 1], [0, 4], [0, 1]]), ["A", "B", "env"], ["door", "body"], pred_ignore=("env",))
    assert m.iou == {"door": pytest.approx(4 / 5), "body": pytest.approx(4 / 6)} and m.n_pixels == 10
    with pytest.raises(DataError, match="do not match 2 predicted and 2 true"):
        part_iou_from_counts(np.zeros((3, 2)), ["A", "B"], ["door", "body"])


def test_part_iou_refuses_mismatched_lengths():
    with pytest.raises(DataError, match="same length"):
        part_iou(["a", "b"], ["a"])


def _j(name, typ, parent, child, axis, origin):
    return JointRecord(name, typ, parent, child, np.array(axis, float), np.array(origin, float))


TRUE = [_j("door_joint", "revolute", "body", "door", [0, 0, 1], [0.3, 0.0, 0.0]),
        _j("drawer_joint", "prismatic", "body", "drawer", [0, -1, 0], [0.0, 0.0, 0.2])]


def test_match_joints_by_parts_and_errors():
    tilt = np.radians(2.0)
    est = [_j("j0", "prismatic", "base", "pB", [0, 1, 0], [5.0, 5.0, 5.0]),  # origin irrelevant for prismatic
           _j("j1", "revolute", "base", "pA", [0, np.sin(tilt), np.cos(tilt)], [0.3, 0.0, 0.0])]
    scores = {s.true_joint: s for s in match_joints(est, TRUE, {"pA": "door", "pB": "drawer", "base": "body"})}
    d, w = scores["door_joint"], scores["drawer_joint"]
    assert (d.est_joint, d.matched_by, d.type_correct) == ("j1", "parts", True)
    assert d.axis_error_deg == pytest.approx(2.0) and d.origin_error_m == pytest.approx(0.0, abs=1e-12)
    assert (w.est_joint, w.axis_error_deg, w.origin_error_m, w.type_correct) == ("j0", 0.0, None, True)


def test_match_joints_falls_back_to_geometry_and_reports_misses():
    est = [_j("j0", "revolute", "base", "q", [0, 0, 1], [0.32, 0.0, 0.0])]  # part q unmatched
    scores = {s.true_joint: s for s in match_joints(est, TRUE, {})}
    assert scores["door_joint"].matched_by == "geometry"
    assert scores["door_joint"].origin_error_m == pytest.approx(0.02)
    miss = scores["drawer_joint"]
    assert miss.est_joint is None and not miss.type_correct and miss.axis_error_deg is None


def test_wrong_type_is_scored():
    est = [_j("j0", "revolute", "base", "pB", [0, 1, 0], [0, 0, 0])]
    s = {x.true_joint: x for x in match_joints(est, TRUE, {"pB": "drawer"})}
    assert s["drawer_joint"].est_joint == "j0" and not s["drawer_joint"].type_correct


def test_topology():
    m = {"pA": "door", "pB": "drawer", "base": "body", "pC": "door"}
    good = [_j("a", "revolute", "base", "pA", [0, 0, 1], [0, 0, 0]), _j("b", "prismatic", "base", "pB", [0, 1, 0], [0, 0, 0]),
            _j("f", "fixed", "base", "pX", [1, 0, 0], [0, 0, 0])]  # fixed joints do not count
    assert topology_correct(good, TRUE, m)
    chained = [good[0], _j("b", "prismatic", "pA", "pB", [0, 1, 0], [0, 0, 0])]  # drawer hung on the door
    assert not topology_correct(chained, TRUE, m)
    wrong_type = [good[0], _j("b", "revolute", "base", "pB", [0, 1, 0], [0, 0, 0])]
    assert not topology_correct(wrong_type, TRUE, m)
    extra = good[:2] + [_j("c", "revolute", "base", "pC", [0, 0, 1], [0, 0, 0])]  # door split in two
    assert not topology_correct(extra, TRUE, m)
    assert not topology_correct(good[:2], TRUE, {"pA": "door"})  # unmapped parts


def test_mean_std_and_exponent():
    assert mean_std([1.0, None, 3.0, float("nan")]) == (2.0, 1.0, 2)
    assert mean_std([None]) == (None, None, 0)
    x = np.array([10.0, 20.0, 40.0, 80.0])
    assert loglog_exponent(x, 3.0 * x**1.5) == pytest.approx(1.5)
    assert loglog_exponent([5.0, 5.0], [1.0, 2.0]) is None
