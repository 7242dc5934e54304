"""The kinematic constraint graph and its reconciliation into a kinematic tree.

Nodes: the static world ("world", the ground) and every track.  For each ordered pair whose
parent has a frame (the world or a full-pose track) the child's relative motion is fitted with
every joint type; a position-only track cannot be a parent (forbidden edge: a point has no frame).

Edge confidence ρ(i→j, type) = P(parent = i | j) · P(type | i, j): the type posterior from
:mod:`graph.score` and a parent posterior exp(−BIC*/2) normalised over j's candidate parents
(BIC* = the pair's best type, on one scale for all of them: misfit per sample, one sample count,
as a parent observed at fewer steps shares fewer of j's samples).  Both are kept in log space.

Tracks joined by a confident rigid edge (rigid posterior ≥ MERGE_PROBABILITY and rigid residual
within SIGNIFICANCE·σ of the noise) are merged first
(union–find); the group holding the world is the base, so the static part is *found* from the
data.  The tree is the maximum spanning arborescence on log ρ (networkx, Edmonds) rooted at the
base: the root's in-edges are EXCLUDED, as networkx has no root argument — this is the
contextual preference for the ground/static part as root.  A child whose parent the data cannot
tell from one of that parent's ancestors, or that moves with the ancestor, then hangs from
the ancestor (the shorter chain, Occam; see ``_shallowest``).
``ArborescenceIterator`` yields the k best trees.  ``method="greedy"`` is the ablation without
a graph: attach groups one at a time, least-moving first, each to the already placed group that
explains it best.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import islice

import networkx as nx
import numpy as np
from networkx.algorithms.tree.branchings import ArborescenceIterator
from scipy.special import ndtri
from threadpoolctl import threadpool_limits

from ..errors import DataError
from ..io.tracks import PoseTracks
from .fit import JointHypothesis, fit_all
from .motion import MIN_SAMPLES, SIGMA_FLOOR, WORLD, relative_motion
from .score import SIGNIFICANCE, closeness_z, log_posterior, score_pair

# A pair is merged into one rigid part when the rigid type is at least this probable (a 95 %
# decision level on the type posterior, not a data-tuned value).
MERGE_PROBABILITY = 0.95
# Two candidate parents explain a child equally well when Vuong's closeness test cannot tell
# them apart at the same 95 % level (two-sided): |z| within this (see :func:`_shallowest`).
CLOSENESS_Z = float(ndtri(0.5 + MERGE_PROBABILITY / 2.0))  # the standard normal quantile
# log ρ of an impossible arc (ρ = 0).  Finite, and far below any real tree's Σ log ρ (the
# smallest positive ρ gives −745 per arc): Edmonds' algorithm subtracts arc weights while it
# contracts cycles, and −1e300 absorbs every other weight in those sums — on a moving-camera
# cabinet networkx then returned a tree of Σ log ρ = −2.83 before one of −0.06.
IMPOSSIBLE_LOG = -1e6


@dataclass(frozen=True, eq=False)
class TreeJoint:
    """One joint of a tree: ``child`` moves relative to ``parent`` as ``hypothesis`` says;
    ``hypothesis.confidence`` is the edge's ρ = P(parent) · P(type)."""

    name: str
    parent: str
    child: str
    hypothesis: JointHypothesis

    @property
    def type(self) -> str:
        return self.hypothesis.type


@dataclass(frozen=True, eq=False)
class LooseTrack:
    """A track the tree keeps rigid with a part although it moves relative to it: the arc's most
    probable type is rigid (no joint type explains the track better — typically none fits its
    orientations), yet the rigid fit misfits its positions beyond the noise.  The tree may miss a
    joint there (a part tracked badly, e.g. shut flush with the body and seen by few cameras), or
    the track spans two parts.  track: the arc's child part (its first track's name); part: the
    part it joined; rigid: the rigid fit; best_moving: the most probable moving type (the best fit
    of the positions among equally improbable ones; None when the edge holds no moving fit)."""

    track: str
    part: str
    rigid: JointHypothesis
    best_moving: JointHypothesis | None

    @property
    def rotation_rms(self) -> float:
        """The orientation misfit [rad] of the better of the two fits."""
        fits = (self.rigid,) if self.best_moving is None else (self.rigid, self.best_moving)
        return min(h.rotation_rms for h in fits)

    def record(self) -> dict:
        """The reconstruction.json entry (SI units) with :meth:`message`."""
        r, m = self.rigid, self.best_moving
        return {"track": self.track, "part": self.part, "rigid_rms_m": float(r.residual_rms),
                "best_moving_type": None if m is None else m.type,
                "best_moving_rms_m": None if m is None else float(m.residual_rms),
                "noise_m": float(r.noise_sigma), "rotation_rms_rad": float(self.rotation_rms), "message": self.message()}

    def message(self) -> str:
        """One line for a person: what moves, by how much, and what the tree did with it."""
        r, m = self.rigid, self.best_moving
        against = "" if m is None else f" against {m.type} {m.residual_rms * 1e3:.0f} mm"
        return (f"track {self.track} is kept rigid with part {self.part} although it moves relative to it: "
                f"rigid fit {r.residual_rms * 1e3:.0f} mm RMS{against} (noise {r.noise_sigma * 1e3:.1f} mm), "
                f"no joint type fitting its orientations better than {self.rotation_rms:.3f} "
                "rad RMS; a joint may be missing there, or the track spans two parts")


@dataclass(frozen=True, eq=False)
class KinematicTree:
    """A kinematic tree over merged parts.

    root: the base part's name (holds the world).  parts: {part name: member track names}.
    joints: parent-before-child order.  log_score: Σ log ρ over the joints (higher is better).
    loose: the tracks it keeps rigid with a part although they move relative to it (:class:`LooseTrack`).
    """

    root: str
    parts: dict[str, tuple[str, ...]]
    joints: tuple[TreeJoint, ...]
    log_score: float
    loose: tuple[LooseTrack, ...] = ()


@dataclass(frozen=True, eq=False)
class GraphResult:
    """best: the chosen tree; alternatives: the next best trees (k-best, best first, excluding
    ``best``; fewer when some re-hang onto an earlier tree, see ``_graph_trees``).  edges:
    {(parent part, child part): {type: scored JointHypothesis}} for every allowed edge of the
    constraint graph.  method: 'graph' or 'greedy'."""

    best: KinematicTree
    alternatives: tuple[KinematicTree, ...]
    edges: dict[tuple[str, str], dict[str, JointHypothesis]]
    method: str


def _pair_fits(tracks: PoseTracks) -> dict[tuple[str, str], dict[str, JointHypothesis]]:
    """Scored fits for every allowed ordered pair (parent, child); indices None = world."""
    names = (WORLD,) + tracks.names
    obs = tracks.observed()
    out = {}
    for i, parent in enumerate(names):
        if i > 0 and not tracks.has_orientation:
            continue  # forbidden: a position-only track has no frame to be a parent
        for j, child in enumerate(names[1:], start=1):
            if i == j:
                continue
            both = obs[j - 1] if i == 0 else obs[j - 1] & obs[i - 1]
            if both.sum() < MIN_SAMPLES:
                continue  # too few common samples to tell any relation: no edge
            motion = relative_motion(tracks, None if i == 0 else i - 1, j - 1)
            out[(parent, child)] = score_pair(fit_all(motion))
    return out


def _adequate_rigid(h: JointHypothesis) -> bool:
    """A rigid fit whose residual RMS is within SIGNIFICANCE·√3·σ of the pair's noise."""
    return h.residual_rms <= SIGNIFICANCE * np.sqrt(3.0) * h.noise_sigma


def _merge(tracks: PoseTracks, fits) -> dict[str, tuple[str, ...]]:
    """Union–find over confident rigid pairs -> {part name: members}; the part holding the world
    is named 'base', others after their first member.

    Pairs are taken best-fitting first, and two groups join only when no pair across them
    contradicts it (a fitted relation whose rigid fit misfits, see :func:`_adequate_rigid`): a
    track seen only while two drawers both rest is rigid with each of them, and must not chain
    drawers that move at different times into one part."""
    parent = {n: n for n in (WORLD,) + tracks.names}
    members = {n: [n] for n in parent}

    def contradicted(ra, rb):
        for x in members[ra]:
            for y in members[rb]:
                for pair in ((x, y), (y, x)):
                    if pair in fits and not _adequate_rigid(fits[pair]["rigid"]):
                        return True
        return False

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    order = sorted(fits, key=lambda ab: fits[ab]["rigid"].residual_rms / max(fits[ab]["rigid"].noise_sigma, 1e-300))
    for a, b in order:
        rigid = fits[(a, b)]["rigid"]
        # Confident *and* adequate: rigid is the most probable type and its residual is at the
        # noise level (when no type fits, rigid can win by default; that is no reason to merge).
        if rigid.confidence >= MERGE_PROBABILITY and _adequate_rigid(rigid):
            ra, rb = find(a), find(b)
            if ra != rb and not contradicted(ra, rb):
                keep = WORLD if WORLD in (ra, rb) else min(ra, rb)
                gone = rb if keep == ra else ra
                parent[gone] = keep
                members[keep] += members.pop(gone)
    groups: dict[str, list[str]] = {}
    for n in parent:
        groups.setdefault(find(n), []).append(n)
    return {("base" if root == WORLD else root): tuple(m) for root, m in groups.items()}


def _representative(members: tuple[str, ...], tracks: PoseTracks) -> str:
    """The world if present, else the member observed most often."""
    if WORLD in members:
        return WORLD
    obs = tracks.observed().sum(axis=1)
    return max(members, key=lambda m: obs[tracks.names.index(m)])


def _part_edges(tracks, fits, parts):
    """{(parent part, child part): scored hypotheses} between part representatives, with the
    confidence of each type set to ρ = P(parent) · P(type)."""
    rep = {p: _representative(m, tracks) for p, m in parts.items()}
    raw = {(pa, pb): fits[(rep[pa], rep[pb])] for pa in parts for pb in parts if (rep[pa], rep[pb]) in fits}
    edges = {}
    for child in parts:
        best = {pa: _best_type(hyps) for (pa, pb), hyps in raw.items() if pb == child}
        if not best:
            continue
        log_parent = log_posterior(_parent_bic(best))
        for pa in best:
            edges[(pa, child)] = {
                k: replace(h, confidence=float(np.exp(log_parent[pa]) * h.confidence))
                for k, h in raw[(pa, child)].items()
            }
    return edges


def _parent_bic(best: dict[str, JointHypothesis]) -> dict[str, float]:
    """BIC of each candidate parent's best relation on a *common* scale for the child: the
    σ and effective sample fraction of the child's best-explained pair (per-pair scaling would
    normalise a bad parent's misfit away), and one sample count: each fit's misfit and latent
    joint values per sample, times the most samples any candidate shares with the child (summed
    over its own samples, a parent tracked over part of the recording wins by the samples it
    lacks: protocol_drawer_1@s7's drawer, lost when pulled, took the body's place as the parent
    of the drawers coasting back after it)."""
    ref = min(best.values(), key=lambda h: max(h.residual_rms, np.sqrt(3.0) * h.noise_sigma))
    sigma2 = max(ref.residual_rms**2 / 3.0, ref.noise_sigma**2)
    s = max((1.0 - float(np.clip(ref.residual_autocorr, 0.0, 1.0))) / (1.0 + max(ref.residual_autocorr, 0.0)), 1.0 / ref.n_samples)
    n = max(h.n_samples for h in best.values())
    return {
        pa: s * n * h.residual_rms**2 / sigma2 + (h.n_params + s * n * h.n_latent / h.n_samples) * np.log(n)
        for pa, h in best.items()
    }


def _best_type(hyps: dict[str, JointHypothesis]) -> JointHypothesis:
    return max(hyps.values(), key=lambda h: h.confidence)


def _log(x: float) -> float:
    return float(np.log(x)) if x > 0 else IMPOSSIBLE_LOG


def _travel(h: JointHypothesis, times: np.ndarray) -> float:
    """Total variation of the fitted joint value Σ|Δq| [m or rad] over the samples at ``times``
    [s] (a subset of ``h.times``): how far the child moves relative to the parent there."""
    return float(np.abs(np.diff(h.q[np.isin(h.times, times)])).sum())


def _tree(root, parts, edges, arcs) -> KinematicTree:
    """Order arcs parent-before-child and name joints j0, j1, …  A child whose chosen relation
    is rigid is part of its parent's link: its members join the parent part, its own children hang
    from the parent, and log ρ of that arc still counts in the tree's score.  The tree's joints
    are therefore all moving ones; a fixed joint would claim a separate rigid body that the data
    do not show (a track that moves but that no joint type explains — a fragment registered
    erratically — is no body of its own either)."""
    rigid_score = 0.0
    owner = {p: p for p in parts}
    moving_rigid = []  # rigid arcs whose rigid fit misfits the child's positions

    def top(p):
        while owner[p] != p:
            p = owner[p]
        return p

    for a, b in arcs:
        h = _best_type(edges[(a, b)])
        if h.type == "rigid" and h.confidence > 0:  # all-zero ρ is no choice (greedy's last resort)
            owner[b] = a
            rigid_score += _log(h.confidence)
            if not _adequate_rigid(h):
                moving_rigid.append((a, b, h))
    loose = tuple(LooseTrack(b, top(a), h, max((m for m in edges[(a, b)].values() if m.type != "rigid"),
                                               key=lambda m: (m.confidence, -m.residual_rms), default=None))
                  for a, b, h in moving_rigid)
    if any(owner[p] != p for p in parts):
        merged: dict[str, list[str]] = {}
        for p in parts:
            merged.setdefault(top(p), []).extend(parts[p])
        parts = {p: tuple(m) for p, m in merged.items()}
        # a joint keeps its fitted relation to the (rigidly attached) member it was fitted to
        edges = {**edges, **{(top(a), b): edges[(a, b)] for a, b in arcs if owner[b] == b and top(a) != a}}
        arcs = [(top(a), b) for a, b in arcs if owner[b] == b]
    children: dict[str, list[str]] = {}
    for a, b in arcs:
        children.setdefault(a, []).append(b)
    order, stack = [], [root]
    while stack:
        node = stack.pop()
        for c in sorted(children.get(node, []), reverse=True):
            order.append((node, c))
            stack.append(c)
    joints = tuple(
        TreeJoint(f"j{i}", a, b, _best_type(edges[(a, b)])) for i, (a, b) in enumerate(order)
    )
    return KinematicTree(root, parts, joints, rigid_score + sum(_log(j.hypothesis.confidence) for j in joints), loose)


def _carrier(edges, anc: str, parent: str, child: str, held: JointHypothesis) -> str | None:
    """Which of ``parent`` and its ancestor ``anc`` the child moves with, by joint travel: "anc",
    "parent", or None when the travel cannot tell.  ``held``: the best fit of the arc parent ->
    child.

    A child carried by its parent travels *less* relative to it than relative to the ancestor
    (the parent's own travel is added); a child that stays put while its parent moves travels
    *more* relative to the parent (it must counter-move).  The difference of the two travels is
    therefore about ± the parent's own travel relative to the ancestor; it decides when it
    exceeds half of that.  Comparable only in one joint type (the units of q), for a fit from the
    ancestor that is not clearly worse: residual RMS within SIGNIFICANCE times the parent's
    (floored at SIGMA_FLOOR's) and orientations not clearly worse (:func:`_turns_worse`; a hinge
    fitted from the base to a folding door's second leaf leaves its turn unexplained, and its q
    says nothing).  The travels are summed over the samples all three fits share: a parent
    tracked over part of the recording sees less of the child's travel than the ancestor does
    (protocol_drawer_1@s7: a drawer's track lost when it is pulled would carry the two drawers
    whose coast after it only the body sees)."""
    if held.type == "rigid" or (anc, parent) not in edges or _best_type(edges[(anc, parent)]).type != held.type:
        return None
    same, own = edges[(anc, child)][held.type], edges[(anc, parent)][held.type]
    misfits = same.residual_rms > SIGNIFICANCE * max(held.residual_rms, np.sqrt(3.0) * SIGMA_FLOOR)
    if misfits or _turns_worse(same, held):
        return None
    shared = np.intersect1d(np.intersect1d(same.times, held.times), own.times)
    difference, margin = _travel(same, shared) - _travel(held, shared), 0.5 * _travel(own, shared)
    return "anc" if difference < -margin else "parent" if difference > margin else None


def _turns_worse(alt: JointHypothesis, held: JointHypothesis) -> bool:
    """True when ``alt`` misfits the child's orientations clearly (SIGNIFICANCE times) worse than
    ``held`` does, both floored at the white-noise level (full-pose tracks; never for
    position-only ones).  The closeness test compares positions only: a folding door's second
    leaf, seen from the base, fits a straight slide to its positions about as well as the hinge
    on the first leaf, while the slide leaves its 0.3-rad turn unexplained."""
    if held.rotation_sigma <= 0:
        return False
    floor = np.sqrt(3.0) * max(held.rotation_sigma, SIGMA_FLOOR)
    return alt.rotation_rms > SIGNIFICANCE * max(held.rotation_rms, floor)


def _shallowest(root, edges, arcs) -> list[tuple[str, str]]:
    """Occam's rule on the arborescence's arcs: a child hangs from the ancestor of its parent
    nearest the root that it moves with, or, when the joint travel cannot tell
    (:func:`_carrier`), that explains its motion as well as the parent does: Vuong's closeness
    test tells the two fits' positions apart by no more than CLOSENESS_Z (either way), and the
    ancestor's fit does not turn clearly worse (:func:`_turns_worse`).

    Two doors on one hinge line move about the same axis relative to the base and relative to
    each other; the chain through the other door fits within the noise just as well, but is the
    longer explanation (it needs that door's joint to be right too).  Drawers on parallel rails
    opened in turn fit each other as well as the body, or better where their tracks share an
    error (a camera drift cancels between two drawers): the travel says the body.  A tray
    sliding out of an opened drawer along the same rail fits the body as well as the drawer:
    the travel says the drawer, which carries it.

    Re-hanging a child on an ancestor of its parent cannot close a cycle; parents are settled
    top-down.  The joint becomes the ancestor's best type (rigid when the child barely moves
    relative to it: a fragment spanning two drawers then rejoins the body)."""
    parent = {b: a for a, b in arcs}
    children: dict[str, list[str]] = {}
    for a, b in arcs:
        children.setdefault(a, []).append(b)
    queue = [root]
    while queue:
        node = queue.pop(0)
        for c in sorted(children.get(node, [])):
            queue.append(c)
            chain = [parent[c]]
            while chain[-1] != root:
                chain.append(parent[chain[-1]])
            held = _best_type(edges[(parent[c], c)])
            for anc in reversed(chain[1:]):  # root first
                if (anc, c) not in edges:
                    continue
                alt = _best_type(edges[(anc, c)])
                carrier = _carrier(edges, anc, parent[c], c, held)
                as_well = abs(closeness_z(held, alt)) <= CLOSENESS_Z and not _turns_worse(alt, held)
                if alt.confidence > 0 and (carrier == "anc" or carrier is None and as_well):
                    parent[c] = anc
                    break
    return [(parent[b], b) for _, b in arcs]


def _arborescences(parts, edges, k_best: int) -> list[list[tuple[str, str]]]:
    """The arcs of the k maximum spanning arborescences rooted at the base, by decreasing
    Σ log ρ of their best types (networkx's Edmonds iterator; ρ = 0 weighs IMPOSSIBLE_LOG)."""
    G = nx.DiGraph()
    G.add_nodes_from(parts)
    for (a, b), hyps in edges.items():
        G.add_edge(a, b, weight=_log(_best_type(hyps).confidence))
    excluded = [(a, "base") for a in G.predecessors("base")]
    return [list(A.edges) for A in islice(ArborescenceIterator(G, weight="weight", minimum=False,
                                                               init_partition=([], excluded)), k_best)]


def _graph_trees(parts, edges, k_best: int) -> list[KinematicTree]:
    """The trees of the k best arborescences, each re-hung by :func:`_shallowest`; an
    arborescence that re-hangs onto an earlier tree is dropped (so fewer than k trees may remain:
    enumerating further could take every tie combination in turn)."""
    trees, seen = [], set()
    for arcs in _arborescences(parts, edges, k_best):
        arcs = _shallowest("base", edges, arcs)
        if frozenset(arcs) not in seen:
            seen.add(frozenset(arcs))
            trees.append(_tree("base", parts, edges, arcs))
    return trees


def _greedy_tree(parts, edges) -> KinematicTree:
    """Ablation: no graph.  Parts are placed least-moving first (by their best BIC against the
    base); each attaches to the already placed part with the best (lowest) BIC."""
    placed, arcs = ["base"], []
    remaining = sorted((p for p in parts if p != "base"),
                       key=lambda p: min(h.bic for h in edges[("base", p)].values()))
    for p in remaining:
        cands = [a for a in placed if (a, p) in edges]
        a = min(cands, key=lambda a: min(h.bic for h in edges[(a, p)].values()))
        arcs.append((a, p))
        placed.append(p)
    return _tree("base", parts, edges, arcs)


def _observed_tracks(tracks: PoseTracks) -> PoseTracks:
    """The tracks observed at MIN_SAMPLES samples or more (fewer relate to nothing: a proposal
    seen at a few steps only); DataError when none is."""
    keep = tracks.observed().sum(axis=1) >= MIN_SAMPLES
    if not keep.any():
        raise DataError(f"no track is observed at {MIN_SAMPLES} samples or more (tracks: {', '.join(tracks.names)}); "
                        "a joint cannot be fitted")
    if keep.all():
        return tracks
    R = tracks.Rs_world_track[keep] if tracks.has_orientation else None
    return PoseTracks(tracks.times, tuple(n for n, k in zip(tracks.names, keep) if k), tracks.positions[keep], R)


def infer_tree(tracks: PoseTracks, method: str = "graph", k_best: int = 3) -> GraphResult:
    """Tracks -> kinematic tree (see module doc).  ``method``: 'graph' (constraint graph +
    arborescence, k_best alternatives) or 'greedy' (ablation, one tree).

    Raises DataError when no track moves relative to the world (nothing to infer).

    BLAS runs on one thread here: the fits' matrices are small (≤ 150 columns), where threaded
    LAPACK only waits on a busy host (one 150×57 SVD took 0.26 s threaded under load; a no-motion
    test went from 31 s to 1.2 s on one thread)."""
    with threadpool_limits(limits=1, user_api="blas"):
        return _infer_tree(tracks, method, k_best)


def _infer_tree(tracks: PoseTracks, method: str, k_best: int) -> GraphResult:
    if method not in ("graph", "greedy"):
        raise ValueError(f"method must be 'graph' or 'greedy', got {method!r}")
    tracks = _observed_tracks(tracks)
    fits = _pair_fits(tracks)
    parts = _merge(tracks, fits)
    if len(parts) == 1:
        sig = max(h["rigid"].noise_sigma for h in fits.values())
        raise DataError(
            f"no motion: every track ({', '.join(tracks.names)}) stays rigid with the world within "
            f"the noise (σ ≈ {sig * 1e3:.3g} mm); there is no joint to infer"
        )
    edges = _part_edges(tracks, fits, parts)
    if method == "greedy":
        return GraphResult(_greedy_tree(parts, edges), (), edges, method)
    trees = _graph_trees(parts, edges, k_best)
    return GraphResult(trees[0], tuple(trees[1:]), edges, method)
