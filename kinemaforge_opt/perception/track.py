"""SE(3) tracks of part proposals through the sequence (trimmed point-to-point ICP on KD-trees
built once per time step, candidates verified by free-space tests).

A proposal is a cluster of moving points at its reference time r.  Its motion ΔT(s) (world
frame, ΔT(r) = I, so the track stays anchored to the reference) is solved outward from r, one
time step at a time, from two guesses: the constant-velocity extrapolation of the neighbouring
solved poses (a door swinging fast between two samples) and the neighbouring pose itself (a part
that stops).  From each, ICP runs — with only the points the images confirm at the guess, when
there are enough (a part's far side would pull it onto what lies behind) — a coarse pass (radius
ICP_COARSE_VOXELS, and a *wide* one starting at WIDE_FACTOR times that: a part that starts,
stops or changes speed between two samples lands outside the coarse basin of either guess) and a
fine pass (radius ICP_FINE_VOXELS) from each coarse pose not within START_SEPARATION_VOXELS of
another (a flat face's voxel grid puts a local minimum every voxel along it); point-to-point, as
point-to-plane would let a flat part slide in its own plane; against the non-static fused points
at s (static surfaces flush with a part, like a cabinet's front frame around a closed door, would
let it slide) — a part at rest where it is
static (a closed drawer's front) finds few correspondences and keeps its guess, which the images
then confirm.  Each result is
*verified* by the free-space tests of :mod:`change` against every depth image at s; it is
acceptable when the points the images can judge are mostly consistent (:func:`acceptable`).  Of
the acceptable results the one with the largest share of points confirmed *and* on an observed
surface (within the fine radius of a fused point) less the share seen through is kept (of
results within FIT_TIE_SIGMAS of it, the first in the guesses' order).  The
free-space test alone cannot rank them: it confirms a point anywhere within τ = 3√2·σ_z(z) of a
reading (several cm at 2 m), ICP matches within 1.5 voxels — a drawer front pulled out 8 cm
between two samples, which the coarse pass from rest leaves short and tilted 44° about its long
axis, is still 97 % confirmed with half its points off any surface (the wide pass puts 99 % of
them on it).  Only when no result is acceptable are principal-axes alignments onto the moving
clusters at s tried (re-detection).  The images accept every alignment of a symmetric part (a
flat door turned half a turn about its normal covers the same surface), so of the acceptable
re-detections the one nearest the constant-velocity prediction is kept (:func:`displacement`).
Where the kept result fits worse than the previous step's beyond that tie, ICP is also tried
from the reference orientation (:meth:`Tracker.unturn`): a turn a flat face hardly shows, once
in a pose, is carried on by both guesses.
With no acceptable candidate the proposal is unobserved at s (NaN: occluded or out of view), and
the next step starts from the last solved pose.

Slips: a fragment sliding along itself (a drawer's side wall) lags its part until no guess
verifies; re-detection may then put it on another face of the part (90° and tens of cm in one
step), which the images accept and from which tracking continues.  A pose is a *jump* when it lies
farther than the wide coarse ICP radius (WIDE_FACTOR·ICP_COARSE_VOXELS voxels, the farthest ICP
reaches from a prediction; RMS over the points) from the constant-velocity prediction of the poses
before it, or farther than the fragment's own RMS radius, or when it turns the fragment's surface
normals by more than FACE_TURN (:func:`jump`, :func:`face_turned`).  The last two are for small
fragments: a few hundred points of a flat face are no wider than ICP's wide reach, so a pass that
lands them on a perpendicular face (a drawer's side-wall strip, hidden in the body once the drawer
is pushed in fast, put on the drawer's front by the wide pass) moves them less than that reach,
and a few degrees of tilt that their geometry cannot resolve, extrapolated along its screw, reach
the turn; a fragment moved farther than its own size no longer covers its predicted place, and
one whose normals turned by more than half a quarter turn faces a neighbouring face's way
(a spin about its normal turns none: its surface cannot witness one).  When the next pose is back
on the prediction from before, the jumped
pose alone is unobserved (an outlier: a flat door flipped half a turn).  A jump is kept when it
goes on along the screw of the increment before it (the same motion, faster or slower: a lid
slammed shut; checked first) or when the next pose continues from it (a part that starts or stops moving between
two samples changes its velocity once); otherwise tracking went on from a wrong pose and the
track ends there in that direction (the jumped pose and the next are unobserved; a jump at the
last solved step alone).  The part's moving points at the lost steps seed a new proposal, which
joins it where it moves with it (:func:`join`).  The first of the two sides tracked from the
reference starts from rest, as nothing yet shows a velocity; its first step is judged by the
increment through the reference that the other side shows, and where it is a slip there (a
drawer still being pulled at the reference, beyond ICP's reach from rest) that side is tracked
again with the constant-velocity guess from that increment.

Growing: a moving part's points near a hinge move less than the free-space test can resolve
(τ ≈ 3√2 σ_z), so the moving cluster misses a strip along the axis; a drawer's inside is never
seen through (it hides in the body), so it is never moving.  After tracking, points of the
reference cloud next to the proposal are added when the track explains them better than the
static hypothesis: over the GROW_STEPS steps where the part moved most, counting only steps where
the moved point is observable (not occluded, in view), (times they land on an observed surface,
within the fine ICP radius) − (times the cameras saw through them) is larger moved along the
track than left in place, and the track puts them in seen-through space at no more than a
quarter of those steps; a tie with no such step also joins (a surface sliding along itself — a
drawer's floor — looks the same under both hypotheses; only seen-through space tells them apart).
The environment planes (floor, back wall) are never grown into: the floor next to a door's foot
also slides along itself under the door's rotation or a drawer's pull, and wherever the voxel is
coarser than the gap between part and floor (a 2.3 cm voxel at 160×120 bridges a door's 2 cm
clearance) the tie would carry the growth over the whole floor.  Growing again where the part
lies farthest from its reference pose finds faces hidden at the reference time (a door's inner
side); of those points, the ones the images at the reference time see through are dropped: there
the part is where its points were seen, so a track wrong at the far step put them there.

Fragments: a piece of a part that slides along itself (a drawer's side wall or floor: a flat
surface moving in its own plane) or hides in the body gives ICP and the free-space test little
grip, so its track lags, stays put or drifts while the part moves, and it would pass as a joint
of its own.  After refinement a proposal is *explained* by another when that one's motion,
applied to its points, puts them nowhere the images contradict: at every step both observe (and
they share COMOVING_SHARE of the proposal's observed steps) at most MAX_VIOLATED_SHARE of the
points are seen through and most of the judged ones are consistent — the bound a tracked pose
must meet (:func:`acceptable`) without the judged-share floor (a drawer shut in the body is not
seen at all).  A step where the other part's pose fails that test for its own points is that
track's failure (a glitch its grown points expose), not a contradiction, as long as such steps
are at most 1 − COMOVING_SHARE of them; they are unobserved after the merge.  One body with one
motion is the simpler explanation when the images cannot tell the two motions apart, so the
proposal's points join that part (:func:`absorb`); of several parts the one whose motion puts
the points on observed surfaces most is taken (confirmed and within the fine ICP radius of a
fused point, less seen through: :meth:`Tracker.fit`, the test that ranks a track's poses).  A
second drawer moving at other times puts the points in the air in front of the body (seen
through) and is no explanation — or inside the body, where nothing contradicts them but no
surface holds them either: so the other motion must also put the points on observed surfaces,
at the steps its track holds, within 1 − COMOVING_SHARE as often as the proposal's own motion
does (:func:`fit_along`).  A surface that a larger proposal holds at a step counts for neither
motion: a fragment whose track was re-detected onto the fronts of drawers at rest while its own
drawer was shut (its true place hidden in the body) lies on surfaces then, but on theirs (a
three-drawer chest, 4 views, 30 frames, seed 24: the fragment became a fourth drawer).  Both
comparisons count the surface, not the free-space test alone: its tolerance grows with the range
to centimetres, so a drawer's floor carried by the drawer above it into the open just over the
ground is "confirmed" by the ground, while carried by its own drawer it is hidden under the one
above (protocol_drawer_0 gave the lower drawer's floor to the upper drawer, part IoU 0.79; on a
three-drawer chest a piece of the lower drawer that no motion puts on a surface as its own does
joined the middle one, which a duplicate track of the middle drawer then explained).

The base is such a body too: a proposal whose points the images never contradict left in place,
and confirm there as often as its own motion does where that motion moves them, is a piece of
the body whose track wandered along its own surface (:func:`static_explains`; a drawer open at a
few steps, its shut place hidden behind its front then, is confirmed only by its motion there).
A proposal that no one motion explains may hold pieces of several (one drawer's side wall
sliding along itself, tracked with a strip of the drawer stacked on it): each point goes to the
motion, of the other proposals' and the base's, that leaves it uncontradicted and under which the
images confirm it most (to the next best when that motion does not explain the piece it takes);
when what no motion explains is less than a part — counting only points the proposal's own track
does not contradict either — the proposal is split among them (:func:`explained_in_pieces`).

Duplicates: a part can be tracked twice, once truly and once by a piece sliding along it (a flat
door), whose grown points the true motion puts partly in seen-through space, so neither explains
the other.  Two rigid parts cannot cover the same surface at every step: a proposal no motion
explains whose points lie on another one's (COMOVING_SHARE of them within the fine ICP radius, at
COMOVING_SHARE of the steps both observe) is the same part (:func:`coincident_with`), and the
motion that puts both point sets on observed surfaces better (:func:`union_fit`) is kept.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from itertools import count

import numpy as np
from scipy.linalg import expm, logm
from scipy.optimize import minimize_scalar
from scipy.spatial import cKDTree

from ..io.sequence import CameraInfo
from ..parallel import thread_map
from ..spatial import rms_radius, transform_points
from .change import MOVING, STATIC, free_space_test, padded_depth
from .clouds import DepthNoise, TimeCloud, downsample
from .segment import CLUSTER_VOXELS, Plane, clusters

# ICP correspondence radii in voxels: coarse (captures the candidate's basin), then fine.
ICP_COARSE_VOXELS = 4.0
ICP_FINE_VOXELS = 1.5
ICP_ITERATIONS = 20
# The coarse pass starts at this multiple of the coarse radius (a part starting to move between
# two samples — a fridge door swinging 20° — lands far outside the coarse basin).
WIDE_FACTOR = 3.0
# Two ICP starts (guesses, coarse poses) nearer than this many voxels are one.  A voxelised flat
# face has a local minimum every voxel along itself (its points sit on the grid): starts a voxel
# apart can end a voxel apart, one of them the face slid along itself (a drawer front carried
# sideways 5 mm a step by the constant-velocity guess, 42 mm over 8 steps).
START_SEPARATION_VOXELS = 0.5
# Of the acceptable ICP results, those whose fit (Tracker.fit) lies within this many binomial
# standard deviations, sqrt(f(1 - f)/N) for N points, of the best one are ties the images cannot
# break, and the first in the guesses' order (constant velocity first) is kept: the motion goes on
# unless the images say otherwise.  A shut drawer's front, flush with its frame and hidden, fits
# about equally a voxel to either side; taking the best of equal fits let it wander ±1 cm at rest.
FIT_TIE_SIGMAS = 2.0
# A track's pose whose fit (Tracker.fit) of a merged point set falls below this share of the
# track's median fit of it has failed at that step (absorb: the fragment's pose may replace it).
FAILED_FIT_SHARE = 0.5
# ICP stops when an iteration moves the points by less than this share of a voxel.
ICP_TOLERANCE_VOXELS = 0.05
# The coarse ICP pass uses every n-th point (it only has to reach the fine basin).
COARSE_SUBSAMPLE = 4
# ICP and verification use at most this many of a proposal's points (a fixed random subset).
MAX_TRACK_POINTS = 1500
# A pose is accepted when at least this share of the proposal's tested points are consistent
# with the images (majority vote) ...
MIN_CONSISTENT_SHARE = 0.5
# ... and at most this share of them lie in space the cameras saw through.
MAX_VIOLATED_SHARE = 0.1
# Smallest moving part tracked [m²]: a 10 cm square (a drawer front, a lid, a door are far
# larger; smaller clusters of moving points are speckle or a part's fringe).
MIN_PART_AREA = 0.01
MIN_PROPOSAL_POINTS = 20
# ICP uses only the points confirmed by the images at the guess when they are at least this share;
# a pose is judged only when the images can judge at least this share of the points.
MIN_VISIBLE_SHARE = 0.2
# A new proposal joins a tracked one when it moves with it at this share of common steps.
COMOVING_SHARE = 0.8
# Growing: rounds of CLUSTER_VOXELS each, and time steps compared per round.
GROW_ROUNDS = 100
GROW_STEPS = 10
# Surface normals from this many nearest points of a fragment.
NORMAL_NEIGHBOURS = 12
# A fragment whose surface turns by more than this from a prediction faces another way: a box's
# faces are a quarter turn apart, and past half that a surface faces nearer a neighbouring face's
# way than its own [rad].
FACE_TURN = np.pi / 4


@dataclass(frozen=True, eq=False)
class Proposal:
    """A candidate rigid part.  name: track name.  ref: index of its reference time step.
    points: (N, 3) world points at the reference time [m].
    Ts_delta: (T, 4, 4) world-frame motion from the reference time (identity at ``ref``, NaN
    where unobserved): p_world(s) = Ts_delta[s] @ p_world(ref)."""

    name: str
    ref: int
    points: np.ndarray
    Ts_delta: np.ndarray

    def points_at(self, s: int) -> np.ndarray | None:
        """(N, 3) the proposal's points moved to time step s, or None if unobserved there."""
        T = self.Ts_delta[s]
        if not np.all(np.isfinite(T)):
            return None
        return transform_points(T, self.points)


def acceptable(consistent: float, violated: float) -> bool:
    """Whether a pose verifies, from the shares of a proposal's points consistent with the images
    and only seen through there: of the points the images can judge (a shut drawer's sides and
    floor are hidden in the body), at least MIN_VISIBLE_SHARE of all, MIN_CONSISTENT_SHARE are
    consistent, and at most MAX_VIOLATED_SHARE of all points are seen through."""
    judged = consistent + violated
    return judged >= MIN_VISIBLE_SHARE and consistent >= MIN_CONSISTENT_SHARE * judged and violated <= MAX_VIOLATED_SHARE


def fit_tie(best: float, n: int) -> float:
    """The margin within which a fit (:meth:`Tracker.fit`) of ``n`` points ties with the ``best``
    one: FIT_TIE_SIGMAS standard deviations of a share of ``n`` points at that value."""
    return FIT_TIE_SIGMAS * float(np.sqrt(max(best * (1.0 - best), 0.0) / n))


def displacement(A: np.ndarray, B: np.ndarray, points: np.ndarray) -> float:
    """RMS distance [m] between (N, 3) ``points`` moved by the (4, 4) motions A and B."""
    d = points @ (A[:3, :3] - B[:3, :3]).T + (A[:3, 3] - B[:3, 3])
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def tracking_subset(points: np.ndarray) -> np.ndarray:
    """At most MAX_TRACK_POINTS of (N, 3) points (a fixed random subset, as tracking uses)."""
    if len(points) <= MAX_TRACK_POINTS:
        return points
    return points[np.random.default_rng(0).choice(len(points), MAX_TRACK_POINTS, replace=False)]


def _predict(poses: list[np.ndarray], ahead: int = 1) -> np.ndarray:
    """Constant-velocity extrapolation ``ahead`` steps past the last of (4, 4) ``poses`` (the
    last pose itself when there is only one)."""
    if len(poses) < 2:
        return poses[-1]
    return np.linalg.matrix_power(poses[-1] @ np.linalg.inv(poses[-2]), ahead) @ poses[-1]


def _unturned(poses: list[np.ndarray], points: np.ndarray) -> np.ndarray:
    """(4, 4) the translation that carries the centroid of (N, 3) reference ``points`` [m] where
    the constant-velocity extrapolation of (4, 4) ``poses`` puts it, without turning them: the
    track's turn so far undone."""
    c = points.mean(axis=0)
    T = np.eye(4)
    T[:3, 3] = transform_points(_predict(poses), c[None])[0] - c
    return T


def surface_normals(points: np.ndarray) -> np.ndarray:
    """(N, 3) unit normals (sign arbitrary) of (N, 3) surface points [m]: the least principal axis
    of each point's NORMAL_NEIGHBOURS nearest points."""
    idx = cKDTree(points).query(points, k=min(NORMAL_NEIGHBOURS, len(points)))[1]
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)
    return np.linalg.svd(nb, full_matrices=False)[2][:, -1, :]


def face_turned(A: np.ndarray, B: np.ndarray, normals: np.ndarray) -> bool:
    """Whether the (4, 4) motions A and B turn a fragment's surface, its (N, 3) reference
    ``normals``, to face ways more than FACE_TURN apart (median over the points): B puts it on
    another face than A.  A turn about a normal (a flat patch spun in its own plane) turns no
    normal: the surface cannot witness it."""
    cos = np.abs(np.einsum("ij,ij->i", normals @ A[:3, :3].T, normals @ B[:3, :3].T))
    return bool(np.median(cos) < np.cos(FACE_TURN))


def _on_screw(before: list[np.ndarray], pose: np.ndarray, points: np.ndarray, normals: np.ndarray,
              tolerance: float) -> bool:
    """Whether (4, 4) ``pose`` lies within ``tolerance`` [m] (:func:`displacement` of (N, 3)
    ``points``), on the same face (:func:`face_turned`, ``normals`` of the points), of the last of
    ``before`` moved further along the screw of the last increment, by any amount up to a
    half-turn either way: the same motion at another speed."""
    if len(before) < 2:
        return False
    xi = np.real(logm(before[-1] @ np.linalg.inv(before[-2])))  # the last increment's twist (4, 4)
    turn = np.linalg.norm(xi[[2, 0, 1], [1, 2, 0]])  # its rotation angle [rad]
    bound = np.pi / turn if turn > 0 else 1.0
    res = minimize_scalar(lambda lam: displacement(pose, expm(lam * xi) @ before[-1], points),
                          bounds=(-bound, bound), method="bounded")
    return bool(res.fun <= tolerance) and not face_turned(pose, expm(res.x * xi) @ before[-1], normals)


def jump(before: list[np.ndarray], pose: np.ndarray, after: np.ndarray | None, points: np.ndarray,
         tolerance: float, normals: np.ndarray | None = None) -> str | None:
    """How the (4, 4) world motion ``pose`` of (N, 3) ``points`` sits between the solved poses
    ``before`` it (the last one or two, in tracking order) and the pose ``after`` it (None at the
    end of the track; module doc).  Two poses are *near* when they lie within ``tolerance`` [m]
    (:func:`displacement`) and on the same face (:func:`face_turned`, on the points' surface
    normals).  None when ``pose`` is near the constant-velocity prediction from ``before`` or continues the
    last increment's screw (:func:`_on_screw`: the same motion, faster or slower); "outlier" when
    ``after`` is back near where the tracker's two motion hypotheses put it
    from ``before`` — constant velocity two steps ahead, or at rest at the last of ``before`` (a
    lid slammed shut stops there) — so ``pose`` alone is wrong (a one-step spike); None when
    ``after`` is near the continuation from ``pose`` (a velocity change, once); else "slip".
    The outlier test comes first: a flat part registered turned over at every other step has a
    constant half-turn "velocity" that every next pose continues.  normals: the points'
    :func:`surface_normals`, if already computed (a track judges every step on the same points)."""
    normals = surface_normals(points) if normals is None else normals

    def near(A: np.ndarray, B: np.ndarray) -> bool:
        return displacement(A, B, points) <= tolerance and not face_turned(A, B, normals)

    if near(pose, _predict(before)) or _on_screw(before, pose, points, normals, tolerance):
        return None
    if after is not None and (near(after, _predict(before, 2)) or near(after, before[-1])):
        return "outlier"
    if after is not None and near(after, _predict([before[-1], pose])):
        return None
    return "slip"


def _principal_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid (3,) and (3, 3) principal axes (columns, right-handed) of (N, 3) points."""
    c = points.mean(axis=0)
    _, _, Vt = np.linalg.svd(points - c, full_matrices=False)
    E = Vt.T
    if np.linalg.det(E) < 0:
        E[:, 2] *= -1
    return c, E


def pca_alignments(source: np.ndarray, target: np.ndarray) -> list[np.ndarray]:
    """The 4 proper rigid transforms (4, 4) mapping the principal frame of (N, 3) ``source``
    onto that of (M, 3) ``target`` (axis signs are ambiguous)."""
    cs, Es = _principal_frame(source)
    ct, Et = _principal_frame(target)
    out = []
    for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        D = np.diag([sx, sy, sx * sy])
        T = np.eye(4)
        T[:3, :3] = Et @ D @ Es.T
        T[:3, 3] = ct - T[:3, :3] @ cs
        out.append(T)
    return out


def symmetries(points: np.ndarray, tolerance: float) -> list[np.ndarray]:
    """The half-turns (4, 4) about the principal axes through the centroid of (N, 3) ``points``
    that map them onto themselves within ``tolerance`` [m] (mean nearest-neighbour distance): a
    flat plate has three, a box with a handle none.  Registered poses differing by one of them
    cover the same surface, so the images cannot tell them apart."""
    c, E = _principal_frame(points)
    tree = cKDTree(points)
    out = []
    for k in range(3):
        S = np.eye(4)
        S[:3, :3] = E @ np.diag(np.where(np.arange(3) == k, 1.0, -1.0)) @ E.T
        S[:3, 3] = c - S[:3, :3] @ c
        if tree.query(points @ S[:3, :3].T + S[:3, 3])[0].mean() <= tolerance:
            out.append(S)
    return out


def kabsch(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(4, 4) rigid transform minimising Σ|T a_i − b_i|² for (N, 3) point pairs."""
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, cb - R @ ca
    return T


def icp(source: np.ndarray, tree: cKDTree, target: np.ndarray, T0: np.ndarray, radii: tuple[float, ...],
        iterations: int = ICP_ITERATIONS, tolerance: float = 0.0) -> np.ndarray:
    """Trimmed point-to-point ICP of (N, 3) ``source`` onto ``target`` (M, 3) with its KD-tree:
    correspondences beyond the current radius [m] are dropped; one pass per radius (coarse to
    fine) from the (4, 4) initial world motion ``T0``; stops a pass when the points move by less
    than ``tolerance`` [m]."""
    T = np.array(T0, dtype=float)
    for r in radii:
        for _ in range(iterations):
            moved = transform_points(T, source)
            d, idx = tree.query(moved, distance_upper_bound=r)
            ok = d < r
            if ok.sum() < 6:
                break
            dT = kabsch(moved[ok], target[idx[ok]])
            T = dT @ T
            step = np.linalg.norm(moved @ (dT[:3, :3] - np.eye(3)).T + dT[:3, 3], axis=1).max()
            if step < tolerance:
                break
    return T


class Tracker:
    """Tracks proposals through fused time clouds (see module doc).

    clouds: the T time steps.  status: per step, (M_t,) STATIC/UNKNOWN/MOVING of its points.
    cameras, noise: for the free-space verification.  voxel: the cloud's voxel edge [m].
    background: the environment planes (:func:`segment.environment_planes`); growing never
    takes a point within ``plane_band`` [m] of one (None: the fine ICP radius)."""

    def __init__(self, clouds: list[TimeCloud], status: list[np.ndarray], cameras: dict[str, CameraInfo],
                 noise: DepthNoise, voxel: float, background: tuple[Plane, ...] = (), plane_band: float | None = None):
        self.clouds, self.status, self.cameras, self.noise, self.voxel = clouds, status, cameras, noise, voxel
        self.background = background
        self.plane_band = ICP_FINE_VOXELS * voxel if plane_band is None else plane_band
        self.set_targets([c.points[s != STATIC] for c, s in zip(clouds, status)])
        self._windows: dict[int, list[np.ndarray]] = {}
        self._moving_clusters: dict[int, list[np.ndarray]] = {}
        self.min_points = max(MIN_PROPOSAL_POINTS, int(MIN_PART_AREA / voxel**2))

    def set_targets(self, targets: list[np.ndarray]) -> None:
        """ICP's target points per step, (M_s, 3) [m], with their KD-trees (None for an empty step)."""
        self.targets = targets
        self.trees = thread_map(lambda t: cKDTree(t) if len(t) else None, targets)

    def full_tree(self, s: int) -> cKDTree:
        """KD-tree of every fused point at step s (the cloud's own, built on first use)."""
        return self.clouds[s].tree

    def windows(self, s: int) -> list[np.ndarray]:
        if s not in self._windows:
            self._windows[s] = [padded_depth(v.depth) for v in self.clouds[s].views]
        return self._windows[s]

    def moving_clusters(self, s: int) -> list[np.ndarray]:
        if s not in self._moving_clusters:
            moving = self.clouds[s].points[self.status[s] == MOVING]
            self._moving_clusters[s] = [moving[i] for i in clusters(moving, self.voxel, self.min_points)]
        return self._moving_clusters[s]

    def verdicts(self, points: np.ndarray, s: int) -> tuple[np.ndarray, np.ndarray]:
        """(N,) int each: 1 where some image at step s confirms the world point (consistent), and
        1 where an image saw through it and none confirmed it (violated)."""
        cons = np.zeros(len(points), dtype=bool)
        viol = np.zeros(len(points), dtype=bool)
        for view, window in zip(self.clouds[s].views, self.windows(s)):
            cam = view.camera or self.cameras[view.frame.camera]
            v = free_space_test(points, cam, view.frame.T_world_camera, window, self.noise)
            cons |= v > 0
            viol |= v < 0
        return cons.astype(int), (viol & ~cons).astype(int)

    def verify(self, points: np.ndarray, s: int) -> tuple[float, float]:
        """(consistent share, violated share) of (N, 3) world points against the images at step
        s: the share of points some image confirms, and of points only seen through."""
        cons, viol = self.verdicts(points, s)
        return float(np.mean(cons)), float(np.mean(viol))

    def _coarse(self, points: np.ndarray, s: int, T0: np.ndarray, wide: bool = False) -> np.ndarray:
        """Coarse ICP pass of every COARSE_SUBSAMPLE-th point from ``T0`` (wide: starting at
        WIDE_FACTOR times the coarse radius)."""
        radii = (ICP_COARSE_VOXELS * self.voxel,)
        if wide:
            radii = (WIDE_FACTOR * radii[0],) + radii
        tol = ICP_TOLERANCE_VOXELS * self.voxel
        return icp(points[::COARSE_SUBSAMPLE], self.trees[s], self.targets[s], T0, radii, tolerance=tol)

    def _fine(self, points: np.ndarray, s: int, T0: np.ndarray) -> np.ndarray:
        """Fine ICP pass of all the points from ``T0``."""
        tol = ICP_TOLERANCE_VOXELS * self.voxel
        return icp(points, self.trees[s], self.targets[s], T0, (ICP_FINE_VOXELS * self.voxel,), tolerance=tol)

    def _confirmed(self, points: np.ndarray, s: int, T0: np.ndarray) -> np.ndarray:
        """The (N', 3) reference points the images at step s confirm at the guess ``T0``, or all
        of them when fewer than MIN_VISIBLE_SHARE are: ICP's source (a door's inner face, turned
        away near closed, would otherwise pull onto the body behind it)."""
        seen = self.verdicts(points @ T0[:3, :3].T + T0[:3, 3], s)[0] > 0
        return points[seen] if seen.sum() >= MIN_VISIBLE_SHARE * len(points) else points

    def fit(self, points: np.ndarray, s: int, verdicts: tuple[np.ndarray, np.ndarray] | None = None,
            held: np.ndarray | None = None) -> float:
        """Share of (N, 3) world points [m] that the images at step s confirm and that lie on an
        observed surface (within the fine ICP radius of a fused point), less the share only seen
        through (module doc: the free-space test alone does not rank poses).  ``verdicts``: the
        points' :meth:`verdicts` at s, if already made.  ``held``: (N,) bool, points on a surface
        another part holds, which count as on none (:func:`explained_by`)."""
        cons, viol = self.verdicts(points, s) if verdicts is None else verdicts
        on = self.full_tree(s).query(points, distance_upper_bound=ICP_FINE_VOXELS * self.voxel, workers=-1)[0] < np.inf
        if held is not None:
            on &= ~held
        return float(np.mean(cons.astype(bool) & on) - np.mean(viol))

    def solve_step(self, points: np.ndarray, s: int,
                   guesses: list[np.ndarray]) -> tuple[np.ndarray | None, float | None]:
        """Best verified (4, 4) world motion of (N, 3) reference points to step s and its
        :meth:`fit`, or (None, None) (module doc): narrow and wide coarse ICP from each distinct
        guess, the fine pass from each distinct coarse pose, and of the acceptable results the
        best :meth:`fit` (from the verdicts the step made); with none, :meth:`redetect`."""
        if self.trees[s] is None or len(self.targets[s]) < 3:
            return None, None
        apart = START_SEPARATION_VOXELS * self.voxel
        starts: list[tuple[np.ndarray, np.ndarray]] = []  # (coarse pose, ICP source)
        for k, T0 in enumerate(guesses):
            if any(displacement(T0, G, points) <= apart for G in guesses[:k]):
                continue  # one start (a part at rest: constant velocity is no motion)
            source = self._confirmed(points, s, T0)
            for wide in (False, True):
                T = self._coarse(source, s, T0, wide)
                if all(displacement(T, U, points) > apart for U, _ in starts):
                    starts.append((T, source))
        found = []  # (pose, moved points, their verdicts) of the acceptable results
        for T0, source in starts:
            T = self._fine(source, s, T0)
            moved = transform_points(T, points)
            cons, viol = self.verdicts(moved, s)
            if acceptable(float(np.mean(cons)), float(np.mean(viol))):
                found.append((T, moved, (cons, viol)))
        if not found:
            T = self.redetect(points, s, guesses[0])
            return (None, None) if T is None else (T, self.fit(transform_points(T, points), s))
        # of the fits within FIT_TIE_SIGMAS of the best, the first in the guesses' order
        fits = np.array([self.fit(f[1], s, f[2]) for f in found])
        best = float(fits.max())
        return next((f[0], float(x)) for f, x in zip(found, fits) if x >= best - fit_tie(best, len(points)))

    def unturn(self, points: np.ndarray, s: int, T: np.ndarray, fit: float, solved: list[np.ndarray],
               last_fit: float | None) -> tuple[np.ndarray, float]:
        """The (4, 4) pose of (N, 3) reference ``points`` at step s and its :meth:`fit`, from
        :meth:`solve_step`'s ``T`` with its ``fit``, after the (4, 4) poses ``solved``.  Where
        that fit falls below ``last_fit`` (the previous step's) beyond the tie, the track may have
        left the part's basin: a turn the surface hardly sees (a drawer front spun about its
        normal), once in a pose, is carried on by both guesses and grows step by step
        (cabinet_multi_1's drawer: 1 → 9.5° while it slides, where the true pose fits better
        beyond the tie).  Then ICP from the reference orientation (:func:`_unturned`) is tried,
        and kept where it fits better beyond the tie."""
        if last_fit is None or fit >= last_fit - fit_tie(last_fit, len(points)):
            return T, fit
        U, fit_u = self.solve_step(points, s, [_unturned(solved, points)])
        return (U, fit_u) if U is not None and fit_u > fit + fit_tie(fit_u, len(points)) else (T, fit)

    def redetect(self, points: np.ndarray, s: int, prediction: np.ndarray) -> np.ndarray | None:
        """Principal-axes alignments of (N, 3) reference points onto the moving clusters at step
        s, refined by ICP: of the acceptable ones the (4, 4) world motion nearest the
        ``prediction`` (module doc), or None."""
        best, best_score = None, -np.inf
        for T0 in (T for cluster in self.moving_clusters(s) for T in pca_alignments(points, cluster)):
            source = self._confirmed(points, s, T0)
            T = self._fine(source, s, self._coarse(source, s, T0))
            score = -displacement(T, prediction, points)
            if score > best_score and acceptable(*self.verify(transform_points(T, points), s)):
                best, best_score = T, score
        return best

    def track(self, name: str, ref: int, points: np.ndarray) -> Proposal:
        """Track (N, 3) world points of step ``ref`` through every step, then grow the
        proposal (module doc)."""
        n = len(self.clouds)
        sample = tracking_subset(points)
        Ts = np.full((n, 4, 4), np.nan)
        Ts[ref] = np.eye(4)
        # a pose farther than ICP reaches from a prediction is a jump, and so is one farther than
        # the fragment's own size: it no longer covers its place at the prediction (module doc)
        radius = rms_radius(sample)
        reach = min(WIDE_FACTOR * ICP_COARSE_VOXELS * self.voxel, radius)
        normals = surface_normals(sample)
        # a symmetric part registers turned over as well as not (a flat lid at rest): of a pose
        # and its symmetric twins, the one nearest a guess (constant velocity, or at rest) is kept
        twins = [np.eye(4)] + symmetries(sample, ICP_FINE_VOXELS * self.voxel)
        sides: list[tuple[list[np.ndarray], list[int]]] = []
        for direction in (1, -1):
            # one trajectory runs through the reference: the first pose of the side tracked
            # before gives the increment before this side's first step (the first side's first
            # step is judged once the second side is tracked)
            lead = [sides[0][0][1]] if sides and len(sides[0][0]) > 1 else []
            sides.append(self._track_side(sample, ref, direction, lead, not sides, False, Ts, reach, normals, twins))
        (solved, steps), other = sides[0], sides[1][0]
        if len(solved) >= 2:  # the first side's first step, after the increment on the other side
            kind = jump(other[1:2][::-1] + [np.eye(4)], solved[1], solved[2] if len(solved) > 2 else None, sample, reach,
                        normals)
            if kind == "outlier":
                Ts[steps[1]] = np.nan
            elif kind == "slip":
                # the part moved on through the reference at the velocity the other side shows
                # (a drawer still being pulled), which the first side, tracked from rest, missed:
                # tracked again from that velocity
                Ts[ref + 1:] = np.nan
                if len(other) > 1:
                    self._track_side(sample, ref, 1, other[1:2], False, True, Ts, reach, normals, twins)
        grown = self.grow(ref, points, Ts)
        return Proposal(name, ref, self.grow_far(ref, grown, Ts), Ts)

    def _track_side(self, sample: np.ndarray, ref: int, direction: int, lead: list[np.ndarray], first: bool,
                    carry: bool, Ts: np.ndarray, reach: float, normals: np.ndarray,
                    twins: list[np.ndarray]) -> tuple[list[np.ndarray], list[int]]:
        """Track (N, 3) ``sample`` from step ``ref`` one step at a time in ``direction`` (±1),
        writing the (4, 4) poses into ``Ts`` (T, 4, 4) and unobserving jumps (module doc); returns
        the solved poses and their steps.  lead: the other side's first pose, if tracked (its
        increment through the reference judges this side's first step, unless ``first``; with
        ``carry`` it also gives the first step a constant-velocity guess).  reach: the jump
        tolerance [m]; normals: the sample's surface normals; twins: its symmetries."""
        n = len(self.clouds)
        solved, steps = [np.eye(4)], [ref]
        s = ref + direction
        last_fit = None
        while 0 <= s < n:
            # constant velocity first, then the last pose
            history = lead + solved if carry else solved
            guesses = [_predict(history), solved[-1]] if len(history) >= 2 else [solved[-1]]
            T, fit = self.solve_step(sample, s, guesses)
            if T is not None and len(solved) >= 2:
                T, last_fit = self.unturn(sample, s, T, fit, solved, last_fit)
            s += direction
            if T is None:
                continue
            T = min((T @ S for S in twins), key=lambda X: min(displacement(X, g, sample) for g in guesses))
            Ts[s - direction] = T
            solved.append(T)
            steps.append(s - direction)
            if len(solved) < 3 or (len(solved) == 3 and first):
                continue
            kind = jump((lead + solved)[-4:-2], solved[-2], T, sample, reach, normals)
            if kind == "outlier":  # the jumped pose alone
                Ts[steps[-2]] = np.nan
                del solved[-2], steps[-2]
            elif kind == "slip":  # the jumped pose and the one built on it; the side ends here
                Ts[steps[-2]] = Ts[steps[-1]] = np.nan
                del solved[-2:], steps[-2:]
                break
        if len(solved) >= (3 if first else 2) and \
                jump((lead + solved)[-3:-1], solved[-1], None, sample, reach, normals) == "slip":
            Ts[steps[-1]] = np.nan  # a jump at the last solved step, on no screw of the track
        return solved, steps

    def grow_far(self, ref: int, points: np.ndarray, Ts: np.ndarray) -> np.ndarray:
        """(N', 3) ``points`` [m, at ``ref``] plus what :meth:`grow` adds at the observed step
        where the part lies farthest from its reference pose, carried back to ``ref``: a face
        hidden at the reference time (a door's inner side while it is shut) shows there.  Of
        those, the points the images at ``ref`` see through are left out: at its reference step
        the part is where its points were seen, so they came from a wrong pose at the far step."""
        obs = [s for s in range(len(Ts)) if s != ref and np.all(np.isfinite(Ts[s])) and len(self.clouds[s].points)]
        if not obs:
            return points
        reach = np.linalg.norm(points.max(axis=0) - points.min(axis=0))
        disp = [np.linalg.norm(Ts[s][:3, :3] - np.eye(3)) * reach + np.linalg.norm(Ts[s][:3, 3]) for s in obs]
        far = obs[int(np.argmax(disp))]
        if max(disp) < ICP_COARSE_VOXELS * self.voxel:  # the part never left its reference pose
            return points
        back = np.linalg.inv(Ts[far])
        Ts_far = np.array([T @ back if np.all(np.isfinite(T)) else T for T in Ts])
        moved = transform_points(Ts[far], points)
        extra = transform_points(back, self.grow(far, moved, Ts_far)[len(moved):])
        # at the reference step the part is where its points were seen: a grown point the
        # cameras saw through there is not on it (the track was wrong at the far step)
        return np.concatenate([points, extra[self.verdicts(extra, ref)[1] == 0]])

    def grow(self, ref: int, points: np.ndarray, Ts: np.ndarray) -> np.ndarray:
        """(N', 3) ``points`` plus the reference cloud's points next to them that the track
        ``Ts`` (T, 4, 4) explains better than the static hypothesis (module doc)."""
        obs = [s for s in range(len(Ts)) if s != ref and np.all(np.isfinite(Ts[s])) and len(self.clouds[s].points)]
        if not obs:
            return points
        # the steps where the part moved most from its reference pose discriminate best
        reach = np.linalg.norm(points.max(axis=0) - points.min(axis=0))
        disp = [np.linalg.norm(Ts[s][:3, :3] - np.eye(3)) * reach + np.linalg.norm(Ts[s][:3, 3]) for s in obs]
        steps = [obs[k] for k in np.argsort(disp)[::-1][:GROW_STEPS]]
        cloud = self.clouds[ref].points
        # the cloud's own copies of the points (exact at the reference step, within half a voxel
        # when the points were carried there by a track) are in the part already
        tested = cKDTree(points).query(cloud, distance_upper_bound=0.5 * self.voxel, workers=-1)[0] < np.inf
        fine = ICP_FINE_VOXELS * self.voxel
        reach_r = CLUSTER_VOXELS * self.voxel
        for plane in self.background:  # a floor slides along itself under a part's motion: never a tie to break
            tested |= np.abs(plane.distance(cloud)) <= self.plane_band
        part = frontier = points
        for _ in range(GROW_ROUNDS):
            # every point near the part before the last round was tested in it: only the points
            # the last round added can bring new candidates
            near = cKDTree(frontier).query(cloud, distance_upper_bound=reach_r, workers=-1)[0] < np.inf
            cand = np.flatnonzero(near & ~tested)
            if cand.size == 0:
                break
            tested[cand] = True
            x = cloud[cand]

            def scores(s: int) -> np.ndarray:
                """(3, n): hits minus violations under the track and the static hypothesis, and
                violations under the track, of the candidates at step s."""
                T = Ts[s]
                m = len(x)
                # both hypotheses' points in one batch: moved by the track, then left in place
                both = np.concatenate([transform_points(T, x), x])
                cons, viol = self.verdicts(both, s)
                on = (self.full_tree(s).query(both, distance_upper_bound=fine)[0] < np.inf).astype(int)
                cons_p, viol_p = cons[:m], viol[:m]
                seen = cons_p | viol_p  # compare only where the moved point can be observed
                return np.stack([seen * (on[:m] - viol_p), seen * (on[m:] - viol[m:]), viol_p])

            part_score, static_score, part_viol = np.sum(thread_map(scores, steps), axis=0)
            take = ((part_score > static_score) & (4 * part_viol <= len(steps))) | ((part_score == static_score) & (part_viol == 0))
            if not take.any():
                break
            frontier = x[take]
            part = np.concatenate([part, frontier])
        return part


def refine(tracker: Tracker, proposals: list[Proposal]) -> list[Proposal]:
    """One more fine ICP pass per proposal and step, from its tracked pose, with the grown points
    as source and the targets extended by every point on a tracked part: a part's strip along a
    hinge is static by the free-space test at steps where the part rests, and without it the
    trimmed ICP slides the part off its true pose toward the part's non-static remainder."""
    fine = ICP_FINE_VOXELS * tracker.voxel

    def target(s: int) -> np.ndarray:
        pts = tracker.clouds[s].points
        keep = tracker.status[s] != STATIC
        for p in proposals:
            moved = p.points_at(s)
            if moved is not None:
                keep |= cKDTree(moved).query(pts, distance_upper_bound=fine)[0] < np.inf
        return pts[keep]

    tracker.set_targets(thread_map(target, range(len(tracker.clouds))))
    rng = np.random.default_rng(0)
    out = []
    for p in proposals:
        sample = p.points if len(p.points) <= MAX_TRACK_POINTS else p.points[rng.choice(len(p.points), MAX_TRACK_POINTS, replace=False)]

        def refined(s: int) -> np.ndarray:
            T0 = p.Ts_delta[s]
            if s == p.ref or not np.all(np.isfinite(T0)) or tracker.trees[s] is None:
                return T0
            T = icp(sample, tracker.trees[s], tracker.targets[s], T0, (fine,), tolerance=ICP_TOLERANCE_VOXELS * tracker.voxel)
            cons, viol = tracker.verify(transform_points(T, sample), s)
            return T if acceptable(cons, viol) else T0

        Ts = np.array(thread_map(refined, range(len(p.Ts_delta))))
        out.append(Proposal(p.name, p.ref, p.points, Ts))
    return out


def seed_order(tracker: Tracker) -> list[int]:
    """Time steps in the order proposals are seeded: most separate moving clusters first (parts
    next to each other — a fridge's two doors — are one cluster while both are closed or both
    open, and apart when only one is open), then most moving points.  Clusters are counted on
    the moving points at twice the voxel edge (a cheap preview of :func:`clusters`)."""
    def key(s: int) -> tuple[int, int]:
        moving = tracker.clouds[s].points[tracker.status[s] == MOVING]
        coarse = downsample(moving, 2 * tracker.voxel)
        n = len(clusters(coarse, 2 * tracker.voxel, max(MIN_PROPOSAL_POINTS, tracker.min_points // 4))) if len(coarse) else 0
        return -n, -len(moving)

    keys = thread_map(key, range(len(tracker.clouds)))
    return sorted(range(len(keys)), key=lambda r: keys[r])


def propose_and_track(tracker: Tracker) -> list[Proposal]:
    """Proposals from the moving points of every time step (order: :func:`seed_order`): moving
    points not yet explained by a tracked proposal (within the coarse ICP radius of its moved
    points: closer leftovers are the part's own fringe, seen through a small track error) are
    clustered into new proposals of at least ``tracker.min_points`` points, and each is tracked
    through the sequence; a proposal seeded on two touching parts is dropped once better tracks
    cover it, and the tracks joined into it return as proposals of their own
    (:func:`without_unions`); then every track is refined (:func:`refine`)."""
    order = seed_order(tracker)
    proposals: list[Proposal] = []
    seeds: dict[str, tuple[int, np.ndarray]] = {}  # a proposal's reference step and seed points
    joined: dict[str, list[tuple[Proposal, np.ndarray]]] = {}  # the tracks joined into each, with their seeds
    radius = ICP_COARSE_VOXELS * tracker.voxel
    for r in order:
        moving = tracker.clouds[r].points[tracker.status[r] == MOVING]
        if len(moving) < tracker.min_points:
            continue
        explained = np.zeros(len(moving), dtype=bool)
        for p in proposals:
            moved = p.points_at(r)
            if moved is not None:
                explained |= cKDTree(moved).query(moving, distance_upper_bound=radius, workers=-1)[0] < np.inf
        rest = moving[~explained]
        if len(rest) < tracker.min_points:
            continue
        for idx in clusters(rest, tracker.voxel, tracker.min_points):
            new = tracker.track(f"p{len(proposals)}", int(r), rest[idx])
            k, a = _comoving(new, proposals, ICP_COARSE_VOXELS * tracker.voxel)
            if k is None:
                proposals.append(new)
                seeds[new.name] = (int(r), rest[idx])
            else:  # a disconnected piece of a tracked part (a drawer's floor behind its front), or
                # the part itself where its track was cut (a slip)
                joined.setdefault(proposals[k].name, []).append((new, rest[idx]))
                proposals[k] = join(proposals[k], new, a)
    proposals = without_unions(tracker, proposals, seeds, joined)
    return merge_fragments(tracker, refine(tracker, proposals)) if proposals else proposals


def observed_steps(p: Proposal) -> int:
    """Number of steps at which ``p``'s motion is known."""
    return int(np.isfinite(p.Ts_delta[:, 0, 0]).sum())


def without_unions(tracker: Tracker, proposals: list[Proposal], seeds: dict[str, tuple[int, np.ndarray]],
                   joined: dict[str, list[tuple[Proposal, np.ndarray]]] | None = None) -> list[Proposal]:
    """The proposals (in the order they were seeded) less each whose seed later ones cover.

    Two parts that touch while both move (a drawer pulled out above a door still swinging back)
    are one cluster of moving points at such a step, and a seed taken there follows neither: its
    track is lost wherever their motions part, or it follows one part and drags the other's points
    along.  Where its track fails or drags, the parts' own moving points are left unexplained and
    seed proposals of their own, later.  When proposals seeded after it and tracked at no fewer
    steps cover COMOVING_SHARE of its seed points (within the fine ICP radius of their moved
    points at the seed's step), its parts are tracked already and it is dropped.  ``seeds``:
    proposal name -> (reference step, (N, 3) seed points).

    A track seeded at another step and joined into a dropped union (``joined``: proposal name ->
    [(joined track, its (M, 3) seed points at its reference step)]; :func:`join`, where the
    union's track went on to follow that part) is a part tracked from its own seed: it returns as
    a proposal of its own, under a new name, unless the kept proposals cover its seed in the same
    way (protocol_drawer_1@s8's first drawer, tracked at every step from its own seed at step 4,
    was joined into a union seeded at step 16 on the two other drawers, and went with it).  A
    piece seeded at the union's own step is a leftover of the parts its seed spans, which the
    kept proposals track: it does not return (a drawer's side wall sliding along it would come
    back as a joint of its own, docs/NOTES.md)."""
    surfaces = _Surfaces(tracker.voxel, subset=False)

    def covered(seed: np.ndarray, ref: int, steps: int, by: list[Proposal]) -> bool:
        return bool(surfaces.held_by([q for q in by if observed_steps(q) >= steps])(seed, ref).mean() >= COMOVING_SHARE)

    out, dropped = list(proposals), []
    for k, p in enumerate(proposals):
        ref, seed = seeds[p.name]
        if covered(seed, ref, observed_steps(p), proposals[k + 1:]):
            out = [x for x in out if x is not p]
            dropped.append(p)
    names = {p.name for p in proposals}
    fresh = (f"p{i}" for i in count() if f"p{i}" not in names)
    for p in dropped:
        for piece, seed in (joined or {}).get(p.name, []):
            if piece.ref != p.ref and not covered(seed, piece.ref, observed_steps(piece), out):
                out.append(replace(piece, name=next(fresh)))
    return out


def _common_anchor(p: Proposal, q: Proposal) -> tuple[np.ndarray, int | None]:
    """(steps both observe, the one nearest ``p``'s reference or None when there is none)."""
    common = np.flatnonzero(np.isfinite(p.Ts_delta[:, 0, 0]) & np.isfinite(q.Ts_delta[:, 0, 0]))
    return common, (int(common[np.argmin(np.abs(common - p.ref))]) if common.size else None)


def carried(by: Proposal, anchor: int, s: int, points: np.ndarray) -> np.ndarray:
    """(N, 3) world points at step ``anchor`` carried by ``by``'s motion to step ``s``."""
    return transform_points(by.Ts_delta[s] @ np.linalg.inv(by.Ts_delta[anchor]), points)


def support(tracker: Tracker, points: np.ndarray, by: Proposal, anchor: int,
            steps: np.ndarray) -> tuple[np.ndarray, list[int]] | None:
    """((len(steps),) per step, how well the images take (N, 3) world points at step ``anchor``
    carried by ``by``'s motion to it (:meth:`Tracker.fit`: the share confirmed on an observed
    surface less the share seen through); the steps where ``by``'s track failed), or None when
    the images contradict the carried points (over MAX_VIOLATED_SHARE seen through, or fewer than
    MIN_CONSISTENT_SHARE of the judged ones consistent) at a step where ``by``'s pose is
    acceptable for its own points, or at more than 1 − COMOVING_SHARE of the steps (module doc,
    fragments: a contradiction at a step where ``by``'s own pose fails the images is its track's
    failure, not the fragment's, when it is one of a few)."""
    fits, failed = [], []
    own = tracking_subset(by.points)
    for s in steps:
        x = carried(by, anchor, s, points)
        verdicts = tracker.verdicts(x, int(s))
        cons, viol = float(np.mean(verdicts[0])), float(np.mean(verdicts[1]))
        if viol > MAX_VIOLATED_SHARE or cons < MIN_CONSISTENT_SHARE * (cons + viol):
            T = by.Ts_delta[s]
            if acceptable(*tracker.verify(transform_points(T, own), int(s))):
                return None
            failed.append(int(s))
            if len(failed) > (1.0 - COMOVING_SHARE) * len(steps):
                return None
        fits.append(tracker.fit(x, int(s), verdicts))
    return np.array(fits), failed


def explained_by(tracker: Tracker, frag: Proposal, proposals: list[Proposal]) -> tuple[int | None, int | None, list[int]]:
    """(index of the proposal whose motion explains ``frag``'s points best — puts them on observed
    surfaces most at the steps its track holds — anchor step, the steps where that proposal's
    track failed: :func:`support`) or (None, None, []) (module doc, fragments)."""
    x = tracking_subset(frag.points)
    observed = observed_steps(frag)
    surfaces = _Surfaces(tracker.voxel)
    larger = [q for q in proposals if len(q.points) > len(frag.points)]  # they hold their surfaces (below)
    best, best_fit, best_anchor, failed = None, -np.inf, None, []
    for k, p in enumerate(proposals):
        if p is frag:
            continue
        common, a = _common_anchor(frag, p)
        if common.size < max(COMOVING_SHARE * observed, 1):
            continue
        xa = transform_points(frag.Ts_delta[a], x)
        sup = support(tracker, xa, p, a, common)
        if sup is None:
            continue
        fits, fails = sup
        held = ~np.isin(common, fails)  # at most 1 - COMOVING_SHARE of them fail (support)
        fit = float(np.mean(fits[held]))
        if fit <= best_fit:
            continue
        # the images must not tell the two motions apart: at the steps the other track holds,
        # its motion puts the points on observed surfaces nearly as often as the fragment's own (a
        # drawer's points carried by the drawer above it hide in the body, uncontradicted, but
        # on no surface).  A surface a larger proposal holds there witnesses neither motion: a
        # fragment re-detected onto the fronts of drawers at rest sits on surfaces, but on theirs
        # (the larger holds it, as merging goes smallest first: a part's surface is not lost to a
        # fragment lying on it)
        if (fit_along(tracker, xa, p, a, common[held], surfaces.held_by([q for q in larger if q is not p]))
                < fit_along(tracker, xa, frag, a, common[held], surfaces.held_by(larger)) - (1.0 - COMOVING_SHARE)):
            continue
        best, best_fit, failed, best_anchor = k, fit, fails, a
    return best, best_anchor, failed


class _Surfaces:
    """Whether points lie on proposals' surfaces at a time step: within the fine ICP radius of a
    proposal's moved points (``subset``: of its tracking subset); ``voxel``: the cloud's voxel
    edge [m].  A rigid motion keeps distances, so the points are carried back to the proposal's
    reference pose instead, against one KD-tree of its points per proposal, built on first use
    (the proposal is kept with it, so its id is not reused by another while the cache lives)."""

    def __init__(self, voxel: float, subset: bool = True):
        self.radius = ICP_FINE_VOXELS * voxel
        self.subset = subset
        self._trees: dict[int, tuple[Proposal, cKDTree]] = {}

    def on(self, points: np.ndarray, p: Proposal, s: int) -> np.ndarray:
        """(N,) bool: which of (N, 3) world points lie on ``p``'s surface at step s (none where
        ``p`` is unobserved)."""
        T = p.Ts_delta[s]
        if not np.all(np.isfinite(T)):
            return np.zeros(len(points), dtype=bool)
        if id(p) not in self._trees:
            self._trees[id(p)] = (p, cKDTree(tracking_subset(p.points) if self.subset else p.points))
        back = transform_points(np.linalg.inv(T), points)
        return self._trees[id(p)][1].query(back, distance_upper_bound=self.radius, workers=-1)[0] < np.inf

    def held_by(self, proposals: list[Proposal]) -> Callable[[np.ndarray, int], np.ndarray]:
        """A function of (N, 3) world points and a step s: (N,) bool, on a surface one of
        ``proposals`` holds at s."""
        def held(points: np.ndarray, s: int) -> np.ndarray:
            on = np.zeros(len(points), dtype=bool)
            for p in proposals:
                on |= self.on(points, p, s)
            return on
        return held


def fit_along(tracker: Tracker, points: np.ndarray, by: Proposal, anchor: int, steps: np.ndarray,
              held: Callable[[np.ndarray, int], np.ndarray] | None = None) -> float:
    """Mean over ``steps`` of :meth:`Tracker.fit` of (N, 3) world points at step ``anchor``
    carried by ``by``'s motion (0 without steps); ``held``: of carried points and a step, (N,)
    bool, those on a surface another part holds there (counted as on none)."""
    if len(steps) == 0:
        return 0.0
    fits = []
    for s in map(int, steps):
        x = carried(by, anchor, s, points)
        fits.append(tracker.fit(x, s, held=None if held is None else held(x, s)))
    return float(np.mean(fits))


def confirmed(tracker: Tracker, points: np.ndarray, by: Proposal, anchor: int, steps: np.ndarray) -> float:
    """Mean over ``steps`` of the share of (N, 3) world points at step ``anchor``, carried by
    ``by``'s motion, that the images confirm minus the share they see through (0 without steps)."""
    if len(steps) == 0:
        return 0.0
    cons, viol = verdict_counts(tracker, points, by, anchor, steps)
    return float(np.mean(cons - viol)) / len(steps)


def static_explains(tracker: Tracker, frag: Proposal) -> bool:
    """Whether the base (the identity) explains ``frag``'s points (module doc, fragments): at no
    step do the images contradict them left in place (over MAX_VIOLATED_SHARE seen through, or
    fewer than MIN_CONSISTENT_SHARE of the judged ones consistent), and at the steps where
    ``frag``'s own motion moves them from their place (RMS beyond the fine ICP radius) they are
    confirmed in place within 1 − COMOVING_SHARE as often as that motion confirms them
    (:func:`confirmed`; a drawer open at two steps of ten, its shut place hidden behind its
    front then, is confirmed only by its motion there)."""
    x = tracking_subset(frag.points)
    in_place = [tracker.verify(x, s) for s in range(len(frag.Ts_delta))]
    if any(viol > MAX_VIOLATED_SHARE or cons < MIN_CONSISTENT_SHARE * (cons + viol) for cons, viol in in_place):
        return False
    moved = [s for s in np.flatnonzero(np.isfinite(frag.Ts_delta[:, 0, 0]))
             if displacement(frag.Ts_delta[s], np.eye(4), x) > ICP_FINE_VOXELS * tracker.voxel]
    if not moved:  # a track that never left the identity
        return True
    still = float(np.mean([in_place[s][0] - in_place[s][1] for s in moved]))
    return still >= confirmed(tracker, x, frag, frag.ref, np.array(moved)) - (1.0 - COMOVING_SHARE)


def absorb(tracker: Tracker, p: Proposal, frag: Proposal, anchor: int, failed: list[int] = ()) -> Proposal:
    """``p`` with ``frag``'s points, carried to ``p``'s reference through the ``anchor`` step both
    observe; ``p``'s motion kept (the fragment's own track is the one not trusted) except at the
    ``failed`` steps, where it put the fragment's points where the images contradict them: there
    ``p``'s track failed, and ``p`` is unobserved (not at its reference, where its motion is the
    identity, nor at the anchor, where the fragment's own pose is what was judged).

    The fragment's motion (continued from ``p``'s pose at the anchor) stands in for ``p``'s, judged
    on the merged points, at two kinds of step:
    - where ``p``'s track never reached, if the images accept it there (:func:`acceptable`): a
      door tracked from its inner face, seen only once it is open, lost the first three steps of
      protocol_microwave_1@s1 while its outer face, seeded near shut, held them;
    - where ``p``'s pose failed — its fit (:meth:`Tracker.fit`) below FAILED_FIT_SHARE of its median
      fit over the track — if the fragment's fits better beyond FIT_TIE_SIGMAS (as
      :meth:`Tracker.solve_step` ranks poses): protocol_moving_cabinet's shut door, tracked open
      0.2–0.5 rad at four steps while the other door swung past, fitted −0.16–0.14 there against
      a median 0.9, and 0.26–0.65 with its fragment's pose.  A step where ``p``'s own fit is
      typical keeps its pose, however well another fits: a drawer's fragment put 58 cm off fitted
      its merged points better on another surface."""
    Ts = p.Ts_delta.copy()
    gap = np.flatnonzero(~np.isfinite(Ts[:, 0, 0]) & np.isfinite(frag.Ts_delta[:, 0, 0]))
    Ts[[s for s in failed if s not in (p.ref, anchor)]] = np.nan
    points = _points_with(p, frag, anchor)
    sample = tracking_subset(points)
    for s in gap:
        T = _continued(frag, p, anchor, s)
        if acceptable(*tracker.verify(transform_points(T, sample), int(s))):
            Ts[s] = T
    both = [int(s) for s in np.flatnonzero(np.isfinite(Ts[:, 0, 0]) & np.isfinite(frag.Ts_delta[:, 0, 0]))
            if s not in (p.ref, anchor) and s not in gap]
    own = {s: tracker.fit(transform_points(Ts[s], sample), s) for s in both}
    typical = float(np.median(list(own.values()))) if own else 0.0
    for s in both:
        if own[s] >= FAILED_FIT_SHARE * typical:
            continue
        T = _continued(frag, p, anchor, s)
        other = tracker.fit(transform_points(T, sample), s)
        if other > own[s] + fit_tie(other, len(sample)):
            Ts[s] = T
    return Proposal(p.name, p.ref, points, Ts)


def verdict_counts(tracker: Tracker, points: np.ndarray, by: Proposal, anchor: int,
                   steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N,) confirmed, (N,) seen through): at how many of ``steps`` the images confirm each of
    (N, 3) world points at step ``anchor``, carried by ``by``'s motion, and only see through it."""
    cons, viol = np.zeros(len(points), dtype=int), np.zeros(len(points), dtype=int)
    for s in steps:
        c, v = tracker.verdicts(carried(by, anchor, s, points), int(s))
        cons += c
        viol += v
    return cons, viol


def without_contradicted(tracker: Tracker, q: Proposal, by: Proposal, anchor: int) -> Proposal:
    """``q`` less the points that ``by``'s motion, carried from the ``anchor`` step, puts where the
    images saw through them at more than 1 − COMOVING_SHARE of the steps both observe (what a
    duplicate's wrong track had grown into: no part of the part whose motion is kept)."""
    common = _common_anchor(q, by)[0]
    seen_through = verdict_counts(tracker, q.points_at(anchor), by, anchor, common)[1]
    keep = seen_through <= (1.0 - COMOVING_SHARE) * common.size
    return Proposal(q.name, q.ref, q.points[keep], q.Ts_delta)


def coincident_with(tracker: Tracker, q: Proposal, proposals: list[Proposal]) -> tuple[int | None, int | None]:
    """(index of the proposal whose moved points ``q``'s cover, anchor step) or (None, None)
    (module doc, duplicates): at COMOVING_SHARE of the steps both observe — themselves
    COMOVING_SHARE of ``q``'s observed steps — at least COMOVING_SHARE of ``q``'s points lie
    within the fine ICP radius of the other's; of several, the one covered at most steps."""
    x = tracking_subset(q.points)
    surfaces = _Surfaces(tracker.voxel, subset=False)
    best, best_share, anchor = None, 0.0, None
    for k, p in enumerate(proposals):
        if p is q:
            continue
        common, a = _common_anchor(q, p)
        if common.size < max(COMOVING_SHARE * observed_steps(q), 2):
            continue
        covered = sum(surfaces.on(transform_points(q.Ts_delta[s], x), p, int(s)).mean() >= COMOVING_SHARE
                      for s in common)
        share = covered / common.size
        if share >= COMOVING_SHARE and share > best_share:
            best, best_share, anchor = k, share, a
    return best, anchor


def union_fit(tracker: Tracker, p: Proposal, q: Proposal, by: Proposal, anchor: int) -> float:
    """Mean :meth:`Tracker.fit`, over the steps ``p`` and ``q`` both observe, of both proposals'
    points (their tracking subsets, taken at the ``anchor`` step) carried from there by ``by``'s
    motion (one of the two)."""
    x = np.concatenate([transform_points(r.Ts_delta[anchor], tracking_subset(r.points)) for r in (p, q)])
    return fit_along(tracker, x, by, anchor, _common_anchor(p, q)[0])


def merge_fragments(tracker: Tracker, proposals: list[Proposal]) -> list[Proposal]:
    """The proposals with every fragment absorbed into the part whose motion explains it
    (:func:`explained_by`), smallest proposal first (a part's large front is explained by no
    fragment's lagging track); a proposal that no motion explains but whose points cover another
    one's at its steps (:func:`coincident_with`) is the same part tracked twice: the two become
    one, with the motion that puts both point sets on observed surfaces better
    (:func:`union_fit`): the covering proposal as it is when its motion wins, else the covered
    one with the covering one's points less those its motion puts in seen-through space
    (:func:`without_contradicted`)."""
    out = list(proposals)
    for name in [p.name for p in sorted(proposals, key=lambda p: len(p.points))]:
        frag = next((p for p in out if p.name == name), None)
        if frag is None:  # merged into a smaller duplicate whose motion was kept
            continue
        k, a, failed = explained_by(tracker, frag, out)
        if k is not None:
            out[k] = absorb(tracker, out[k], frag, a, failed)
            out = [p for p in out if p is not frag]
            continue
        k, a = coincident_with(tracker, frag, out)
        if k is not None:
            other = out[k]
            # kept: the covering proposal (the covered one's points lie on it, but for at most
            # 1 - COMOVING_SHARE that nothing ties to the part); or, when the covered one's motion
            # wins, that one with both point sets, less what its motion contradicts
            if union_fit(tracker, other, frag, frag, a) > union_fit(tracker, other, frag, other, a):
                out[k] = absorb(tracker, frag, without_contradicted(tracker, other, frag, a), a)
            out = [p for p in out if p is not frag]
        else:
            pieces = explained_in_pieces(tracker, frag, out)
            for k, piece, a, failed in pieces or []:
                if k is not None:  # a base piece is dropped: its points are the base's
                    out[k] = absorb(tracker, out[k], piece, a, failed)
            if pieces is not None:
                out = [p for p in out if p is not frag]
    return out


def explained_in_pieces(tracker: Tracker, frag: Proposal,
                        proposals: list[Proposal]) -> list[tuple[int | None, Proposal, int, list[int]]] | None:
    """The pieces of ``frag`` that other motions explain, when together they leave fewer than
    ``tracker.min_points`` of the points its own track explains (module doc, fragments: a piece
    of one drawer that slides along itself, tracked with a strip of the drawer stacked on it),
    else None.  Each piece is (index of the proposal whose motion explains it, or None for the
    base; the piece, with ``frag``'s track; anchor step; that proposal's failed steps:
    :func:`explained_by`, :func:`static_explains`).

    A point (of at most MAX_TRACK_POINTS, each of the others taking its nearest one's lot) is
    *uncontradicted* by a motion that carries it into seen-through space at no more
    than 1 − COMOVING_SHARE of the steps (those :func:`support` judges; every step for the base),
    and goes to the uncontradicted motion under which the images confirm it most (mean of
    confirmed − seen through per step; of equals — a flat wall sliding along itself is confirmed
    by any motion along it, a point hidden under every motion by none — the motion nearest
    ``frag``'s own track, which lags or wanders but follows its part more than any other).  When
    a motion does not explain the piece it takes, or that piece is smaller than a part, those
    points go to their next best motion, until every piece is explained."""
    sample = tracking_subset(frag.points)  # judged on the sample; each point takes its nearest's lot
    nearest = cKDTree(sample).query(frag.points, workers=-1)[1]
    candidates = []  # (index or None, anchor, (n,) uncontradicted, (n,) mean support, distance)
    base = Proposal("", frag.ref, frag.points, np.tile(np.eye(4), (len(frag.Ts_delta), 1, 1)))
    for k, p in [*enumerate(proposals), (None, base)]:
        common, a = _common_anchor(frag, p)
        if p is frag or common.size < max(COMOVING_SHARE * observed_steps(frag), 1):
            continue
        x = transform_points(frag.Ts_delta[a], sample)
        # how far this motion leads the points from where their own (distrusted) track does
        away = np.mean([displacement(p.Ts_delta[s] @ np.linalg.inv(p.Ts_delta[a]),
                                     frag.Ts_delta[s] @ np.linalg.inv(frag.Ts_delta[a]), x) for s in common])
        if k is None:  # the base is judged at every step: it is never unobserved
            common = np.arange(len(frag.Ts_delta))
        cons, viol = verdict_counts(tracker, x, p, a, common)
        candidates.append((k, a, viol <= (1.0 - COMOVING_SHARE) * common.size, (cons - viol) / common.size, away))
    candidates.sort(key=lambda c: c[4])
    score = np.array([np.where(c[2], c[3], -np.inf) for c in candidates])
    # what no motion explains, its own track included, is no evidence of a part of its own
    observed = np.flatnonzero(np.isfinite(frag.Ts_delta[:, 0, 0]))
    seen_through = verdict_counts(tracker, sample, frag, frag.ref, observed)[1]
    own = (seen_through <= (1.0 - COMOVING_SHARE) * observed.size)[nearest]
    verdict = {}  # (candidate, its sample points) -> (explained, failed steps)
    while True:  # a point whose motion's piece is refused (or smaller than a part) tries its next best
        best, left = np.argmax(score, axis=0), np.isneginf(score.max(axis=0))
        if np.sum(left[nearest] & own) >= tracker.min_points:
            return None
        pieces, refused = [], None
        for i, (k, a, *_) in enumerate(candidates):
            mine = (best == i) & ~left
            take = mine[nearest]
            if not mine.any():
                continue
            key = (i, mine.tobytes())
            piece = Proposal(frag.name, frag.ref, frag.points[take], frag.Ts_delta)
            if key not in verdict:
                if take.sum() < tracker.min_points:
                    verdict[key] = (False, [])
                elif k is None:
                    verdict[key] = (static_explains(tracker, piece), [])
                else:
                    j, _, failed = explained_by(tracker, piece, [proposals[k], piece])
                    verdict[key] = (j is not None, failed)
            explained, failed = verdict[key]
            if not explained:
                refused = (i, mine)
                break
            pieces.append((k, piece, a, failed))
        if refused is None:
            break
        score[refused[0], refused[1]] = -np.inf
    return pieces or None


def join(p: Proposal, new: Proposal, anchor: int) -> Proposal:
    """``p`` with ``new``'s points (carried to ``p``'s reference through the ``anchor`` step both
    observe) and, at the steps ``p`` lacks and ``new`` observes, ``new``'s motion continued from
    ``p``'s pose at the anchor."""
    Ts = p.Ts_delta.copy()
    gap = ~np.isfinite(Ts[:, 0, 0]) & np.isfinite(new.Ts_delta[:, 0, 0])
    Ts[gap] = _continued(new, p, anchor, gap)
    return Proposal(p.name, p.ref, _points_with(p, new, anchor), Ts)


def _continued(other: Proposal, p: Proposal, anchor: int, steps) -> np.ndarray:
    """``other``'s motion at ``steps`` (a step index or an array of them: (4, 4) or (K, 4, 4))
    continued from ``p``'s pose at the ``anchor`` step both observe, as a motion from ``p``'s
    reference."""
    return other.Ts_delta[steps] @ np.linalg.inv(other.Ts_delta[anchor]) @ p.Ts_delta[anchor]


def _points_with(p: Proposal, other: Proposal, anchor: int) -> np.ndarray:
    """``p``'s points and ``other``'s, carried from ``other``'s reference to ``p``'s through the
    ``anchor`` step both observe (world points at ``p``'s reference, (N + M, 3))."""
    T = np.linalg.inv(p.Ts_delta[anchor]) @ other.Ts_delta[anchor]  # other's reference -> p's
    return np.concatenate([p.points, transform_points(T, other.points)])


def _comoving(new: Proposal, proposals: list[Proposal], tolerance: float) -> tuple[int | None, int | None]:
    """(index of the tracked proposal that ``new`` moves rigidly with, anchor step), or (None,
    None): ``new``'s points, carried from the anchor — the step both observe nearest ``new``'s
    reference — by that proposal's motion instead of their own, land within ``tolerance`` [m]
    (RMS) of their own track at COMOVING_SHARE of the steps both observe (a new track may fail at
    a few steps where its piece is hidden).  The anchor alone is no evidence (both tracks put the
    points where they are there): a proposal observed only at the new one's reference step would
    swallow any part seeded at that step, and with it that part's track."""
    best, best_share, anchor = None, 0.0, None
    for k, p in enumerate(proposals):
        common, a = _common_anchor(new, p)
        if a is None or common.size < 2:
            continue
        x = new.points @ new.Ts_delta[a][:3, :3].T + new.Ts_delta[a][:3, 3]  # new's points at a
        agree = 0
        for s in common:
            Dn = new.Ts_delta[s] @ np.linalg.inv(new.Ts_delta[a])  # each track's motion from a to s
            Dp = p.Ts_delta[s] @ np.linalg.inv(p.Ts_delta[a])
            agree += displacement(Dn, Dp, x) <= tolerance
        share = agree / common.size
        if share >= COMOVING_SHARE and share > best_share:
            best, best_share, anchor = k, share, a
    return best, anchor
