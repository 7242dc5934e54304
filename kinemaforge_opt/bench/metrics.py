"""Reconstruction metrics of the seed's Table 1, as pure numpy functions (no pipeline code):
axis error, origin (joint-line) error, part IoU with Hungarian part matching, joint matching,
joint-type and topology correctness, mean ± std and log-log exponents.

Every function takes plain arrays / names, so each is checked against analytic answers in
``tests/bench/test_reco_metrics.py``.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..errors import DataError
from ..spatial import axis_angle_error, line_point_distance


def axis_error_deg(axis_est, axis_true) -> float:
    """Angle [deg] between the estimated and the true joint axis, sign-agnostic (a ≡ −a):
    in [0, 90].  Raises DataError for a zero-length axis."""
    a, b = np.asarray(axis_est, dtype=float), np.asarray(axis_true, dtype=float)
    if a.shape != (3,) or b.shape != (3,) or np.linalg.norm(a) < 1e-12 or np.linalg.norm(b) < 1e-12:
        raise DataError(f"axis error needs two non-zero 3-vectors, got {a.tolist()} and {b.tolist()}")
    return float(np.degrees(axis_angle_error(a, b)))


def origin_error_m(axis_est, origin_est, origin_true) -> float:
    """Distance [m] from the true joint origin (``origin_true``, the true line's point at the
    part) to the estimated joint line (origin_est + s·axis_est); parallel lines give their
    separation.  Meaningful for revolute (and helical) joints; a prismatic joint has no line
    (callers skip it).

    Not the two lines' shortest distance: two lines nearly parallel come closest far from the
    part (a lid's hinge 5.6 mm off and 0.04° askew comes within 0.9 mm of the true one 8 m
    away, protocol_laptop_0@s2), so that distance hid the error where the part turns."""
    a = np.asarray(axis_est, dtype=float)
    if a.shape != (3,) or np.linalg.norm(a) < 1e-12:
        raise DataError(f"origin error needs a non-zero 3-vector axis, got {a.tolist()}")
    return line_point_distance(a, origin_est, origin_true)


@dataclass(frozen=True)
class PartMatch:
    """Result of :func:`part_iou`.

    mean_iou: mean over the true parts of the IoU with their matched predicted part (0 for a
    true part left unmatched).  iou: true part -> IoU.  pred_to_true: predicted part -> true
    part (the Hungarian matching maximising the summed IoU; pairs with zero overlap are left
    out).  n_pixels: number of labelled samples compared."""

    mean_iou: float
    iou: dict
    pred_to_true: dict
    n_pixels: int


def part_iou(pred: Sequence[Hashable], true: Sequence[Hashable], pred_ignore: Iterable[Hashable] = (),
             true_ignore: Iterable[Hashable] = ()) -> PartMatch:
    """Part IoU between two labelings of the same N samples (pixels or points).

    ``pred``, ``true``: (N,) labels.  The parts are the distinct labels except the ignored ones
    (e.g. "environment", "nothing"); ignored samples still count in every union (a predicted part
    that spills onto the floor is penalised).  Predicted and true parts are matched one-to-one by
    the Hungarian method on the IoU matrix, so the labels' names and order do not matter.
    """
    p = np.asarray(pred, dtype=object)
    t = np.asarray(true, dtype=object)
    if p.shape != t.shape or p.ndim != 1:
        raise DataError(f"part IoU needs two label arrays of the same length, got shapes {p.shape} and {t.shape}")
    pred_names = list(dict.fromkeys(p.tolist()))
    true_names = list(dict.fromkeys(t.tolist()))
    pi = np.array([pred_names.index(x) for x in p.tolist()], dtype=np.int64)
    ti = np.array([true_names.index(x) for x in t.tolist()], dtype=np.int64)
    counts = np.bincount(pi * len(true_names) + ti, minlength=len(pred_names) * len(true_names))
    return part_iou_from_counts(counts.reshape(len(pred_names), len(true_names)), pred_names, true_names,
                                pred_ignore, true_ignore)


def part_iou_from_counts(counts: np.ndarray, pred_names: Sequence[Hashable], true_names: Sequence[Hashable],
                         pred_ignore: Iterable[Hashable] = (), true_ignore: Iterable[Hashable] = ()) -> PartMatch:
    """:func:`part_iou` from the confusion matrix: ``counts[i, j]`` samples labelled
    ``pred_names[i]`` and ``true_names[j]`` (every label, the ignored ones included, so unions
    are complete).  Use it to accumulate large labelings (millions of pixels) frame by frame."""
    C = np.asarray(counts, dtype=np.int64)
    if C.shape != (len(pred_names), len(true_names)):
        raise DataError(f"confusion counts of shape {C.shape} do not match {len(pred_names)} predicted and "
                        f"{len(true_names)} true labels")
    pi, ti = set(pred_ignore), set(true_ignore)
    rows = [i for i, x in enumerate(pred_names) if x not in pi]
    cols = [j for j, x in enumerate(true_names) if x not in ti and C[:, j].sum() > 0]
    if not cols:
        raise DataError("part IoU: the true labels hold no part (all samples ignored)")
    inter = C[np.ix_(rows, cols)].astype(float)
    union = C.sum(1)[rows][:, None] + C.sum(0)[cols][None, :] - inter
    iou = np.where(union > 0, inter / np.maximum(union, 1), 0.0)
    pred_to_true, per_true = {}, {true_names[j]: 0.0 for j in cols}
    if rows:
        for r, c in zip(*linear_sum_assignment(-iou)):
            if iou[r, c] > 0:
                pred_to_true[pred_names[rows[r]]] = true_names[cols[c]]
                per_true[true_names[cols[c]]] = float(iou[r, c])
    return PartMatch(float(np.mean(list(per_true.values()))), per_true, pred_to_true, int(C.sum()))


@dataclass(frozen=True)
class JointRecord:
    """A joint as the metrics see it: type, parent and child part names, world axis (3,) and a
    world point on its line (3,) [m]."""

    name: str
    type: str
    parent: str
    child: str
    axis_world: np.ndarray
    origin_world: np.ndarray


@dataclass(frozen=True)
class JointScore:
    """One true movable joint against its matched estimate (None fields: no estimate matched;
    origin_error_m is None for prismatic joints).  matched_by: "parts" (the estimate's child part
    is the true child under the part matching) or "geometry" (Hungarian on axis and line
    distance among the joints the parts left unmatched)."""

    true_joint: str
    true_type: str
    est_joint: str | None
    est_type: str | None
    axis_error_deg: float | None
    origin_error_m: float | None
    type_correct: bool
    matched_by: str | None


def _geometric_cost(e: JointRecord, t: JointRecord, length_scale_m: float) -> float:
    c = np.radians(axis_error_deg(e.axis_world, t.axis_world))
    if t.type != "prismatic" and e.type != "prismatic":
        c += origin_error_m(e.axis_world, e.origin_world, t.origin_world) / length_scale_m
    return float(c)


def match_joints(est: Sequence[JointRecord], true: Sequence[JointRecord], pred_to_true: dict | None = None,
                 length_scale_m: float = 0.1) -> list[JointScore]:
    """Score every true movable joint against the estimated movable joints.

    First by parts: the estimate whose child part maps (``pred_to_true``) onto the true joint's
    child.  The true joints still unmatched are then paired with the unused estimates by the
    Hungarian method on cost = axis angle [rad] + line distance / ``length_scale_m`` (the line
    term only when neither joint is prismatic).  A true joint with no estimate left scores
    type_correct False and None errors."""
    est = [e for e in est if e.type != "fixed"]
    true = [t for t in true if t.type != "fixed"]
    pred_to_true = pred_to_true or {}
    pairs: dict[int, tuple[int, str]] = {}
    used: set[int] = set()
    for ti, t in enumerate(true):
        for ei, e in enumerate(est):
            if ei not in used and pred_to_true.get(e.child) == t.child:
                pairs[ti] = (ei, "parts")
                used.add(ei)
                break
    left_t = [i for i in range(len(true)) if i not in pairs]
    left_e = [i for i in range(len(est)) if i not in used]
    if left_t and left_e:
        C = np.array([[_geometric_cost(est[e], true[t], length_scale_m) for e in left_e] for t in left_t])
        for r, c in zip(*linear_sum_assignment(C)):
            pairs[left_t[r]] = (left_e[c], "geometry")
    out = []
    for ti, t in enumerate(true):
        if ti not in pairs:
            out.append(JointScore(t.name, t.type, None, None, None, None, False, None))
            continue
        ei, how = pairs[ti]
        e = est[ei]
        ax = axis_error_deg(e.axis_world, t.axis_world)
        org = None if t.type == "prismatic" else origin_error_m(e.axis_world, e.origin_world, t.origin_world)
        out.append(JointScore(t.name, t.type, e.name, e.type, ax, org, e.type == t.type, how))
    return out


def topology_correct(est: Sequence[JointRecord], true: Sequence[JointRecord], pred_to_true: dict) -> bool:
    """True when the estimated movable joints, with their parts renamed by ``pred_to_true``, are
    exactly the true movable joints as (parent, child, type) triples: same tree, same types, no
    extra or missing joint.  A part that ``pred_to_true`` does not map makes it False."""
    mapped = set()
    for e in est:
        if e.type == "fixed":
            continue
        if e.parent not in pred_to_true or e.child not in pred_to_true:
            return False
        mapped.add((pred_to_true[e.parent], pred_to_true[e.child], e.type))
    want = {(t.parent, t.child, t.type) for t in true if t.type != "fixed"}
    n_est = sum(e.type != "fixed" for e in est)
    return mapped == want and n_est == len(want)


def mean_std(values: Iterable[float | None]) -> tuple[float | None, float | None, int]:
    """(mean, population std, n) of the values that are not None / NaN; (None, None, 0) if none."""
    v = np.array([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if v.size == 0:
        return None, None, 0
    return float(v.mean()), float(v.std()), int(v.size)


def loglog_exponent(x: Sequence[float], y: Sequence[float]) -> float | None:
    """Exponent p of y ∝ x^p by least squares on (log x, log y) over the positive pairs; None
    when fewer than two distinct x remain."""
    xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    ok = (xa > 0) & (ya > 0) & np.isfinite(xa) & np.isfinite(ya)
    if np.unique(xa[ok]).size < 2:
        return None
    return float(np.polyfit(np.log(xa[ok]), np.log(ya[ok]), 1)[0])
