"""Motion-consistent per-point segmentation of tracked proposals.

A proposal is one Euclidean cluster of moving points (:mod:`segment`), so two parts that touch
while they move — two drawers stacked with no gap — can share one proposal, whose track then
follows the larger of them; growing can also carry a strip of the body into a part.  After
tracking, every point of a proposal is therefore asked which of the known rigid motions explains
it: its own track, the static base (the identity), or the track of another proposal (carried from
this proposal's reference step).  A motion's evidence for a point at a step is the point's
*support* under the free-space test of :mod:`change` against every image of the step: +1 when
some image confirms the moved point, −1 when the cameras only saw through it, 0 otherwise
(hidden, out of view).

Two motions are compared at the steps both observe where they move the proposal differently (RMS
displacement of its points above the fine ICP radius; of those, the GROW_STEPS where they differ
most), and only where the images judge the point as its own track places it (a part's hidden
inside speaks for no motion).  A point *prefers* another motion when that motion's summed support
exceeds its own track's by at least MIN_EVIDENCE: one verdict can be a noise outlier (a 3σ test
fails ~0.3 % of the time), two independent ones are the criterion :mod:`change` uses to call a
point moving.  Points that prefer the same motion form *groups* (DBSCAN, as proposals are made);
a group of at least the tracker's smallest part (``tracker.min_points``) leaves the proposal — to
the base (its points are dropped from every proposal, so they are labelled base) or to the other
proposal (carried to its reference step) — provided the images do not contradict the new motion
(at most MAX_VIOLATED_SHARE of the group seen through at COMOVING_SHARE of the compared steps).

A group no motion takes whose own track puts it where the images saw through — at MIN_EVIDENCE
steps or more, over 1 − COMOVING_SHARE of the steps where it is judged, counting only steps whose
pose the majority of the proposal's judged points accept (:func:`unexplained`) — belongs to a part
whose motion is unknown (a neighbouring drawer with no clean track of its own): it is dropped
too, so that it does not bend its host's joint fit.  A proposal left with fewer than
``tracker.min_points`` points is dropped.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .clouds import downsample
from .segment import CLUSTER_VOXELS, clusters
from .track import (COMOVING_SHARE, GROW_STEPS, ICP_FINE_VOXELS, MAX_VIOLATED_SHARE, MIN_CONSISTENT_SHARE, Proposal,
                    Tracker, displacement, tracking_subset)

# Net verdicts by which another motion must out-support a point's own track (module doc).
MIN_EVIDENCE = 2
# Support is computed on the proposal's points downsampled at this many voxels (each then
# speaks for the few points of its cell: a group of the smallest part still has dozens).
SCORE_VOXELS = CLUSTER_VOXELS
BASE_MOTION = "base"
UNEXPLAINED = "unexplained"  # points no known motion explains


def observed(Ts: np.ndarray) -> np.ndarray:
    """(T,) whether each (4, 4) motion of a (T, 4, 4) track is known."""
    return np.isfinite(Ts).all(axis=(1, 2))


def step_support(tracker: Tracker, points: np.ndarray, T: np.ndarray, s: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((N,) support, (N,) seen through, (N,) judged) at step s of (N, 3) world points moved by the
    (4, 4) motion ``T`` (module doc: support +1 where some image confirms the moved point, −1
    where the images only saw through it, 0 otherwise; judged: either of the two)."""
    x = points @ T[:3, :3].T + T[:3, 3]
    cons, viol = tracker.verdicts(x, s)
    return cons - viol, viol.astype(bool), (cons + viol) > 0


def candidate_motions(p: Proposal, proposals: list[Proposal]) -> dict[str, np.ndarray]:
    """Name -> (T, 4, 4) world motions of ``p``'s points from its reference step under each
    alternative to its own track: the base (identity) and every other proposal observed at
    ``p``'s reference step (its motion carried from there)."""
    out = {BASE_MOTION: np.tile(np.eye(4), (len(p.Ts_delta), 1, 1))}
    for q in proposals:
        if q is not p and observed(q.Ts_delta)[p.ref]:
            out[q.name] = q.Ts_delta @ np.linalg.inv(q.Ts_delta[p.ref])
    return out


def compared_steps(p: Proposal, Ts: np.ndarray, sample: np.ndarray, tolerance: float) -> np.ndarray:
    """Of the steps both ``p`` and the motions ``Ts`` observe where they move (N, 3) ``sample``
    apart by more than ``tolerance`` [m] RMS (:func:`track.displacement`), the GROW_STEPS where
    they differ most (those discriminate best, as in :meth:`Tracker.grow`), in time order."""
    both = np.flatnonzero(observed(p.Ts_delta) & observed(Ts))
    apart = np.array([displacement(p.Ts_delta[s], Ts[s], sample) for s in both])
    keep = np.argsort(-apart, kind="stable")[:GROW_STEPS]
    return np.sort(both[keep[apart[keep] > tolerance]])


def preferences(tracker: Tracker, p: Proposal, motions: dict[str, np.ndarray], steps: dict[str, np.ndarray],
                points: np.ndarray) -> np.ndarray:
    """(M,) name of the motion each of (M, 3) ``points`` (world, at ``p``'s reference step)
    prefers, "" for ``p``'s own track: the alternative whose summed support over its compared
    ``steps`` leads the own track's most, by at least MIN_EVIDENCE, counting only the steps where
    the images judge the point where its own track puts it (a part's hidden inside — a drawer's
    floor in the body — says nothing for its own track, and a motion that slides it onto some
    visible surface is no better explanation) — module doc."""
    best = np.zeros(len(points), dtype=int)
    choice = np.full(len(points), "", dtype=object)
    own: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # own track's (support, judged) per step
    for name, Ts in motions.items():
        lead = np.zeros(len(points), dtype=int)
        for s in steps[name]:
            if s not in own:
                mine, _, judged = step_support(tracker, points, p.Ts_delta[s], s)
                own[s] = (mine, judged)
            mine, judged = own[s]
            lead += judged * (step_support(tracker, points, Ts[s], s)[0] - mine)
        take = (lead >= MIN_EVIDENCE) & (lead > best)
        choice[take], best[take] = name, lead[take]
    return choice


def uncontradicted(tracker: Tracker, points: np.ndarray, Ts: np.ndarray, steps: np.ndarray) -> bool:
    """Whether (N, 3) ``points`` moved by the motions ``Ts`` are seen through by at most
    MAX_VIOLATED_SHARE of them at COMOVING_SHARE of ``steps`` (all of them when there are none)."""
    x = tracking_subset(points)
    shares = [step_support(tracker, x, Ts[s], s)[1].mean() for s in steps]
    return bool(np.mean(np.array(shares) <= MAX_VIOLATED_SHARE) >= COMOVING_SHARE) if shares else True


def unexplained(tracker: Tracker, p: Proposal, points: np.ndarray) -> np.ndarray:
    """(M,) whether ``p``'s own track puts each of (M, 3) ``points`` (at its reference step) where
    the images saw through at MIN_EVIDENCE or more of the steps whose pose the majority of the
    judged points accept (MIN_CONSISTENT_SHARE: a step where the track itself failed says nothing
    about which points belong to it), and at over 1 − COMOVING_SHARE of the steps where they are
    judged — the share of failed steps :func:`track.support` excuses a partner's track: a track
    a few centimetres off in its own plane at a step or two puts a strip along the part's edge in
    the air there, and that strip stays)."""
    cons_n = np.zeros(len(points), dtype=int)
    viol_n = np.zeros(len(points), dtype=int)
    for s in np.flatnonzero(observed(p.Ts_delta)):
        if s == p.ref:
            continue
        support, viol, judged = step_support(tracker, points, p.Ts_delta[s], s)
        cons = support > 0
        if judged.any() and cons.sum() >= MIN_CONSISTENT_SHARE * judged.sum():
            cons_n += cons
            viol_n += viol
    return (viol_n >= MIN_EVIDENCE) & (viol_n > (1.0 - COMOVING_SHARE) * (viol_n + cons_n))


def _edge(tree: cKDTree, cells: np.ndarray, cell: float) -> np.ndarray:
    """Indices of the sample cells on the edge of a group of ``cells`` (indices into the sample
    behind ``tree``, cells of edge ``cell`` [m]): the group's cells next to a cell outside it and
    those outside cells (26-neighbourhood)."""
    inside = np.zeros(tree.n, dtype=bool)
    inside[cells] = True
    edge = set()
    for c, nb in zip(cells, tree.query_ball_point(tree.data[cells], np.sqrt(3.0) * cell * 1.01)):
        out = [j for j in nb if not inside[j]]
        if out:
            edge.add(int(c))
            edge.update(out)
    return np.array(sorted(edge), dtype=int)


def split_moves(tracker: Tracker, p: Proposal, proposals: list[Proposal]) -> list[tuple[str, np.ndarray]]:
    """(motion name, indices into ``p.points``) of each group of ``p``'s points that another motion
    explains better than ``p``'s own track and the images do not contradict (module doc).

    Support is scored on the points downsampled at SCORE_VOXELS voxels, each point taking its
    cell's choice; a group's edge cells (a boundary between two parts cuts through cells) are then
    judged point by point, and their points join the group when its motion out-supports their own
    track by MIN_EVIDENCE."""
    motions = candidate_motions(p, proposals)
    cell = SCORE_VOXELS * tracker.voxel
    sample = downsample(p.points, cell)
    steps = {name: compared_steps(p, Ts, sample, ICP_FINE_VOXELS * tracker.voxel) for name, Ts in motions.items()}
    coarse = preferences(tracker, p, motions, steps, sample)
    lost = unexplained(tracker, p, sample)
    if not np.any(coarse != "") and not lost.any():
        return []
    tree = cKDTree(sample)
    nearest = tree.query(p.points)[1]
    taken = np.zeros(len(p.points), dtype=bool)
    moves = []
    for name in dict.fromkeys(c for c in coarse if c):
        idx = np.flatnonzero(coarse[nearest] == name)
        for group in clusters(p.points[idx], tracker.voxel, tracker.min_points):
            members = idx[group][~taken[idx[group]]]  # not already joined to an earlier group's edge
            if not uncontradicted(tracker, p.points[members], motions[name], steps[name]):
                continue
            on_edge = np.isin(nearest, _edge(tree, np.unique(nearest[members]), cell)) & ~taken
            judged = np.flatnonzero(on_edge)
            joins = judged[preferences(tracker, p, {name: motions[name]}, steps, p.points[judged]) == name]
            members = np.union1d(np.setdiff1d(members, judged), joins)
            if len(members) < tracker.min_points:  # what its edge left is smaller than a part
                continue
            taken[members] = True
            moves.append((name, members))
    # what no motion took and the own track puts where the images saw through is nobody's
    idx = np.flatnonzero(lost[nearest] & ~taken)
    moves += [(UNEXPLAINED, idx[group]) for group in clusters(p.points[idx], tracker.voxel, tracker.min_points)]
    return moves


def resegment(tracker: Tracker, proposals: list[Proposal]) -> list[Proposal]:
    """The proposals with every group of points that another motion explains moved to it (to the
    base: dropped) and every unexplained group dropped, judged against the tracks as given
    (:func:`split_moves`); proposals left smaller than ``tracker.min_points`` are dropped (module
    doc); an unchanged proposal is returned as is."""
    by_name = {p.name: p for p in proposals}
    keep = {p.name: np.ones(len(p.points), dtype=bool) for p in proposals}
    received: dict[str, list[np.ndarray]] = {p.name: [] for p in proposals}
    for p in proposals:
        for name, idx in split_moves(tracker, p, proposals):
            keep[p.name][idx] = False
            if name not in (BASE_MOTION, UNEXPLAINED):
                q = by_name[name]
                D = np.linalg.inv(q.Ts_delta[p.ref])  # p's reference step -> q's
                received[name].append(p.points[idx] @ D[:3, :3].T + D[:3, 3])
    out = []
    for p in proposals:
        if keep[p.name].all() and not received[p.name]:
            out.append(p)  # unchanged: the same object
            continue
        points = np.concatenate([p.points[keep[p.name]], *received[p.name]])
        if len(points) >= tracker.min_points:
            out.append(Proposal(p.name, p.ref, points, p.Ts_delta))
    return out
