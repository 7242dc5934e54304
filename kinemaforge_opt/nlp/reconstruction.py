"""Joint inference on RGB-D data: the screw-axis NLP over a kinematic tree.

Decision variables (names as in the :class:`~kinemaforge_opt.nlp.problem.Problem`):

- per movable joint j: ``axis:<j>`` (3, joint frame, on the unit sphere: constraint
  ``unit_axis:<j>``), ``origin:<j>`` (3, parent link frame, a point on the axis; revolute and
  helical only — a prismatic joint's line position is not observable — with the gauge constraint
  ``gauge:<j>`` that keeps it from sliding along the axis), ``pitch:<j>`` (helical only);
- joint states: ``q`` (n, T) at the T observed time steps, or with the dynamics ``x`` = (q, v)
  (2n, G) on a grid that subdivides every frame interval into steps of at most ``substep_s``;
- with the dynamics and recorded forces: ``damping:<j>``, ``coulomb:<j>`` (≥ 0) and
  ``inertia_ratio:<link>`` (the link's mesh inertia scaled by this ratio: the density is a guess,
  the forces make the scale identifiable).

Named costs (each reported at the optimum; any can be switched off):

- ``vis``: Σ pseudo-Huber point-to-plane residuals of every moving part's observed points against
  its surface model moved by the bridge's ``link_poses`` (:mod:`.visual`), divided by δ²; inside
  one solve its IRLS quadratic (a (13, 13) moment matrix per part and step), the weights and the
  correspondences refreshed between solves;
- ``dyn``: compressed Hermite–Simpson defects of (q̇ = v, v̇ = ABA(q, v, τ_applied + τ_passive, θ))
  (the same transcription as :mod:`.joint_space`), each row divided by h × its typical rate
  and by ``dyn_sigma``, under a pseudo-Huber loss (robust to unmodelled contacts);
  τ_applied = Jᵀ W maps the recorded force (wrenches.csv: force f at world point p, on the link it
  grips) to joint forces through the joint screws of the current model; only between the first
  and the last step at which every moving part is seen (:func:`seen_free`) and outside the stop
  spans (:func:`~kinemaforge_opt.stops.stop_spans`);
- ``energy`` (the seed's Eq. 5): per window, ΔE − ∫ (τ_applied + τ_passive)·v dt relative to the
  energy scale of the motion; ``soft`` (a cost, divided by ``energy_sigma``) or ``hard`` (the
  constraint |·| ≤ ``energy_tolerance``).

The objective is the sum of the terms divided by the number of visual residuals.  Every
per-step function is ``casadi.Function.map``-ped over the time steps, so the graph stays small and
``jit`` is an option (it works, but compiling each stage costs more than it saves here); the
dynamics maps evaluate on :func:`~kinemaforge_opt.parallel.workers` threads.  The
dense stage's Lagrangian Hessian is assembled from per-block derivatives
(:mod:`.structured_hessian`, the exact Hessian, build independent of the number of intervals):
on protocol_cabinet_0 (2 doors, 77 grid points) the stage's build went from ~7 s CPU (casadi's
Hessian of the expanded graph, still ``hessian="flat"``) to ~0.5 s; L-BFGS did not converge
there.  Coarse-to-fine (:func:`refine_screws`): closed-form init → ``vis`` warm-up
on the frame grid with correspondences refreshed between solves → the same warm-up with pairs
beyond 3 robust standard deviations of its settled residuals left out (:func:`residual_gate`) →
full objective on the dense grid → the same with every axis near plumb or level (or square to
its parent's faces) made so, kept when the BIC prefers it (:mod:`.gravity_aligned`).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.interpolate import CubicSpline

from ..errors import DataError, KinemaforgeError, ModelError
from ..io.sequence import Wrenches
from ..model import ArticulatedModel, Inertial, JointLimits
from ..parallel import thread_map, workers
from ..physics.effects import EFFECTS
from ..spatial import rms_radius
from ..symbolic import build_dynamics
from .inertial_scales import MIN_COM_SCALE, com_scale, has_axis_ratio, link_axis, scaled_inertial, scaled_parameters
from .problem import Problem, Result, SolverCache
from ..stops import stop_limits, stop_spans
from .gravity_aligned import (AlignmentTest, alignment, alignment_test, constraint_rows, project, square_direction,
                              step_shares)
from .structured_hessian import DenseTerms, lagrangian_hessian
from .visual import Correspondences, SurfaceModel, correspond, surface_model, fixed_subsample, pseudo_huber, robust_value, z_vector

ENERGY_MODES = ("soft", "hard", "off")
# Prior spread of log(inertia ratio): the robust mesh inertia (perception/mass.py) came within
# 0.9-4.5x of the true joint-space inertia on eight synthetic bench cases (160x120, 4 views), so a
# factor 2 is one standard deviation.  At camera rate (2-10 Hz) the data alone trade inertia for
# damping and initial speed; the prior keeps the scale where the geometry puts it unless the
# recorded forces say otherwise.
INERTIA_PRIOR_SIGMA = float(np.log(2.0))
# Prior spread of log(mass ratio / inertia ratio) of a rotating link: how far the mesh's first
# moment per inertia about the axis (its shape, not its density) is off.  On five laptop lids
# (full size laptop_0/1 seeds 0/1, quick laptop_1) the mesh's m·c / I_a came within 1-10 % of the
# truth's (RMS 5 %), so 10 % is one standard deviation.  Without it, a revolute joint's mass ratio
# drifted where the data barely see it: protocol_refrigerator_0's door to 0.10 (traded for its
# axis tilt: 0.36 -> 0.58° axis error), the seed-1 laptop lids to I_a 3x the truth's.
SHAPE_PRIOR_SIGMA = float(np.log(1.1))
# The visual term Σ ρ(r)/δ² is ≈ ½ χ² of the point residuals: an unconverged stage whose iterate
# raises it by less than ½ (Δχ² = 1, one standard deviation of one parameter) fits the points as
# well as before and is kept (protocol_drawer_0 quick: the full stage stopped at 200 iterations
# with its normalised visual term 6e-5 of itself higher and was dropped, mesh masses 4.6 / 12.4 kg
# kept for true 5.7 / 6.1 kg; kept: 8.3 / 6.2 kg, 1-s drift 0.062 -> 0.004 m).
VIS_SLACK = 0.5
# Pairs beyond this many robust standard deviations of the warm-up's residuals are outliers (the
# 3σ rule; :func:`residual_gate`).
PLANE_GATE_SIGMAS = 3.0
# Observed points per part and step the measurement of the joint values uses (ScrewResult.measured_q;
# the fit uses ScrewOptions.points_per_part).  Over Table 1's 28 joints the RMS error of the measured
# q against the truth averaged 4.4 (mrad or mm) with 200 points, 3.5 with 1000, 3.2 with 3000 and
# with every point (up to 15 000); 3000 cost 0.6 s on protocol_cabinet_0, every point 1.4 s.
MEASURE_POINTS_PER_PART = 3000
# Points per step that estimate a part's far-side thickness (a median over all steps).
THICKNESS_SAMPLE = 500
# A part's far-side slab thickness is fitted in a visual stage when its far-side pairs weigh at
# least this much (summed IRLS weights: about as many pairs within the robust width).
MIN_FAR_SIDE_WEIGHT = 10.0
HESSIANS = ("exact", "gauss_newton", "flat", "lbfgs")
# Bounds of the mass and inertia ratios (the mesh's mass properties are a guess, not that bad).
RATIO_BOUNDS = (MIN_COM_SCALE, 50.0)


@dataclass(frozen=True)
class ScrewOptions:
    """Switches and settings of the screw-axis NLP.

    vis, dyn: use the visual / dynamics term.  energy: "soft", "hard" or "off".
    coarse_to_fine: vis warm-up before the full objective (else one solve from the closed form with
    correspondences found once).  points_per_part: observed points per part and time step (fixed
    seeded subsample).  rounds: vis warm-up solves (correspondences refreshed before each).
    substep_s: longest collocation step [s].  dyn_sigma: relative size of a dynamics defect that
    counts as one standard deviation (the prior, loosest scale).  dyn_row_sigma: (q̇ = v rows,
    v̇ rows) scales replacing dyn_sigma, or None; set by ``reweight_dyn``: after the full stage,
    the scales are re-estimated from that fit's defects (:func:`process_noise_scales`) and the
    full objective solved again from its solution (not with the hard energy constraint: on the
    pushed-door test that solve ran into max_iter).  energy_sigma (soft) / energy_tolerance
    (hard): relative energy-balance residual per window.  energy_weight: multiplies the soft energy term.
    energy_window_s: energy window length [s].  fit_dynamics: free damping, Coulomb friction and
    an inertia ratio per moving link when forces are recorded.  max_iter: IPOPT iterations per
    solve.  jit: compile the mapped functions (needs a C compiler).  hessian: of the dense stage's
    Lagrangian: "exact" (assembled from per-block derivatives, :mod:`.structured_hessian`),
    "gauss_newton" (the same blocks, no curvature of the dynamics residuals: converges slowly here),
    "flat" (casadi's exact Hessian of the whole expanded graph: seconds to build) or "lbfgs".
    expand: expand the dense stage to SX (see :func:`_solver_options`).  refuse: after the warm-up,
    rebuild every surface model from all steps' observed points moved back to q = 0 by the
    NLP's motion, and warm up again on it.  inertia_prior_sigma: standard deviation of
    log(inertia ratio) around 1 (the mesh's inertia), a Gaussian prior added to the objective
    (``inertia_prior``; 0 or inf = no prior).  stop_impacts: leave the dynamics and energy terms
    out from the frame before a joint runs into the end of its observed range at speed (an impact
    on a stop, which the NLP does not model) until it has left that end (:func:`~kinemaforge_opt.stops.stop_spans`).
    gravity_aligned: after the last dense stage, refit with every axis near plumb or level (or
    square to its parent's faces, ``ScrewData.faces``) made so, kept if the BIC prefers it
    (:mod:`.gravity_aligned`).  fit_thickness: the visual stages on the frame grid fit each part's
    far-side slab thickness with its motion (else it is the median depth of the far-side points
    under the current motion, :func:`far_side_thickness`, re-estimated with each refresh of the
    pairs); the dense stages hold the last fitted value.
    """

    vis: bool = True
    dyn: bool = True
    energy: str = "soft"
    coarse_to_fine: bool = True
    points_per_part: int = 200
    rounds: int = 6
    substep_s: float = 0.1
    dyn_sigma: float = 0.1
    dyn_row_sigma: tuple[float, float] | None = None
    reweight_dyn: bool = True
    energy_sigma: float = 0.05
    energy_tolerance: float = 0.02
    energy_weight: float = 1.0
    energy_window_s: float = 1.0
    fit_dynamics: bool = True
    max_iter: int = 200
    jit: bool = False
    hessian: str = "exact"
    refuse: bool = False
    expand: bool = True
    inertia_prior_sigma: float = INERTIA_PRIOR_SIGMA
    stop_impacts: bool = True
    gravity_aligned: bool = True
    fit_thickness: bool = True

    def __post_init__(self):
        if self.energy not in ENERGY_MODES:
            raise KinemaforgeError(f"energy must be one of {ENERGY_MODES}, got {self.energy!r}")
        if not (self.vis or self.dyn):
            raise KinemaforgeError("the screw NLP needs at least one of the terms 'vis' and 'dyn'")
        if self.hessian not in HESSIANS:
            raise KinemaforgeError(f"hessian must be one of {HESSIANS}, got {self.hessian!r}")
        if self.points_per_part < 3 or self.rounds < 1 or self.substep_s <= 0:
            raise KinemaforgeError("points_per_part >= 3, rounds >= 1 and substep_s > 0 are required")


@dataclass(frozen=True, eq=False)
class ScrewData:
    """What the NLP fits.

    model: the closed-form model; the root link is the world and every link frame is placed at the
    zero configuration (q = 0).  times: (T,) observed time steps [s].  q_init: (T, n) closed-form
    joint values, ``model.joint_names`` order.  observed: moving link -> per time step the (M, 3)
    world points [m] seen on it (None or empty when not seen).  surfaces: moving link -> its
    :class:`SurfaceModel` at q = 0.  delta: pseudo-Huber width [m] (point noise level).
    gate: correspondence rejection distance [m].  wrenches: recorded forces or None.
    pushed_link: (len(wrenches.t),) name of the link the force acts on per sample ("" = none).
    sightlines: like ``observed``, per point the unit vector towards the cameras that saw it, or
    None (no far-side test, :func:`~.visual.correspond`).  faces: link -> (2, 3) the horizontal
    directions [world, unit] its side faces look along at q = 0
    (:func:`~.gravity_aligned.face_directions`), for the joints it carries ("square" axes), or None.
    """

    model: ArticulatedModel
    times: np.ndarray
    q_init: np.ndarray
    observed: dict[str, list[np.ndarray | None]]
    surfaces: dict[str, SurfaceModel]
    delta: float
    gate: float
    wrenches: Wrenches | None = None
    pushed_link: np.ndarray | None = None
    sightlines: dict[str, list[np.ndarray | None]] | None = None
    faces: dict[str, np.ndarray] | None = None

    def __post_init__(self):
        n, T = self.model.nq, self.times.size
        if self.q_init.shape != (T, n):
            raise DataError(f"q_init has shape {self.q_init.shape}, expected (T, n) = ({T}, {n})")
        for link, obs in self.observed.items():
            if link not in self.surfaces:
                raise DataError(f"part {link!r} has observed points but no surface model")
            if len(obs) != T:
                raise DataError(f"part {link!r}: {len(obs)} observation steps, expected {T}")
            if self.sightlines is not None:
                seen = self.sightlines.get(link, [])
                if len(seen) != T or any(_rows(o) != _rows(v) for o, v in zip(obs, seen)):
                    raise DataError(f"part {link!r}: its sightlines do not match its observed points step by step")
        if self.wrenches is not None and (self.pushed_link is None or len(self.pushed_link) != self.wrenches.t.size):
            raise DataError("wrenches need pushed_link: one link name per wrench sample")

    def sightlines_of(self, link: str) -> list[np.ndarray | None]:
        """``link``'s sightlines per step (all None when the data carry none)."""
        return self.sightlines[link] if self.sightlines is not None else [None] * len(self.observed[link])


def _rows(a: np.ndarray | None) -> int:
    return 0 if a is None else len(a)


@dataclass
class ScrewState:
    """Current estimate.  axes (n, 3) joint frame (unit), origins (n, 3) parent frame [m], pitches (n,)
    [m/rad]; t (G,) grid [s], q (G, n), v (G, n) or None; damping, coulomb (n,); mass_ratio
    {link: ratio of mass and first moment to the mesh's}; inertia_ratio {link: ratio of the inertia
    about the link's joint axis to the mesh's} (:mod:`.inertial_scales`); thickness {link: the slab
    thickness [m] of its far side (:func:`~.visual.correspond`) as last fitted; empty until a
    visual stage fits it}."""

    axes: np.ndarray
    origins: np.ndarray
    pitches: np.ndarray
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray | None
    damping: np.ndarray
    coulomb: np.ndarray
    inertia_ratio: dict[str, float] = field(default_factory=dict)
    mass_ratio: dict[str, float] = field(default_factory=dict)
    thickness: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class Normalisation:
    """What a dense problem's terms are scaled by, taken from the state it is built around.
    v_s, a_s: (n,) per-joint RMS speed and acceleration of the start's motion [rad/s or m/s, /s²]
    (defect rows and the friction variables are in these units).  dyn_mask: (G − 1,) 1 where an
    interval's defect counts (0 in a stop span or outside the seen span, :func:`seen_free`), or
    None without dynamics.  e_scale: the energy residual's scale [J], or None without the energy
    term.  A continuation (a stopped solve resumed from its last iterate) is built with the
    stopped problem's own, so that it resumes the same problem: rebuilt from the iterate, the
    scales and the stop spans moved with it (a gravity-aligned door's objective went from 0.027
    to 0.97 between the two solves)."""

    v_s: np.ndarray
    a_s: np.ndarray
    dyn_mask: np.ndarray | None = None
    e_scale: float | None = None


@dataclass(frozen=True, eq=False)
class ScrewProblem:
    """A built (not solved) screw NLP: ``problem`` plus what reading its solution needs.
    frame_cols: (T,) grid column of each observed time step.  dynamics: the bridge functions.
    n_vis: number of weighted visual residuals (the objective's normaliser).  hess_lag: the
    assembled Lagrangian Hessian (or None).  prior: the ratio prior as a Function of the parameter
    variables (every variable but the states, declaration order), or None.  normalisation: the
    scales of its terms (:class:`Normalisation`).  reuse_key: for a problem on the frame grid, whose
    pairs, weights and starting point are parameters, bounds and guesses, the key under which a
    :class:`~.problem.SolverCache` kept for the same :class:`ScrewData` may reuse its solver; None
    when the terms hold the data as constants."""

    problem: Problem
    data: ScrewData
    options: ScrewOptions
    state: ScrewState
    frame_cols: np.ndarray
    dynamics: object
    free: tuple[str, ...]
    use_dyn: bool
    n_vis: int
    hess_lag: ca.Function | None = None
    prior: ca.Function | None = None
    defects: ca.Function | None = None
    normalisation: Normalisation | None = None
    reuse_key: tuple | None = None


@dataclass(frozen=True, eq=False)
class ScrewResult:
    """The refined estimate.  model: the model with refined axes, origins, pitches, limits (observed
    range of q, or where a joint rests against a stop: :func:`~kinemaforge_opt.stops.stop_limits`), and damping / Coulomb
    friction / scaled inertia where identified.  q: (T, n) at the observed steps.  terms: name -> value of each term at the end, None for a term switched off:
    ``vis`` the robust sum Σ ρ_δ(r)/δ² over the final correspondences, ``dyn`` the robust sum of
    normalised defects, ``energy`` the soft penalty (× energy_weight) or, for the hard constraint,
    Σ (relative residual)² over the windows, ``unseen_hold`` (when a part is unseen somewhere,
    :func:`unseen_hold`) ½ Σ w (q − q_init)² at those frames.  iterations: IPOPT iterations over all stages.
    success: every stage converged (or its continuation did).  stages: per stage (name,
    iterations, success, seconds).
    fitted: the dynamic parameters the NLP fitted ("damping:<joint>", "coulomb:<joint>",
    "mass_ratio:<link>", "inertia_ratio:<link>").  identified: those of them the data determine
    (status "identified").  When a damping or Coulomb coefficient fitted away from 0 is not
    determined by the data, every such coefficient not identified is held at the nominal (input
    model's) value and the rest re-fitted (stage ``full_refit``; notes say so);
    a ratio the data do not determine stays near its prior (1, the mesh's).  notes: why a term was
    off (or cut short).  identifiability: per fitted dynamic parameter whether the data determine
    it (:func:`dynamic_identifiability`); empty when none was fitted.  measured_q: (T, n) the joint
    values the images alone give at the observed steps under the final joints (stages
    ``measure_<r>``: the visual term on the frame grid over up to :data:`MEASURE_POINTS_PER_PART`
    observed points a step with every axis, origin and pitch held, pairs refreshed until they
    settle), free of the dynamics and energy terms that shaped ``q``: the motion the verifier
    checks the model against; None without a visual term or when no measuring solve converged.
    measure_stages: those solves' records (as ``stages``; not part of the fit, nor of
    ``success``).  alignment_tests: one record per gravity-aligned hypothesis tested, in order
    (:mod:`~.gravity_aligned`): ``joints`` {joint: "plumb" | "level" | "square"}, ``converged``,
    ``kept``, and for a converged refit the test's ``dchi2``, ``bound``, ``z``, ``critical``
    (:class:`~.gravity_aligned.AlignmentTest`; z and critical None when the steps could not
    measure the comparison's noise)."""

    model: ArticulatedModel
    q: np.ndarray
    state: ScrewState
    terms: dict[str, float | None]
    iterations: int
    success: bool
    stages: tuple[dict, ...]
    time_s: float
    identified: tuple[str, ...]
    notes: tuple[str, ...]
    identifiability: dict = field(default_factory=dict)
    fitted: tuple[str, ...] = ()
    measured_q: np.ndarray | None = None
    measure_stages: tuple[dict, ...] = ()
    alignment_tests: tuple[dict, ...] = ()


# --- helpers ---------------------------------------------------------------------------------


def _grid(times: np.ndarray, substep_s: float, breaks: np.ndarray = np.zeros(0)) -> tuple[np.ndarray, np.ndarray]:
    """Grid (G,) subdividing every frame interval into steps <= substep_s, and the frame columns.

    breaks: times [s] the grid must also hold (where the applied force starts, ends or moves to
    another link, :func:`force_breaks`); a break nearer than ``substep_s`` / 20 to a frame or to an
    earlier break is left out."""
    min_step = substep_s / 20
    pieces, cols = [], []
    for a, b in zip(times[:-1], times[1:]):
        cols.append(sum(p.size for p in pieces))
        knots = [a]
        for t in np.sort(breaks[(breaks > a + min_step) & (breaks < b - min_step)]):
            if t - knots[-1] >= min_step:
                knots.append(float(t))
        knots.append(b)
        for lo, hi in zip(knots[:-1], knots[1:]):
            m = max(1, int(np.ceil((hi - lo) / substep_s - 1e-9)))
            pieces.append(np.linspace(lo, hi, m + 1)[:-1])
    cols.append(sum(p.size for p in pieces))
    return np.concatenate(pieces + [times[-1:]]), np.asarray(cols)


def force_breaks(data: ScrewData) -> np.ndarray:
    """Times [s] where the recorded force, as the NLP reads it (:func:`_wrench_at`), kinks or
    jumps: both samples around each change of pushed link (a contact's force ramps between
    them).  Hermite-Simpson integrates a force linear over an interval exactly; across an end of a
    push it loses part of the push's last impulse."""
    if data.wrenches is None:
        return np.zeros(0)
    change = np.flatnonzero(data.pushed_link[1:] != data.pushed_link[:-1])
    return np.unique(np.asarray(data.wrenches.t, dtype=float)[np.r_[change, change + 1]])


def initial_state(data: ScrewData) -> ScrewState:
    """The closed-form estimate as a state on the frame grid."""
    m = data.model
    n = m.nq
    joints = m.movable_joints
    return ScrewState(
        axes=np.array([j.axis / np.linalg.norm(j.axis) for j in joints]).reshape(n, 3),
        origins=np.array([j.T_parent_joint[:3, 3] for j in joints]).reshape(n, 3),
        pitches=np.array([j.pitch for j in joints]),
        t=data.times.copy(), q=data.q_init.copy(), v=None,
        damping=np.array([j.dynamics.damping for j in joints]),
        coulomb=np.array([j.dynamics.coulomb for j in joints]),
    )


def state_model(data: ScrewData, state: ScrewState) -> ArticulatedModel:
    """The model of ``state``: axes, origins, pitches, damping/Coulomb and inertia ratios applied,
    limits those of q at the observed steps (:func:`~kinemaforge_opt.stops.stop_limits`, as the written URDF's)."""
    model = _with_origins(data.model, state.origins)
    cols = np.searchsorted(state.t, data.times)
    ranges = stop_limits(data.times, state.q[cols], joints_seen(data))
    for k, j in enumerate(model.movable_joints):
        lim = j.limits if j.limits is not None else JointLimits()
        limits = JointLimits(float(ranges[k, 0]), float(ranges[k, 1]), lim.effort, lim.velocity)
        dyn = dataclasses.replace(j.dynamics, damping=float(state.damping[k]), coulomb=float(state.coulomb[k]))
        model = model.with_joint(j.name, axis=state.axes[k] / np.linalg.norm(state.axes[k]),
                                 pitch=float(state.pitches[k]) if j.type == "helical" else 0.0,
                                 limits=limits, dynamics=dyn)
    return with_ratios(bodies_kept(model, data.model), data.model, state.mass_ratio, state.inertia_ratio)


def _with_origins(model: ArticulatedModel, origins: np.ndarray) -> ArticulatedModel:
    """``model`` with its rotating joints' origins (n, 3) [m, parent frames] replaced (a prismatic
    joint's origin is not fitted: it keeps its own)."""
    for k, j in enumerate(model.movable_joints):
        if j.type in ("revolute", "continuous", "helical"):
            T = j.T_parent_joint.copy()
            T[:3, 3] = origins[k]
            model = model.with_joint(j.name, T_parent_joint=T)
    return model


def frames_at_zero(model: ArticulatedModel) -> dict[str, np.ndarray]:
    """Link name -> (4, 4) pose of its frame in the root frame at q = 0."""
    T = {model.root.name: np.eye(4)}
    for j in model.joints:
        T[j.child] = T[j.parent] @ j.T_parent_joint
    return T


def bodies_kept(model: ArticulatedModel, reference: ArticulatedModel) -> ArticulatedModel:
    """``model`` with each link's mass properties those of ``reference``'s link, kept where they
    are at q = 0 while ``model``'s link frames sit elsewhere (moved joint lines): the centre of
    mass and rotational inertia re-expressed in the new frame."""
    T_new, T_ref = frames_at_zero(model), frames_at_zero(reference)
    for link in model.links:
        inert = reference.link(link.name).inertial
        if inert is None:
            continue
        T = np.linalg.solve(T_new[link.name], T_ref[link.name])  # reference link frame -> new one
        R = T[:3, :3]
        model = model.with_link(link.name, inertial=Inertial(inert.mass, R @ inert.com + T[:3, 3], R @ inert.inertia @ R.T))
    return model


def _frame_shifts(model: ArticulatedModel, origins: np.ndarray) -> dict[str, np.ndarray]:
    """Link name -> displacement (3,) [m, in the link's axes] of its frame at q = 0 when the
    movable joints' origins (n, 3) (parent frames; a prismatic joint keeps its own) replace
    ``model``'s."""
    T_ref, T_new = frames_at_zero(model), frames_at_zero(_with_origins(model, origins))
    return {l: T_new[l][:3, :3].T @ (T_new[l][:3, 3] - T_ref[l][:3, 3]) for l in T_ref}


def with_ratios(model: ArticulatedModel, reference: ArticulatedModel, mass_ratio: dict[str, float],
                inertia_ratio: dict[str, float]) -> ArticulatedModel:
    """``model`` with each link's mass properties scaled by its ratios (:func:`scaled_inertial`),
    the ratios' shares computed on ``reference``'s body about its joint axis (the model the NLP
    was built on; its link frames may differ from ``model``'s only by translations)."""
    for link, r_m in mass_ratio.items():
        ref = reference.link(link).inertial
        scaled = scaled_inertial(model.link(link).inertial, link_axis(reference, link), r_m, inertia_ratio.get(link), ref)
        model = model.with_link(link, inertial=scaled)
    return model


def _transforms_world0_t(dyn, theta, link_index: int, q, q_zero):
    """Symbolic T_world_link(q) · T_world_link(0)⁻¹ (4, 4) of link ``link_index``."""
    P = dyn.link_poses(q, theta)
    P0 = dyn.link_poses(q_zero, theta)
    T = P[4 * link_index : 4 * link_index + 4, :]
    T0 = P0[4 * link_index : 4 * link_index + 4, :]
    R0t = T0[:3, :3].T
    inv0 = ca.vertcat(ca.horzcat(R0t, -ca.mtimes(R0t, T0[:3, 3])), ca.horzcat(ca.SX.zeros(1, 3), ca.SX.ones(1, 1)))
    return ca.mtimes(T, inv0)


def transforms_world0_t(model: ArticulatedModel, link: str, q: np.ndarray) -> np.ndarray:
    """Numeric (T, 4, 4) motion of ``link`` from the zero configuration to each q (T, n)."""
    dyn = build_dynamics(model)
    i = model.link_names.index(link)
    T0 = dyn.poses(np.zeros(model.nq))[i]
    inv0 = np.linalg.inv(T0)
    return np.array([dyn.poses(qq)[i] @ inv0 for qq in q])


def correspondences(data: ScrewData, state: ScrewState, size: int, seed: int = 0,
                    delta: float | None = None, plane_gate: float = np.inf) -> dict[str, list[Correspondences]]:
    """Per moving part and observed step, correspondences under the motion of ``state``, with IRLS
    weights for the pseudo-Huber width ``delta`` [m] (default ``data.delta``); pairs off their
    tangent plane by more than ``plane_gate`` [m] are left out (:func:`residual_gate`)."""
    delta = data.delta if delta is None else delta
    model = state_model(data, state)
    cols = np.searchsorted(state.t, data.times)
    out = {}
    for p, (link, obs) in enumerate(data.observed.items()):
        Ts = transforms_world0_t(model, link, state.q[cols])
        blocks = []
        for s, (pts, sight) in enumerate(zip(obs, data.sightlines_of(link))):
            pts = np.zeros((0, 3)) if pts is None else pts
            pick = fixed_subsample(pts, size, seed + 1000 * p + s)
            blocks.append((pts[pick], Ts[s], None if sight is None else sight[pick]))
        surface = data.surfaces[link]
        # only an oriented surface has a far side (correspond ignores the thickness otherwise)
        thickness = None
        if data.sightlines is not None and surface.oriented:
            thickness = state.thickness[link] if link in state.thickness else far_side_thickness(surface, blocks, delta)
        # the steps on the workers (the KD queries release the GIL); the same pairs as in order
        out[link] = thread_map(lambda b: correspond(b[0], b[1], surface, data.gate, size, delta, plane_gate, b[2], thickness),
                               blocks)
    return out


def far_side_thickness(surface: SurfaceModel, blocks: list, delta: float) -> float:
    """A part's thickness [m] as a slab (:func:`~.visual.correspond`): the median depth of the
    points on its far side behind the modelled surface.  ``blocks``: per step (observed points,
    motion, sightlines).  Pairs are made without gates, which would cut the depth distribution
    short.  At least 0; 0 when no point is on the far side."""
    # a median needs far fewer points than the fit: every k-th point, at most THICKNESS_SAMPLE
    strided = [slice(None, None, max(1, len(pts) // THICKNESS_SAMPLE)) for pts, _, _ in blocks]
    corr = [correspond(pts[k][:THICKNESS_SAMPLE], T, surface, np.inf, THICKNESS_SAMPLE, delta,
                       sightlines=sight[k][:THICKNESS_SAMPLE], thickness=0.0)
            for k, (pts, T, sight) in zip(strided, blocks) if sight is not None and len(pts)]
    # r = n·(x − y₀): the depth of the back-moved point y₀ behind its nearest surface point x
    depth = np.concatenate([c.residuals[c.far_side & (c.weights > 0)] for c in corr])
    return max(0.0, float(np.median(depth))) if depth.size else 0.0


def residual_gate(data: ScrewData, corr: dict[str, list[Correspondences]]) -> float:
    """The outlier cut-off 3σ̂ [m] (:data:`PLANE_GATE_SIGMAS`; at least ``data.delta``) of the
    point-to-plane residuals of the gated pairs ``corr`` (under the motion they were made at),
    σ̂ = 1.4826 × their median absolute value (the normal-consistent scale, robust to the outliers).

    Why: the nearest-point gate (``data.gate``, two ICP inlier distances) admits the near edge of
    surfaces the zero-step model lacks (a door's inner face once it opens: half of
    protocol_microwave_0's door points at 90°); under the true motion the modelled points sit
    within ~2 mm, and the admitted tail pulled the vis-only axis 0.26° (closed form) -> 0.75°
    off; gated at 3σ̂ (8.9 mm) it ends 0.33° off."""
    gated = [c.residuals[c.weights > 0] for items in corr.values() for c in items]
    r = np.concatenate(gated) if gated else np.zeros(0)
    if r.size < 10:
        return np.inf
    # never below the Huber width (the point noise level): exact points leave σ̂ ≈ 0
    return float(max(PLANE_GATE_SIGMAS * 1.4826 * np.median(np.abs(r)), data.delta))


def truncated_vis_by_step(data: ScrewData, state: ScrewState, corr: dict[str, list[Correspondences]], size: int,
                          charge: float) -> np.ndarray:
    """Per observed step (T,): the robust visual term Σ ρ_δ(r)/δ² of its pairs under the motion of
    ``state``, plus ``charge`` for each of its observed points (at most ``size`` a part) that the
    gates left out (a truncated loss: no motion gains by pushing points out)."""
    out = np.zeros(data.times.size)
    for link, values in robust_values(data, state, corr).items():
        for s, (value, c, pts) in enumerate(zip(values, corr[link], data.observed[link])):
            seen = min(0 if pts is None else len(pts), size)
            out[s] += value + (seen - c.weights.sum()) * charge
    return out


def solved_defects(sp: ScrewProblem, res: Result) -> np.ndarray:
    """(2n, K) the normalised defects of the solved dense problem over its K free intervals
    (q̇ = v rows, then v̇ rows; :attr:`ScrewProblem.defects`)."""
    return np.asarray(sp.defects(*[res.values[name] for name in sp.problem.terms["variables"]]))


def dyn_by_step(sp: ScrewProblem, res: Result, times: np.ndarray) -> np.ndarray:
    """Per observed step (T,) at ``times`` (T,) [s]: the dyn term (½ χ²: Σ ρ of the normalised
    defects) of the free intervals whose midpoint lies from that step to the next (the ends go to
    the first and last steps); zeros for a problem without dynamics."""
    out = np.zeros(times.size)
    if sp.defects is None:
        return out
    D = solved_defects(sp, res)
    t = sp.state.t
    mid = ((t[:-1] + t[1:]) / 2)[np.flatnonzero(sp.normalisation.dyn_mask)]
    steps = np.clip(np.searchsorted(times, mid, side="right") - 1, 0, times.size - 1)
    np.add.at(out, steps, np.sum(pseudo_huber(D, 1.0), axis=0))
    return out


def robust_values(data: ScrewData, state: ScrewState, corr: dict[str, list[Correspondences]]) -> dict[str, list[float]]:
    """Per part, per observed step: ρ_δ(r)/δ² summed over the step's pairs (:func:`~.visual.robust_value`)
    under the motion of ``state``."""
    model = state_model(data, state)
    cols = np.searchsorted(state.t, data.times)
    out = {}
    for link, items in corr.items():
        Ts = transforms_world0_t(model, link, state.q[cols])
        out[link] = [robust_value(c, T, data.delta, state.thickness.get(link)) for c, T in zip(items, Ts)]
    return out


def vis_value(data: ScrewData, state: ScrewState, corr: dict[str, list[Correspondences]]) -> float:
    """The robust visual term Σ ρ_δ(r)/δ² (not its IRLS surrogate) under the motion of ``state``."""
    total = 0.0
    for values in robust_values(data, state, corr).values():
        total += sum(values)
    return float(total)


def ancestor_joints(model: ArticulatedModel, link: str) -> list[int]:
    """Indices (in movable-joint order) of the movable joints from the root to ``link``."""
    names = model.joint_names
    parent_joint = {j.child: j for j in model.joints}
    out = []
    while link in parent_joint:
        j = parent_joint[link]
        if j.name in names:
            out.append(names.index(j.name))
        link = j.parent
    return out[::-1]


def _applied_force(model, dyn, theta, axis_of, pitch_of, q, p, f, sel, pushed: list[str]):
    """τ = Jᵀ W (n,): force f (3,) [N] at world point p (3,) [m] acting on link ``pushed[i]`` with
    weight sel[i]; each ancestor joint k contributes its screw's work rate: a·((p − o) × f) for a
    rotation (+ pitch · a·f for a helix), a·f for a translation (a, o: world axis and point)."""
    n = model.nq
    P = dyn.link_poses(q, theta)
    tau = [ca.SX(0)] * n
    joints = model.movable_joints
    for i, link in enumerate(pushed):
        for k in ancestor_joints(model, link):
            j = joints[k]
            c = model.link_names.index(j.child)
            R, o = P[4 * c : 4 * c + 3, :3], P[4 * c : 4 * c + 3, 3]
            a = ca.mtimes(R, axis_of[k])
            a = a / ca.norm_2(a)
            if j.type == "prismatic":
                g = ca.dot(a, f)
            else:
                g = ca.dot(a, ca.cross(p - o, f))
                if j.type == "helical":
                    g = g + pitch_of[k] * ca.dot(a, f)
            tau[k] = tau[k] + sel[i] * g
    return ca.vertcat(*tau)


def _wrench_at(data: ScrewData, t: np.ndarray, pushed: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Force application point (3, len(t)) [m], force (3, len(t)) [N] and link selector
    (len(pushed), len(t)) at times ``t``: the samples' first-order hold (as the verifier's replay
    applies them).  Between a sample on a link and one on none the force ramps to the second's
    (nothing) on the first's link and point, so a contact's force is continuous: it kinks at the
    samples :func:`force_breaks` names and jumps only where one link's contact gives way to
    another's."""
    w = data.wrenches
    if w is None:
        z = np.zeros((3, t.size))
        return z, z.copy(), np.zeros((len(pushed), t.size))
    last = w.t.size - 1
    before = np.clip(np.searchsorted(w.t, t, side="right") - 1, 0, last)
    after = np.clip(before + 1, 0, last)
    on = np.where(data.pushed_link[before] != "", before, after)  # the sample whose contact this is
    p = np.array([np.interp(t, w.t, c) for c in w.points_world.T])
    lone = (data.pushed_link[before] == "") != (data.pushed_link[after] == "")  # a contact's first or last ramp
    p[:, lone] = w.points_world[on[lone]].T
    f = np.array([np.interp(t, w.t, c, left=0.0, right=0.0) for c in w.forces_world.T])
    sel = np.array([(data.pushed_link[on] == link).astype(float) for link in pushed]).reshape(len(pushed), t.size)
    return p, f, sel


def _rates(t: np.ndarray, q: np.ndarray) -> tuple[CubicSpline, np.ndarray, np.ndarray]:
    """A not-a-knot spline through q (T, n) at t, and per-joint RMS speed and acceleration of it
    (floored so a joint that does not move still has a finite scale)."""
    spline = CubicSpline(t, q, axis=0)
    tt = np.linspace(t[0], t[-1], max(50, 10 * t.size))
    v, a = spline(tt, 1), spline(tt, 2)
    duration = max(t[-1] - t[0], 1e-6)
    v_s = np.maximum(np.sqrt(np.mean(v**2, axis=0)), 1e-3)
    a_s = np.maximum(np.sqrt(np.mean(a**2, axis=0)), v_s / duration)
    return spline, v_s, a_s


def stop_free(times: np.ndarray, q: np.ndarray, t_grid: np.ndarray) -> np.ndarray:
    """(G − 1,) 1.0 for each interval of ``t_grid`` (G,) [s] outside every :func:`~kinemaforge_opt.stops.stop_spans` span
    of the frames (times, q), else 0.0 (an interval is in a span when its midpoint is)."""
    mid = (t_grid[:-1] + t_grid[1:]) / 2
    free = np.ones(mid.size)
    for a, b in stop_spans(times, q):
        free[(mid > times[a]) & (mid < times[b])] = 0.0
    return free


def parts_seen(data: ScrewData) -> np.ndarray:
    """(T, parts) True where a moving part has observed points at a step (``data.observed``'s order)."""
    return np.array([[_rows(obs[i]) > 0 for obs in data.observed.values()] for i in range(data.times.size)],
                    dtype=bool).reshape(data.times.size, len(data.observed))


def unseen_carried_on(times: np.ndarray, q: np.ndarray, seen: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """(T, n) ``q`` (T, n) at ``times`` (T,) [s] with each joint's values before its first seen
    frame (``seen`` (T, n)) carried back at the speed of its first seen frame step, and after its
    last carried on at that of its last, within ``limits`` (n, 2) [rad or m].  The NLP holds
    those values (nothing there places the part); this is a guess for placing the part in frames
    the tracker missed (its solid claims the points there:
    :func:`~kinemaforge_opt.perception.solids.fill_part_solids`).  protocol_microwave_1@s1's
    door, first seen 0.475 s into its push: held at that pose its part IoU was 0.913, carried
    back 0.954 (true frame poses −0.62, −0.53, −0.29 rad; carried −0.875, −0.58, −0.29)."""
    out = np.array(q, dtype=float, copy=True)
    for k in range(out.shape[1]):
        rows = np.flatnonzero(seen[:, k])
        if rows.size < 2:
            continue
        for end, near in ((rows[0], rows[0] + 1), (rows[-1], rows[-1] - 1)):
            speed = (out[end, k] - out[near, k]) / (times[end] - times[near])
            span = slice(0, end) if end == rows[0] else slice(end + 1, None)
            out[span, k] = np.clip(out[end, k] + speed * (times[span] - times[end]), *limits[k])
    return out


def joints_seen(data: ScrewData) -> np.ndarray:
    """(T, n) True where each movable joint's child part is seen at a step (every step for a child
    with no observations)."""
    seen = parts_seen(data)
    parts = list(data.observed)
    return np.column_stack([seen[:, parts.index(j.child)] if j.child in parts else np.ones(data.times.size, dtype=bool)
                            for j in data.model.movable_joints]).reshape(data.times.size, data.model.nq)


def seen_free(data: ScrewData, t_grid: np.ndarray) -> np.ndarray:
    """(G − 1,) 1.0 for each interval of ``t_grid`` (G,) [s] between the first and the last
    observed step at which every moving part is seen, else 0.0 (an interval is in when its
    midpoint is; all 1.0 when fewer than two steps see every part).  Before a part is first seen
    nothing but the dynamics places it: with the initial state free they swung the tiny door
    0.5 rad open before the first frame that saw it shut, and the fit crawled for 400 iterations
    trading that swing against the door's mass."""
    steps = np.flatnonzero(parts_seen(data).all(axis=1))
    free = np.ones(t_grid.size - 1)
    if steps.size < 2:
        return free
    mid = (t_grid[:-1] + t_grid[1:]) / 2
    free[(mid < data.times[steps[0]]) | (mid > data.times[steps[-1]])] = 0.0
    return free


def unseen_hold(data: ScrewData, frame_cols: np.ndarray,
                reached: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The ``unseen_hold`` cost's entries, or None: (indices into vec(Q) (n, G) column-major,
    closed-form targets ``data.q_init`` [rad or m], weights [1/rad² or 1/m²]) of each joint's q
    at each frame where its child part is not seen (:func:`joints_seen`) and no free dynamics
    interval reaches (``reached`` (G,) True where one does; None: no dynamics term).

    There nothing observes that q directly.  It may still be seen through a descendant, but then
    only in combination with the descendant's own joint: a drawer's track split into a parent
    part unseen at the first steps and a child part seen there, on parallel prismatic joints,
    leaves only their sum observed (protocol_drawer_0@s4: the two ran apart, stage after stage,
    to −1.6 and +3.2 km, and the written limits with them).  The hold is worth one point on the
    child at the noise level (weight ℓ²/δ², ℓ = 1 for a slide, the child's RMS radius about its
    centroid for a turn, as a lever arm): it pins what nothing else observes and gives way to
    anything that does."""
    seen = joints_seen(data)
    joints = data.model.movable_joints
    ks, ts = np.nonzero(~seen.T)
    if reached is not None:
        keep = ~reached[frame_cols[ts]]
        ks, ts = ks[keep], ts[keep]
    if ks.size == 0:
        return None
    lever = np.ones(len(joints))
    for k, j in enumerate(joints):
        if j.type != "prismatic" and j.child in data.surfaces:
            lever[k] = rms_radius(data.surfaces[j.child].points)
    n = len(joints)
    return ks + n * frame_cols[ts], data.q_init[ts, ks], lever[ks] ** 2 / data.delta**2


def build_screw_problem(data: ScrewData, options: ScrewOptions, state: ScrewState,
                        corr: dict[str, list[Correspondences]] | None, dense: bool,
                        held: frozenset[str] = frozenset(), aligned: dict[str, np.ndarray] | None = None,
                        normalisation: Normalisation | None = None, kinematics_held: bool = False) -> ScrewProblem:
    """Build the NLP around ``state`` with fixed correspondences ``corr`` (see module doc).
    ``dense``: states (q, v) on the collocation grid with the dynamics/energy terms as the options
    say; else q on the frame grid and only ``vis``.  ``held``: damping / Coulomb variables
    ("damping:<joint>") held at the state's value instead of fitted.  ``aligned``: joint name ->
    (k, 3) rows C of the linear constraint ``aligned:<joint>`` C · axis = 0 (:mod:`.gravity_aligned`).
    ``normalisation``: the scales of the terms (a continuation's: those of the solve it resumes),
    else taken from ``state``.  ``kinematics_held``: every axis, origin and pitch held at the
    state's value (bounds fixed, their constraints dropped): only the joint states are fitted."""
    model = data.model
    n = model.nq
    joints = model.movable_joints
    have_forces = data.wrenches is not None
    use_dyn = dense and options.dyn
    use_energy = use_dyn and options.energy != "off"
    fit_dyn = use_dyn and options.fit_dynamics and have_forces
    pushed = sorted({l for l in (data.pushed_link if have_forces else ()) if l})
    moving_links = sorted({j.child for j in joints} | {l for j in joints for l in model.subtree_links(j.child)})
    moving_links = [l for l in model.link_names if l in moving_links]

    free = []
    for j in joints:
        free.append(f"{j.name}.axis")
        if j.type in ("revolute", "continuous", "helical"):
            free.append(f"{j.name}.origin")
        if j.type == "helical":
            free.append(f"{j.name}.pitch")
    body_links = [l for l in moving_links if model.link(l).inertial is not None and model.link(l).inertial.mass > 0] if use_dyn else []
    ratio_links = body_links if fit_dyn else []
    free += [f"{l}.inertia" for l in body_links]
    dyn = build_dynamics(model, free=free)

    # grid and initial states
    if use_dyn:
        t_grid, frame_cols = _grid(data.times, options.substep_s, force_breaks(data))
    else:
        t_grid, frame_cols = data.times.copy(), np.arange(data.times.size)
    if state.t.size == t_grid.size and np.allclose(state.t, t_grid):
        q0 = state.q
        v0 = state.v
    else:
        q0 = CubicSpline(state.t, state.q, axis=0)(t_grid) if state.t.size > 2 else np.array([np.interp(t_grid, state.t, c) for c in state.q.T]).T
        v0 = None
    cols_state = np.searchsorted(state.t, data.times)
    spline, v_s, a_s = _rates(data.times, state.q[cols_state])
    if normalisation is not None:
        v_s, a_s = normalisation.v_s, normalisation.a_s
    if use_dyn and v0 is None:
        v0 = spline(t_grid, 1)

    prob = Problem("screw_axes")
    # a frame-grid problem is rebuilt round after round around refreshed pairs (reuse_key): what
    # the rounds change is a parameter, so one IPOPT solver serves them all (SolverCache)
    reusable = not dense

    def given(name: str, value) -> ca.MX | ca.DM:
        """Data the terms read: a parameter of a reusable problem, else a constant."""
        return prob.parameter(name, value) if reusable else ca.DM(value)

    # --- joint parameters -> theta (MX) and their SX twins for the per-step functions --------
    theta_sx = ca.SX.sym("theta", dyn.theta0.size)
    theta_parts = []
    axis_of, pitch_of = [], []

    def bounds(value, lower=-np.inf, upper=np.inf):  # a held parameter's bounds are its value
        return (value, value) if kinematics_held else (lower, upper)

    for k, j in enumerate(joints):
        a_var = prob.variable(f"axis:{j.name}", 3, *bounds(state.axes[k], -1.5, 1.5), init=state.axes[k])
        if not kinematics_held:
            prob.add_constraint(f"unit_axis:{j.name}", ca.sumsqr(a_var) - 1.0)
        if aligned and j.name in aligned and not kinematics_held:
            prob.add_constraint(f"aligned:{j.name}", ca.mtimes(given(f"aligned_rows:{j.name}", aligned[j.name]), a_var))
        theta_parts.append(a_var)
        axis_of.append(theta_sx[dyn.parameter(f"{j.name}.axis").slice])
        if j.type in ("revolute", "continuous", "helical"):
            o_var = prob.variable(f"origin:{j.name}", 3, *bounds(state.origins[k]), init=state.origins[k])
            if not kinematics_held:
                a_parent = j.T_parent_joint[:3, :3] @ state.axes[k]
                prob.add_constraint(f"gauge:{j.name}", ca.dot(given(f"gauge_axis:{j.name}", a_parent),
                                                              o_var - given(f"gauge_origin:{j.name}", state.origins[k])))
            theta_parts.append(o_var)
        if j.type == "helical":
            p_var = prob.variable(f"pitch:{j.name}", 1, *bounds(state.pitches[k]), init=state.pitches[k])
            theta_parts.append(p_var)
            pitch_of.append(theta_sx[dyn.parameter(f"{j.name}.pitch").slice])
        else:
            pitch_of.append(None)
    ratios = []  # names of the ratio variables (mass_ratio:<l>, inertia_ratio:<l>)
    # each body where its points put it, about the link frame on the stage's starting joint line
    # (within the stage it moves with the frame; the next stage and the written model put it
    # back): the parameter map stays linear in the variables, as the structured Hessian assumes
    shifts = _frame_shifts(model, state.origins)
    for l in body_links:
        inertial, axis = model.link(l).inertial, link_axis(model, l)
        r_m, r_a = state.mass_ratio.get(l, 1.0), state.inertia_ratio.get(l, 1.0) if has_axis_ratio(inertial, axis) else None
        if l in ratio_links:
            r_m = prob.variable(f"mass_ratio:{l}", 1, lower=RATIO_BOUNDS[0], upper=RATIO_BOUNDS[1], init=r_m)
            ratios.append(f"mass_ratio:{l}")
            if r_a is not None:
                r_a = prob.variable(f"inertia_ratio:{l}", 1, lower=RATIO_BOUNDS[0], upper=RATIO_BOUNDS[1], init=r_a)
                ratios.append(f"inertia_ratio:{l}")
                # the scaled body stays physical: its inertia about the centre of mass stays positive
                prob.add_constraint(f"com_inertia_floor:{l}", com_scale(inertial, axis, r_m, r_a), MIN_COM_SCALE, np.inf)
        theta_parts.append(ca.vertcat(*scaled_parameters(inertial, axis, r_m, r_a, shifts[l])))
    use_prior = bool(ratios) and 0 < options.inertia_prior_sigma < np.inf
    theta_mx = ca.vertcat(*theta_parts)

    # --- states ------------------------------------------------------------------------------
    G = t_grid.size
    if use_dyn:
        # interval k: grid k -> k + 1
        if normalisation is not None and normalisation.dyn_mask is not None:
            dyn_mask = normalisation.dyn_mask.copy()
        else:
            seen = seen_free(data, t_grid)
            dyn_mask = seen * (stop_free(data.times, state.q[cols_state], t_grid) if options.stop_impacts else 1.0)
            if not dyn_mask.any():
                dyn_mask = seen  # an impact at the first frame: nothing would be left
        lower, upper = np.full((2 * n, G), -np.inf), np.full((2 * n, G), np.inf)
        if not options.vis:  # nothing observes q: hold the observed steps at the current values
            lower[:n, frame_cols] = upper[:n, frame_cols] = q0.T[:, frame_cols]
        # in a stop span or before the parts are seen no term sees v, nor q between frames or at
        # a frame that sees no part: hold them (IPOPT drops them)
        after = np.ones(G, dtype=bool)  # column c: no free interval (c - 1 or c) touches it
        after[1:] &= dyn_mask == 0
        after[:-1] &= dyn_mask == 0
        x_init = np.vstack([q0.T, v0.T])
        fixed_states = np.zeros((2 * n, G), dtype=bool)
        fixed_states[n:, after] = True
        between = after.copy()
        between[frame_cols[parts_seen(data).any(axis=1)]] = False
        fixed_states[:n, between] = True
        lower[fixed_states] = upper[fixed_states] = x_init[fixed_states]
        X = prob.variable("x", (2 * n, G), init=np.vstack([q0.T, v0.T]), lower=lower, upper=upper)
        Q = X[:n, :]
    else:
        lower = upper = None
        if not options.vis:  # nothing observes q: hold the closed-form values
            lower = upper = q0.T
        Q = prob.variable("q", (n, G), init=q0.T, lower=-np.inf if lower is None else lower,
                          upper=np.inf if upper is None else upper)
    terms = {}
    n_vis = 0
    vis_blocks = []  # (per-step Function, frame columns, H blocks) for the structured Hessian

    # --- vis -----------------------------------------------------------------------------------
    jit = {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O1"]}} if options.jit else {}
    if options.vis and corr:
        total = ca.MX(0)
        qs = ca.SX.sym("q", n)
        for link, items in corr.items():
            Tm = _transforms_world0_t(dyn, theta_sx, model.link_names.index(link), qs, ca.DM.zeros(n))
            zv = z_vector(Tm)
            made_at = items[0].thickness if items else None
            far_pairs = sum(float(c.H_thickness[13, 13]) for c in items) if made_at is not None else 0.0
            if not dense and options.fit_thickness and far_pairs >= MIN_FAR_SIDE_WEIGHT:
                # the part's far side is a slab whose thickness is fitted with the motion: held at
                # the median depth of the far-side points under the current motion, a hinge off
                # along the part and a too-thin slab explain a turned part's far side alike
                # (protocol_laptop_0@s2: a 2 mm slab for a 7.7 mm lid, the hinge 5.6 mm off).  At
                # most one gate thicker than the pairs were made at: beyond it they would not pair.
                t_var = prob.variable(f"thickness:{link}", 1, lower=0.0, upper=made_at + data.gate, init=made_at)
                Hs, dt = ca.SX.sym("H", 14, 14), ca.SX.sym("dt")
                zt = ca.vertcat(zv, dt)
                step = ca.Function(f"vis_{link}", [qs, theta_sx, Hs, dt], [0.5 * ca.mtimes([zt.T, Hs, zt]) / data.delta**2], jit)
                vals = step.map(len(items))(Q[:, frame_cols.tolist()], theta_mx,
                                            given(f"H_thickness:{link}", np.hstack([c.H_thickness for c in items])),
                                            t_var - given(f"thickness_paired:{link}", made_at))
            else:
                Hs = ca.SX.sym("H", 13, 13)
                step = ca.Function(f"vis_{link}", [qs, theta_sx, Hs],
                                   [0.5 * ca.mtimes([zv.T, Hs, zv]) / data.delta**2], jit)
                H = np.hstack([c.H for c in items])
                vals = step.map(len(items))(Q[:, frame_cols.tolist()], theta_mx, given(f"H:{link}", H))
                vis_blocks.append((step, frame_cols, H))
            total = total + ca.sum2(vals)
            n_vis += int(sum(c.weights.sum() for c in items))
        terms["vis"] = total
    norm = float(max(n_vis, 1))
    hold = unseen_hold(data, frame_cols, reached=~after if use_dyn else None)
    if hold is not None:
        idx, target, weight = hold
        terms["unseen_hold"] = 0.5 * ca.sumsqr(ca.DM(np.sqrt(weight)) * (ca.vec(Q)[idx.tolist()] - ca.DM(target)))

    # --- dyn and energy --------------------------------------------------------------------
    if use_dyn:
        eps = np.maximum(0.03 * v_s, 1e-4)
        phi = ca.SX.sym("phi", 2 * n)  # damping, coulomb

        def passive(q, v):
            return ca.vertcat(*[EFFECTS["viscous_damping"].force(q[k], v[k], phi[k])
                                + EFFECTS["coulomb_friction"].force(q[k], v[k], phi[n + k], eps=float(eps[k]))
                                for k in range(n)])

        ps, fs, ss = ca.SX.sym("p", 3), ca.SX.sym("f", 3), ca.SX.sym("sel", max(len(pushed), 1))

        def rhs(x, p, f, sel):
            q, v = x[:n], x[n:]
            u = _applied_force(model, dyn, theta_sx, axis_of, pitch_of, q, p, f, sel, pushed) if pushed else ca.SX.zeros(n)
            tau = u + passive(q, v)
            return ca.vertcat(v, dyn.aba(q, v, tau, theta_sx)), ca.dot(tau, v)

        def energy_of(x):
            q, v = x[:n], x[n:]
            return 0.5 * ca.dot(v, ca.mtimes(dyn.crba(q, theta_sx), v)) + dyn.potential_energy(q, theta_sx)

        # the right-hand side once per grid point (mapped over G), the midpoint inside the interval
        xs, h = ca.SX.sym("x", 2 * n), ca.SX.sym("h")
        r_pt, w_pt = rhs(xs, ps, fs, ss)
        point = ca.Function("rhs", [xs, ps, fs, ss, theta_sx, phi], [r_pt, w_pt], jit)
        xk, xk1 = ca.SX.sym("xk", 2 * n), ca.SX.sym("xk1", 2 * n)
        rk, rk1 = ca.SX.sym("rk", 2 * n), ca.SX.sym("rk1", 2 * n)
        wk, wk1 = ca.SX.sym("wk"), ca.SX.sym("wk1")
        xm = (xk + xk1) / 2 + h / 8 * (rk - rk1)
        rm, wm = rhs(xm, ps, fs, ss)
        defect = xk1 - xk - h / 6 * (rk + 4 * rm + rk1)
        scale = ca.DM(np.concatenate([v_s, a_s]))
        sigma = ca.DM(np.repeat(options.dyn_row_sigma, n)) if options.dyn_row_sigma else options.dyn_sigma
        dnorm = defect / (h * scale) / sigma
        interval = ca.Function("hermite_simpson", [xk, xk1, rk, rk1, wk, wk1, ps, fs, ss, h, theta_sx, phi],
                               [ca.sum1(pseudo_huber(dnorm, 1.0)), h / 6 * (wk + 4 * wm + wk1), dnorm], jit)
        energy = ca.Function("energy", [xs, theta_sx], [energy_of(xs)], jit)
        t_mid = (t_grid[:-1] + t_grid[1:]) / 2
        P, F, S = _wrench_at(data, t_grid, pushed or [""])
        Pm, Fm, Sm = _wrench_at(data, t_mid, pushed or [""])
        phi_parts = []
        for name, values in (("damping", state.damping), ("coulomb", state.coulomb)):
            for k, j in enumerate(joints):
                if fit_dyn and f"{name}:{j.name}" not in held:
                    force_s = _force_scale(data, j, v_s[k], a_s[k])
                    sc = force_s / v_s[k] if name == "damping" else force_s
                    z = prob.variable(f"{name}:{j.name}", 1, lower=0.0, init=values[k] / sc)
                    phi_parts.append(z * sc)
                else:
                    phi_parts.append(ca.MX(values[k]))
        phi_mx = ca.vertcat(*phi_parts)
        Rg, Wg = point.map(G, "thread", workers())(X, P, F, S, theta_mx, phi_mx)
        Dsum, Wk, Dn = interval.map(G - 1, "thread", workers())(
            X[:, :-1], X[:, 1:], Rg[:, :-1], Rg[:, 1:], Wg[:, :-1], Wg[:, 1:],
            Pm, Fm, Sm, np.diff(t_grid)[None, :], theta_mx, phi_mx)
        terms["dyn"] = ca.sum2(Dsum * ca.DM(dyn_mask[None, :]))
        if use_energy:
            steps = max(1, int(round(options.energy_window_s / max(np.median(np.diff(t_grid)), 1e-9))))
            edges = list(range(0, G - 1, steps)) + [G - 1]
            E = energy.map(len(edges))(X[:, edges], theta_mx)  # ΔE telescopes: only window edges
            resid = ca.vertcat(*[E[i + 1] - E[i] - ca.sum2(Wk[:, a:b]) for i, (a, b) in enumerate(zip(edges[:-1], edges[1:]))])
            e_mask = np.array([float(dyn_mask[a:b].all()) for a, b in zip(edges[:-1], edges[1:])])
            e_scale = (normalisation.e_scale if normalisation is not None and normalisation.e_scale is not None
                       else _energy_scale(model, dyn, q0, v0))
            rel = resid / e_scale
            if options.energy == "soft":
                terms["energy"] = ca.sumsqr(rel * ca.DM(e_mask) / options.energy_sigma) * options.energy_weight
            else:
                big = np.where(e_mask > 0, options.energy_tolerance, np.inf)
                prob.add_constraint("energy", rel, -big, big)
                terms["energy_residual"] = ca.sumsqr(rel * ca.DM(e_mask))
    prior_fn = None
    if use_dyn and use_prior:
        # ½ Σ e²: in the units of the other terms (each ≈ ½ χ²), added with the same weight
        terms["inertia_prior"] = 0.5 * ca.sumsqr(ca.vertcat(*_prior_residuals(prob, ratios, options.inertia_prior_sigma)))
    cost_scale = given("cost_scale", 1.0 / norm)
    for name, expr in terms.items():
        if name == "energy_residual":  # reported, not minimised
            continue
        prob.add_cost(name, expr, weight=cost_scale)
    if "energy_residual" in terms:
        prob.add_cost("energy_residual", terms["energy_residual"], weight=0.0)
    if not prob.terms["costs"]:
        raise KinemaforgeError("the screw NLP has no active term: enable 'vis' (with observed points) or 'dyn'")
    new_state = dataclasses.replace(state, t=t_grid, q=q0, v=v0 if use_dyn else None)
    defects = None
    if use_dyn:  # the normalised defects (2n, G - 1) of the free intervals, for the process-noise estimate
        names = prob.terms["variables"]
        defects = ca.Function("defects", [prob.symbol(name) for name in names], [Dn[:, np.flatnonzero(dyn_mask).tolist()]])
    hess_lag = None
    if use_dyn and options.hessian in ("exact", "gauss_newton"):
        pnames = [name for name in prob.terms["variables"] if name != "x"]
        theta_phi = ca.Function("theta_phi", [prob.symbol(name) for name in pnames], [theta_mx, phi_mx])
        if "inertia_prior" in terms:
            prior_fn = ca.Function("inertia_prior", [prob.symbol(name) for name in pnames], [terms["inertia_prior"]])
        hess_lag = lagrangian_hessian(DenseTerms(
            prob, n, G, theta_phi, point, interval, energy if use_energy else None, (P, F, S), (Pm, Fm, Sm),
            np.diff(t_grid), vis_blocks, 1.0 / norm, options.energy if use_energy else "off",
            edges if use_energy else [], e_scale if use_energy else 1.0,
            options.energy_weight / options.energy_sigma**2,
            [] if kinematics_held else [(f"axis:{j.name}", f"unit_axis:{j.name}") for j in joints],
            options.hessian == "gauss_newton",
            dyn_mask=dyn_mask, energy_mask=e_mask if use_energy else None, prior=prior_fn,
            hold=None if hold is None else (hold[0], hold[2])))
    scales = Normalisation(v_s, a_s, dyn_mask if use_dyn else None, e_scale if use_energy else None)
    return ScrewProblem(prob, data, options, new_state, frame_cols, dyn, tuple(free), use_dyn, n_vis, hess_lag, prior_fn,
                        defects, scales, ("frame_grid", options.jit) if reusable else None)


def _prior_residuals(prob: Problem, ratios: list[str], sigma: float) -> list:
    """Normalised prior residuals of the ratio variables ``ratios``: log r_a / σ for a link's
    inertia ratio (its scale), log(r_m / r_a) / SHAPE_PRIOR_SIGMA for its mass ratio beside it
    (the mesh's shape), log r_m / σ for a link with a mass ratio only."""
    out = []
    for name in ratios:
        kind, _, link = name.partition(":")
        r = prob.symbol(name)
        if kind == "mass_ratio" and f"inertia_ratio:{link}" in ratios:
            out.append(ca.log(r / prob.symbol(f"inertia_ratio:{link}")) / SHAPE_PRIOR_SIGMA)
        else:
            out.append(ca.log(r) / sigma)
    return out


def _prior_hessian(sp: ScrewProblem, x: np.ndarray, params: list[str]) -> np.ndarray:
    """(P, P) Hessian of the raw ratio prior (½ Σ e², :func:`_prior_residuals`) over ``params`` at
    the decision vector ``x``; zeros without a prior."""
    P = len(params)
    if sp.prior is None:
        return np.zeros((P, P))
    vs, _ = sp.problem.layout()
    names = [n for n in vs if n != "x"]
    syms = [ca.MX.sym(n, vs[n].stop - vs[n].start) for n in names]
    z = ca.vertcat(*syms)
    H = ca.Function("prior_hessian", syms, [ca.hessian(sp.prior(*syms), z)[0]])(*[x[vs[n]] for n in names])
    H = np.asarray(ca.DM(H).full())
    offsets = np.cumsum([0] + [vs[n].stop - vs[n].start for n in names])
    local = [int(offsets[names.index(p)]) for p in params]
    return H[np.ix_(local, local)]


def _prior_precision(name: str, value: float, params: list[str], sigma: float) -> float:
    """Marginal precision [1/ratio²] the prior of :func:`_prior_residuals` alone gives the ratio
    variable ``name`` at ``value`` (Gauss–Newton: log r_a ~ N(0, σ²), log r_m ~ N(0, σ² + σ_s²)
    beside an inertia ratio, else N(0, σ²)); 0 without a prior."""
    if not 0 < sigma < np.inf:
        return 0.0
    kind, _, link = name.partition(":")
    var_log = sigma**2 + (SHAPE_PRIOR_SIGMA**2 if kind == "mass_ratio" and f"inertia_ratio:{link}" in params else 0.0)
    return 1.0 / (var_log * value**2)


def _force_scale(data: ScrewData, joint, v_s: float, a_s: float) -> float:
    """Typical generalised force on ``joint`` [N·m or N]: inertia along it × typical acceleration."""
    from ..model.pinocchio import joint_space_inertia

    M = joint_space_inertia(data.model, np.zeros(data.model.nq))
    k = data.model.joint_index(joint.name)
    return float(max(M[k, k] * a_s, 1e-6))


def _energy_scale(model: ArticulatedModel, dyn, q: np.ndarray, v: np.ndarray) -> float:
    """Spread of the mechanical energy along the initial trajectory [J] (≥ 1e-9)."""
    E = [0.5 * vv @ dyn.crba(qq, dyn.theta0).full() @ vv + float(dyn.potential_energy(qq, dyn.theta0)) for qq, vv in zip(q, v)]
    return float(max(np.ptp(E), 1e-9))


# IPOPT for a refit started next to its optimum (the re-weighted, friction-held and aligned fits,
# each from the converged full fit): a monotone barrier from a small mu.  The adaptive barrier's
# first mu there was ~1 (damping and Coulomb start at their bound 0), its first step went 30
# units away and protocol_cabinet_1@s1's plumb fit stopped at 2 × 200 iterations; from mu 1e-4
# both plumb doors are kept.  The re-weighted fit from the default barrier took 156 iterations on
# protocol_refrigerator_0 (15 this way, the same optimum) and stopped at 200 on the demo door,
# protocol_cabinet_1@s1 and protocol_drawer_1@s1 (19, 20 and 119 this way).
NEAR_START_IPOPT = {"ipopt.mu_strategy": "monotone", "ipopt.mu_init": 1e-4}
# IPOPT for a dense stage restarted after its adaptive-barrier solve and the warm continuation
# were refused: a monotone barrier from mu 0.01.  On the demo door (its body kept at its points)
# the adaptive barrier's fifth step went 561 units out (mass ratio 8.9), both solves stopped at
# 200 iterations and the refit without damping left the replay 17 cm off after 1 s; restarted
# this way the full stage converges in 64 (monotone from IPOPT's default mu 0.1 crawled on
# protocol_cabinet_0 and the hard-energy test door; as the default from 0.01 it failed three tests).
RESTART_IPOPT = {"ipopt.mu_strategy": "monotone", "ipopt.mu_init": 1e-2}


def _solver_options(options: ScrewOptions, dense: bool, hess_lag: ca.Function | None = None) -> dict:
    """IPOPT options.  With the dynamics, the mapped MX graph is expanded to SX unless JIT is on:
    the exact Hessian of the mapped ABA intervals evaluated through MX cost ~1 s per iteration
    on the test door, the expanded one a few ms (building it costs ~1 s once)."""
    out = {"ipopt.acceptable_tol": 1e-5}
    if options.hessian == "lbfgs":
        out["ipopt.hessian_approximation"] = "limited-memory"
    if dense:
        # the dense problem is non-convex (IPOPT corrects the Hessian's inertia at most
        # iterations); the monotone barrier update crawled there: protocol_cabinet_0 101
        # iterations -> 26 adaptive, the hard-energy test door 200 (not converged) -> 79
        out["ipopt.mu_strategy"] = "adaptive"
        # IPOPT's filter takes any step that lowers the constraint violation while that is above
        # theta_min (default 1e-4 here), whatever it does to the objective; the unit-axis
        # constraints' curvature leaves ~1e-4 after each step, so steps that cut it were taken
        # while the objective went 0.2 -> 1600 (the tiny door's full stage, 3 × 200 iterations).
        # Below 1e-2 the iterate counts as feasible and every step must lower the objective
        # (Armijo): that stage converges in 114.
        out["ipopt.theta_min_fact"] = 1e-2
        # the adaptive barrier may raise mu (to 20 at protocol_cabinet_0's second iteration): the
        # barrier then pushed the variables bounded at 0 (damping, Coulomb) 1e4 units out, the
        # objective went 0.18 -> 435 and the stage stopped at 2 × 200 iterations.  Capped at the
        # restart's mu (RESTART_IPOPT) it converges in 29.
        out["ipopt.mu_max"] = 1e-2
    if hess_lag is not None:  # the structured Hessian: the MX graph's own derivatives are cheap
        out["hess_lag"] = hess_lag
    elif dense and options.expand and not options.jit:
        out["expand"] = True
    return out


def read_solution(sp: ScrewProblem, result: Result) -> ScrewState:
    """The state at ``result``'s optimum."""
    st, vals = sp.state, result.values
    joints = sp.data.model.movable_joints
    n = len(joints)
    axes, origins, pitches = st.axes.copy(), st.origins.copy(), st.pitches.copy()
    damping, coulomb = st.damping.copy(), st.coulomb.copy()
    for k, j in enumerate(joints):
        a = vals[f"axis:{j.name}"]
        axes[k] = a / np.linalg.norm(a)
        if f"origin:{j.name}" in vals:
            origins[k] = vals[f"origin:{j.name}"]
        if f"pitch:{j.name}" in vals:
            pitches[k] = float(vals[f"pitch:{j.name}"][0])
    ratios = {"mass_ratio": dict(st.mass_ratio), "inertia_ratio": dict(st.inertia_ratio),
              "thickness": dict(st.thickness)}
    for name, v in vals.items():
        kind, _, link = name.partition(":")
        if kind in ratios:
            ratios[kind][link] = float(v[0])
    if "x" in vals:
        q, v = vals["x"][:n].T, vals["x"][n:].T
    else:
        q, v = vals["q"].T, None
    # damping / coulomb are scaled variables: recover physical values from the built expression
    if any(name.startswith(FRICTION_PARAMETERS) for name in vals):
        v_s, a_s = sp.normalisation.v_s, sp.normalisation.a_s
        for k, j in enumerate(joints):
            fs = _force_scale(sp.data, j, v_s[k], a_s[k])
            # IPOPT may relax the bound 0 by ~1e-8: clip
            if f"damping:{j.name}" in vals:
                damping[k] = max(float(vals[f"damping:{j.name}"][0]) * fs / v_s[k], 0.0)
            if f"coulomb:{j.name}" in vals:
                coulomb[k] = max(float(vals[f"coulomb:{j.name}"][0]) * fs, 0.0)
    return ScrewState(axes, origins, pitches, st.t.copy(), q, v, damping, coulomb, ratios["inertia_ratio"],
                      ratios["mass_ratio"], ratios["thickness"])


FRICTION_PARAMETERS = ("damping:", "coulomb:")
RATIO_PARAMETERS = ("mass_ratio:", "inertia_ratio:")
DYNAMIC_PARAMETERS = FRICTION_PARAMETERS + RATIO_PARAMETERS
# A fitted damping / Coulomb coefficient counts as identified when its standard deviation is below
# this fraction of its value (its 95 % interval then excludes 0 by ~2σ).
IDENTIFIED_REL_STD = 0.5


def dynamic_identifiability(sp: ScrewProblem, res: Result) -> dict:
    """Which dynamic parameters of the dense solve the data determine, from the curvature of the
    objective at the optimum: the Hessian of the objective (the assembled exact one, so only with
    ``hessian="exact"`` / ``"gauss_newton"``) over the joint states and the parameters, the states
    eliminated (Schur complement; the axes and origins held at their optimum, which the visual
    term fixes far better), times the number of visual residuals (the objective's normaliser; each
    term is ≈ ½ χ²) = the information matrix of the parameters, inverted to a covariance.

    Returns {name: {"value", "std", "relative_std", "status"}, "correlation": {joint: ρ(damping,
    Coulomb)}} in the NLP's variable units (damping and Coulomb scaled by the joint's force
    scale: only ratios and correlations are meaningful).  status: "identified" (std below
    IDENTIFIED_REL_STD × value), "not_identified", "at_bound" (fitted at 0) or, for a mass or
    inertia ratio, "identified" (the data's information on it, marginally over the other
    parameters, at least the prior's), "prior_dominated" (less: it rests on the mesh) or
    "not_identified" (no positive curvature)."""
    if sp.hess_lag is None or not np.isfinite(res.objective):
        return {}
    prob = sp.problem
    vs, gs = prob.layout()
    nw = sum(sl.stop - sl.start for sl in vs.values())
    ng = sum(sl.stop - sl.start for sl in gs.values())
    x = np.zeros(nw)
    for name, sl in vs.items():
        x[sl] = np.asarray(res.values[name], dtype=float).reshape(-1, order="F")
    params = [n for n in vs if n.startswith(DYNAMIC_PARAMETERS)]
    if not params:
        return {}
    Hu = np.asarray(sp.hess_lag(x, [], 1.0, np.zeros(ng)).full())
    H = Hu + Hu.T - np.diag(np.diag(Hu))
    pidx = np.array([vs[n].start for n in params])
    var = prob._vars["x"]
    free = np.flatnonzero(var.lower < var.upper) + vs["x"].start
    Hpp, Hpx, Hxx = H[np.ix_(pidx, pidx)], H[np.ix_(pidx, free)], H[np.ix_(free, free)]
    ridge = 1e-12 * max(np.abs(np.diag(Hxx)).max(), 1e-30)
    S = Hpp - Hpx @ np.linalg.solve(Hxx + ridge * np.eye(free.size), Hpx.T)
    info = max(sp.n_vis, 1) * S
    cov = np.linalg.pinv(info)
    # the data's own information: the prior's Hessian (it involves no states) taken out
    cov_data = np.linalg.pinv(info - _prior_hessian(sp, x, params))
    sigma = sp.options.inertia_prior_sigma
    out = {}
    for i, name in enumerate(params):
        value = float(x[pidx[i]])
        var_i = float(cov[i, i])
        std = float(np.sqrt(var_i)) if var_i > 0 else float("inf")
        rel = std / abs(value) if value != 0 else float("inf")
        if name.startswith(RATIO_PARAMETERS):
            if not np.isfinite(std):  # the curvature there is not positive: nothing pins it
                status = "not_identified"
            else:
                # identified when the data alone (marginally over the other parameters) pin it at
                # least as tightly as the prior alone does
                data_info = 1.0 / cov_data[i, i] if cov_data[i, i] > 0 else 0.0
                status = "identified" if data_info >= _prior_precision(name, value, params, sigma) else "prior_dominated"
        elif value <= 1e-6 * max(abs(x[pidx]).max(), 1e-12) or prob._vars[name].lower[0] >= value - 1e-9:
            status = "at_bound"
        else:
            status = "identified" if rel < IDENTIFIED_REL_STD else "not_identified"
        finite = lambda v: float(v) if np.isfinite(v) else None  # noqa: E731 — JSON has no inf
        out[name] = {"value": value, "std": finite(std), "relative_std": finite(rel), "status": status}
    corr = {}
    for j in sp.data.model.movable_joints:
        a, b = f"damping:{j.name}", f"coulomb:{j.name}"
        if a in params and b in params:
            ia, ib = params.index(a), params.index(b)
            d = np.sqrt(max(cov[ia, ia], 0) * max(cov[ib, ib], 0))
            corr[j.name] = float(cov[ia, ib] / d) if d > 0 else None
    out["correlation_damping_coulomb"] = corr
    return out


def refine_screws(data: ScrewData, options: ScrewOptions | None = None) -> ScrewResult:
    """Coarse-to-fine refinement of the closed-form joints in ``data`` (see module doc).

    Stages: ``vis`` warm-up (up to ``options.rounds`` solves on the frame grid, correspondences and
    IRLS weights refreshed before each, the robust width annealed from half the gate down to
    ``data.delta``; stops early once a round moves nothing), the gated warm-up (as many rounds,
    pairs beyond :func:`residual_gate` of the settled fit left out) then the full objective on
    the dense grid (correspondences refreshed once more, gated); without coarse-to-fine, one full
    solve with the correspondences of the closed form.  A stage that does not converge is
    recorded (``success`` False, IPOPT's status kept); its last iterate is kept (``accepted``)
    only if its robust visual term is no worse than before the stage (within :data:`VIS_SLACK`),
    else it is continued once from that iterate, warm-started with its multipliers and barrier
    parameter (``<stage>_continued``: protocol_drawer_1@s1's full stage stopped at 200 iterations
    and converged 46 later; restarted cold, it stopped at 200 again) and judged the same way, and
    if refused again the next stage starts from the previous state.  The re-weighted full solve
    is kept only when it converges."""
    options = options or ScrewOptions()
    start = time.perf_counter()
    state = initial_state(data)
    stages, notes, alignment_tests = [], [], []
    size = options.points_per_part
    want_dense = options.dyn and data.wrenches is not None
    if options.dyn and data.wrenches is None:
        notes.append("dyn: no recorded forces (wrenches.csv); the dynamics term is off")
    if not options.vis and not want_dense:
        raise KinemaforgeError("the screw NLP has nothing to fit: 'vis' is off and 'dyn' has no recorded forces")
    opts = dataclasses.replace(options, dyn=want_dense)
    solvers = SolverCache()  # the frame-grid rounds' solvers, built once for this data

    def run(name, corr, dense, held=frozenset(), converged_only=False, start=None, aligned=None, accept=None,
            stage_options=None, warm=None, commit=True, ipopt=None, resumes=None, kinematics_held=False, log=None):
        """Solve a stage from ``start`` (default: the current state) with ``stage_options``
        (default: the current ones); ``accept(problem, result)``: a test of a converged result
        that must also pass; ``warm``: the stopped result whose last iterate ``start`` is (IPOPT warm start), with
        ``resumes`` its problem (whose :class:`Normalisation` the continuation keeps);
        ``commit``: an accepted result becomes the current state; ``ipopt``: IPOPT options on top
        of :func:`_solver_options`; ``kinematics_held``: only the joint states are fitted
        (:func:`build_screw_problem`); ``log``: the list the stage's record goes to (default: the
        fit's ``stages``).  Returns (problem, result, the accepted solution or else the
        unaccepted last iterate or None)."""
        nonlocal state
        t0 = time.perf_counter()
        sp = build_screw_problem(data, stage_options or opts, start or state, corr, dense, held, aligned,
                                 None if resumes is None else resumes.normalisation, kinematics_held)
        ipopt_options = {**_solver_options(options, sp.use_dyn, sp.hess_lag), **(ipopt or {})}
        if sp.reuse_key is not None and warm is None:
            res = solvers.solve(sp.problem, sp.reuse_key, max_iter=options.max_iter, tol=1e-8, options=ipopt_options)
        else:
            res = sp.problem.solve(max_iter=options.max_iter, tol=1e-8, warm=warm, options=ipopt_options)
        accepted, iterate = False, None
        if np.isfinite(res.objective) and _physical(data, candidate := read_solution(sp, res)):
            # an unconverged iterate is kept only if it fits the observed points no worse (VIS_SLACK)
            accepted = res.success or (not converged_only and (
                not corr or vis_value(data, candidate, corr) <= vis_value(data, state, corr) + VIS_SLACK))
            accepted = bool(accepted and (accept is None or accept(sp, res)))
            iterate = candidate
            if accepted and commit:
                state = candidate
        (stages if log is None else log).append({
            "stage": name, "iterations": res.iterations, "success": res.success, "status": res.status,
            "accepted": accepted,
            "time_s": time.perf_counter() - t0, "solve_s": res.solve_time_s,
            "eval_s": {k: round(float(v), 3) for k, v in res.stats.items() if k.startswith("t_wall_nlp")},
            "costs": res.costs, "violations": res.violations, "n_vis": sp.n_vis,
            "variables": sp.problem.sizes["variables"]})
        return sp, res, iterate

    def run_dense(name, corr, held=frozenset(), converged_only=False, ipopt=None):
        """A dense stage (``ipopt``: IPOPT options of its first solve, on top of
        :func:`_solver_options`); stopped at max_iter on an iterate that fits the points worse than
        the state before, it is continued once from that iterate, warm-started with the stopped
        solve's multipliers and barrier parameter; refused again, it is restarted from the state
        before with :data:`RESTART_IPOPT`."""
        sp, res, iterate = run(name, corr, True, held, converged_only, ipopt=ipopt)
        if iterate is not None and not stages[-1]["accepted"] and not res.success and not converged_only:
            sp, res, _ = run(f"{name}_continued", corr, True, held, start=iterate, warm=res, resumes=sp)
            if not stages[-1]["accepted"]:
                sp, res, _ = run(f"{name}_restarted", corr, True, held, ipopt=RESTART_IPOPT)
        return sp, res

    if options.coarse_to_fine and options.vis:
        for r in range(options.rounds):
            # the robust width is annealed from half the gate down to delta: far pairs keep their
            # pull while the alignment is coarse, and lose it once it is fine
            delta = max(data.delta, data.gate / 2 ** (r + 1))
            before = (state.axes.copy(), state.origins.copy(), state.q.copy())
            run(f"vis_warmup_{r + 1}", correspondences(data, state, size, delta=delta), dense=False)
            if delta == data.delta and _converged(before, state):
                break
        if options.refuse:
            data = refused_surfaces(data, state)
            for r in range(options.rounds):
                before = (state.axes.copy(), state.origins.copy(), state.q.copy())
                run(f"vis_refused_{r + 1}", correspondences(data, state, size), dense=False)
                if _converged(before, state):
                    break
        # the settled fit's own residual scale now sets how far off its tangent plane a pair may
        # be; warm up again with the pairs it leaves
        plane_gate = residual_gate(data, correspondences(data, state, size))
        for r in range(options.rounds):
            before = (state.axes.copy(), state.origins.copy(), state.q.copy())
            run(f"vis_gated_{r + 1}", correspondences(data, state, size, plane_gate=plane_gate), dense=False)
            if _converged(before, state):
                break
        notes.append(f"vis: pairs off their tangent plane by more than {plane_gate * 1e3:.1f} mm left out "
                     "(3 robust standard deviations of the warm-up's residuals)")
        if state.thickness:
            notes.append("vis: far-side slab thickness fitted with the motion: " + ", ".join(
                f"{link} {t * 1e3:.1f} mm" for link, t in sorted(state.thickness.items())))
        corr = correspondences(data, state, size, plane_gate=plane_gate)
    else:
        plane_gate = np.inf
        corr = correspondences(data, state, size) if options.vis else None
    sp, res = run_dense("full", corr)
    fitted_state = stages[-1]["accepted"]  # the state is (sp, res)'s solution
    if options.reweight_dyn and options.energy != "hard" and sp.defects is not None and stages[-1]["accepted"]:
        opts = dataclasses.replace(opts, dyn_row_sigma=process_noise_scales(sp, res))
        # a refinement of a converged fit: its unconverged iterate may fit the points as well while
        # its dynamics are anywhere (seen: a door's mass ×22 at max_iter), so only a converged one counts
        sp_rw, res_rw = run_dense("full_reweighted", corr, converged_only=True, ipopt=NEAR_START_IPOPT)
        if stages[-1]["accepted"]:
            sp, res = sp_rw, res_rw
            notes.append("dyn: defect scales re-estimated from the full fit: q̇ = v {:.3g}, v̇ {:.3g} (prior {:.3g})"
                         .format(*opts.dyn_row_sigma, options.dyn_sigma))
    identifiability = _identifiability(sp, res)
    unsupported = _unsupported(identifiability)
    held = frozenset()
    if any(identifiability[n]["status"] == "not_identified" for n in unsupported):
        # joint friction the recording cannot determine keeps its nominal value; the rest is re-fitted
        state = _nominal_friction(state, data.model, unsupported)
        notes.append("dyn: not identified, kept at the nominal value: " + ", ".join(sorted(unsupported)))
        sp_refit, res_refit = run_dense("full_refit", corr, held=frozenset(unsupported), ipopt=NEAR_START_IPOPT)
        if stages[-1]["accepted"]:  # else the full stage's fit stands, its unsupported friction nominal
            sp, res = sp_refit, res_refit
            refit = _identifiability(sp, res)
            # a parameter that the refit no longer determines is held too, without another solve
            later = _unsupported(refit)
            state = _nominal_friction(state, data.model, later)
            identifiability = {**identifiability, **_conditional(refit, identifiability)}
            unsupported |= later
        # what the note says is kept at its nominal value stays there in the stages after (the
        # gravity-aligned refit fitted it again when the refit above was refused)
        held = frozenset(unsupported)
    if options.gravity_aligned and res.success and fitted_state:
        # per joint near plumb or level, its aligned hypotheses (kind, rows), the strongest first
        aligned: dict[str, list[tuple[str, np.ndarray]]] = {}
        for k, j in enumerate(data.model.movable_joints):
            kind = alignment(data.model, j.name, state.axes[k])
            if kind is None:
                continue
            aligned[j.name] = [(kind, constraint_rows(data.model, j.name, kind))]
            face = square_direction(data.model, j.name, state.axes[k], (data.faces or {}).get(j.parent))
            if face is not None:
                aligned[j.name].insert(0, ("square", constraint_rows(data.model, j.name, "square", face)))
        kept: dict[str, np.ndarray] = {}

        # The test compares the two fits on a score of the state alone: the robust visual term on
        # correspondences refreshed at the state, every observed point left out of the gates
        # charged the loss at the gate (a truncated loss, so that no motion gains by pushing points
        # out), each fit first settled by the same rounds of the visual term with its pairs
        # refreshed.  Judged on the free fit's pairs instead, any other motion was charged for
        # pairs made under the free one: that refused protocol_cabinet_1's plumb door by Δχ² 256,
        # while on pairs refreshed per step the true axis fits the points as well as the 1.07° one.
        charge = float(pseudo_huber(min(plane_gate, data.gate), data.delta)) / data.delta**2
        settled_cache: dict = {}

        def settled(rows: dict[str, np.ndarray], name: str) -> tuple[ScrewState, dict | None, np.ndarray, int]:
            """From the current fit with the axes of ``rows`` projected, rounds of the visual term
            with those axes held aligned (pairs refreshed before each, as in the gated warm-up)
            until nothing moves.  Returns (state on the frame grid, its pairs, its truncated
            visual score per step (T,) (:func:`truncated_vis_by_step`), the number of pairs
            within the gates)."""
            key = tuple((name, rows[name].tobytes()) for name in sorted(rows))
            if key in settled_cache:
                return settled_cache[key]
            cols = np.searchsorted(state.t, data.times)
            start = dataclasses.replace(state, t=data.times.copy(), q=state.q[cols], v=None, axes=np.array(
                [project(a, rows[j.name]) if j.name in rows else a for a, j in zip(state.axes, data.model.movable_joints)]))
            if corr is None:
                return start, None, np.zeros(data.times.size), 0
            for r in range(options.rounds):
                pairs = correspondences(data, start, size, plane_gate=plane_gate)
                _, _, solved = run(f"{name}_vis_{r + 1}", pairs, False, held, converged_only=True, start=start,
                                   aligned=rows or None, commit=False)
                if not stages[-1]["accepted"]:
                    break
                moved = not _converged((start.axes, start.origins, start.q), solved)
                start = solved
                if not moved:
                    break
            pairs = correspondences(data, start, size, plane_gate=plane_gate)
            n_in = int(sum(c.weights.sum() for items in pairs.values() for c in items))
            settled_cache[key] = start, pairs, truncated_vis_by_step(data, start, pairs, size, charge), n_in
            return settled_cache[key]

        def non_visual(r: Result, n: int) -> float:
            """½χ² of the dynamics, energy and prior terms of a solved fit (objective × normaliser)."""
            return (r.objective - r.costs.get("vis", 0.0)) * n

        def try_aligned(hypotheses: dict[str, tuple[str, np.ndarray]]) -> bool:
            """Refit with the joints of ``hypotheses`` (name -> (kind, rows)) aligned on top of the
            joints already kept aligned, on the aligned motion's own settled pairs; keep it unless
            the free fit is better beyond the BIC's penalty and the noise of the comparison
            (:func:`~.gravity_aligned.alignment_test`; the parameters saved: their rows)."""
            nonlocal sp, res, corr
            rows = {**kept, **{name: r for name, (_, r) in hypotheses.items()}}
            saved = sum(r.shape[0] for _, r in hypotheses.values())
            n_res = max(sp.n_vis, 1)
            vis_free = settled(kept, "gravity_free")[2]
            step_free = vis_free + dyn_by_step(sp, res, data.times)
            score_free = vis_free.sum() + non_visual(res, n_res)
            start, corr_al, vis_al, n_in_al = settled(rows, "gravity_aligned")
            n_al = n_res if corr_al is None else max(n_in_al, 1)

            def test(sp_r: ScrewProblem, r: Result) -> AlignmentTest:  # both scores in the free fit's normalisation
                per_step = step_shares(step_free, vis_al + dyn_by_step(sp_r, r, data.times))
                return alignment_test(score_free / n_res, (vis_al.sum() + non_visual(r, n_al)) / n_res, n_res, saved,
                                      per_step)

            def accept(sp_r: ScrewProblem, r: Result) -> bool:
                return test(sp_r, r).kept

            if sp.use_dyn:
                # the free fit's dense states, q shifted by what settling moved at the frames and v
                # kept (the shift's derivative added the per-frame jitter to v: refrigerator_1's
                # aligned fit then ran into max_iter, where from these it converges in 11)
                cols = np.searchsorted(state.t, data.times)
                shift = CubicSpline(data.times, start.q - state.q[cols], axis=0)
                start = dataclasses.replace(start, t=state.t, q=state.q + shift(state.t), v=state.v)
            sp_al, res_al, iterate = run("gravity_aligned", corr_al, sp.use_dyn, held, converged_only=True, start=start,
                                         aligned=rows, accept=accept, stage_options=sp.options, ipopt=NEAR_START_IPOPT)
            if not res_al.success and iterate is not None:
                # stopped at max_iter: continued once, warm, as the dense stages are (run_dense)
                sp_al, res_al, _ = run("gravity_aligned_continued", corr_al, sp.use_dyn, held, converged_only=True,
                                       start=iterate, aligned=rows, accept=accept, stage_options=sp.options, warm=res_al,
                                       resumes=sp_al)
            ok = stages[-1]["accepted"]
            tested = "axes: " + ", ".join(f"{name} {kind}" for name, (kind, _) in hypotheses.items())
            record = {"joints": {name: kind for name, (kind, _) in hypotheses.items()}, "converged": bool(res_al.success),
                      "kept": bool(ok)}
            if res_al.success:
                verdict = test(sp_al, res_al)
                alignment_tests.append({**record, **dataclasses.asdict(verdict)})
                notes.append(f"{tested} tested (BIC, {saved} parameters): {verdict.describe()}, "
                             f"{'kept' if ok else 'refused'}")
            else:
                alignment_tests.append(record)
                notes.append(f"{tested} tested: the aligned fit did not converge ({res_al.status}), refused")
            if ok:
                sp, res, corr = sp_al, res_al, corr_al
                kept.update(rows)
                settled_cache.clear()
            return ok

        # all at once, each joint's strongest; refused, each joint on its own, strongest first (one
        # askew hinge, or a joint set whose aligned fit does not converge, does not hold back the
        # others; a drawer not square to its carcass may still slide level)
        if aligned and not try_aligned({name: choices[0] for name, choices in aligned.items()}):
            for name, choices in aligned.items():
                for choice in choices[1:] if len(aligned) == 1 else choices:
                    if try_aligned({name: choice}):
                        break
    cols = np.searchsorted(state.t, data.times)
    measured_q, measure_stages = None, []
    if corr:
        # the motion the images show under the final joints: the visual term alone, the joints held
        measured = dataclasses.replace(state, t=data.times.copy(), q=state.q[cols], v=None)
        for r in range(options.rounds):
            pairs = correspondences(data, measured, MEASURE_POINTS_PER_PART, plane_gate=plane_gate)
            _, _, solved = run(f"measure_{r + 1}", pairs, False, converged_only=True, start=measured, commit=False,
                               stage_options=dataclasses.replace(opts, fit_thickness=False), kinematics_held=True,
                               log=measure_stages)
            if not measure_stages[-1]["accepted"]:
                break
            moved = not _converged((measured.axes, measured.origins, measured.q), solved)
            measured = solved
            measured_q = measured.q
            if not moved:
                break
    model = state_model(data, state)
    terms = {"vis": None, "dyn": None, "energy": None, "inertia_prior": None}
    for name, value in res.costs.items():
        key = "energy" if name == "energy_residual" else name
        terms[key] = float(value) * (max(sp.n_vis, 1) if name != "energy_residual" else 1.0)
    if corr:
        terms["vis"] = vis_value(data, state, corr)
    fitted = tuple(dict.fromkeys([n for n in sp.problem.terms["variables"] if n.startswith(DYNAMIC_PARAMETERS)]
                                 + sorted(unsupported)))
    identified = tuple(n for n in fitted if identifiability.get(n, {}).get("status") == "identified")
    spans = stop_spans(data.times, state.q[cols]) if sp.use_dyn and options.stop_impacts else []
    if not sp.use_dyn:
        model = _without_fitted_dynamics(model, data.model)
    if spans:
        where = ", ".join(f"{data.times[a]:.2f}-{data.times[b]:.2f} s" for a, b in spans)
        notes.append(f"dyn, energy: stop impacts; the terms leave out {where}")
    return ScrewResult(model, state.q[cols], state, terms, int(sum(s["iterations"] for s in stages)),
                       _all_converged(stages), tuple(stages), time.perf_counter() - start,
                       identified, tuple(notes), identifiability, fitted, measured_q, tuple(measure_stages),
                       tuple(alignment_tests))


def _all_converged(stages: list[dict]) -> bool:
    """Whether every stage converged, a stage stopped at max_iter counting as converged when its
    continuation (``<stage>_continued``, the same solve resumed warm) or its restart
    (``<stage>_restarted``) did."""
    base = lambda name: name.removesuffix("_continued").removesuffix("_restarted")  # noqa: E731
    resumed = {base(s["stage"]) for s in stages if s["stage"] != base(s["stage"]) and s["success"]}
    return all(s["success"] or base(s["stage"]) in resumed for s in stages)


# The re-estimated defect scales are at least this share of dyn_sigma: a bound on how much more
# the re-weighted fit may trust the dynamics than the prior (the conditioning of the dense solve),
# not a property of the object.
MIN_ROW_SIGMA_SHARE = 0.05


def process_noise_scales(sp: ScrewProblem, res: Result) -> tuple[float, float]:
    """Relative defect scales (q̇ = v rows, v̇ rows) the solved dense problem's own defects
    support: dyn_sigma × the RMS of the normalised defects of each row kind over the free
    intervals (one step of the maximum-likelihood update of a variance component), within
    [MIN_ROW_SIGMA_SHARE, 1] × dyn_sigma.  The q̇ = v rows take up the tracks' measurement noise,
    the v̇ rows the model's force error; one prior scale for both leaves the second, which is what
    determines friction and inertia, weighed far below what the data support."""
    D = solved_defects(sp, res)
    n = D.shape[0] // 2
    prior = sp.options.dyn_sigma
    used = sp.options.dyn_row_sigma or (prior, prior)  # the scales D is normalised by
    return tuple(min(max(s * float(np.sqrt(np.mean(rows**2))), MIN_ROW_SIGMA_SHARE * prior), prior)
                 for s, rows in zip(used, (D[:n], D[n:])))


def _physical(data: ScrewData, state: ScrewState) -> bool:
    """Whether every link of ``state``'s model is a physical body (an unconverged iterate may
    violate the floor on the inertia about the centre of mass)."""
    try:
        with_ratios(data.model, data.model, state.mass_ratio, state.inertia_ratio)
    except ModelError:
        return False
    return True


def _identifiability(sp: ScrewProblem, res: Result) -> dict:
    """:func:`dynamic_identifiability`, or {"error": ...} when the state block is singular."""
    try:
        return dynamic_identifiability(sp, res)
    except np.linalg.LinAlgError as e:  # report why, keep the fit
        return {"error": f"{type(e).__name__}: {e}"}


def _conditional(refit: dict, full: dict) -> dict:
    """The refit's identifiability entries, each no more determined than the full fit found it:
    the refit's curvature is conditional on the held friction (a modelling choice, not data), so
    a status the full fit gave below "identified" stands, with the refit's value."""
    out = {}
    for name, entry in refit.items():
        before = full.get(name)
        if isinstance(entry, dict) and isinstance(before, dict) and before.get("status") not in (None, "identified"):
            entry = {**entry, "status": before["status"]}
        out[name] = entry
    return out


def _unsupported(identifiability: dict) -> set[str]:
    """Damping / Coulomb variables the data do not determine: status "not_identified" or
    "at_bound" (fitted at 0) in ``identifiability``.  Held at the nominal value in the refit, none
    of them is left as a direction the objective does not bend along."""
    return {name for name, entry in identifiability.items()
            if name.startswith(FRICTION_PARAMETERS) and entry["status"] in ("not_identified", "at_bound")}


def _nominal_friction(state: ScrewState, nominal: ArticulatedModel, names: set[str]) -> ScrewState:
    """``state`` with the damping / Coulomb coefficients ``names`` ("damping:<joint>") back at the
    values of ``nominal``."""
    damping, coulomb = state.damping.copy(), state.coulomb.copy()
    for k, j in enumerate(nominal.movable_joints):
        if f"damping:{j.name}" in names:
            damping[k] = j.dynamics.damping
        if f"coulomb:{j.name}" in names:
            coulomb[k] = j.dynamics.coulomb
    return dataclasses.replace(state, damping=damping, coulomb=coulomb)


def refused_surfaces(data: ScrewData, state: ScrewState) -> ScrewData:
    """``data`` with every surface model rebuilt from the observed points of all steps moved back
    to the zero configuration by the motion of ``state`` (spacing ``data.delta``)."""
    model = state_model(data, state)
    cols = np.searchsorted(state.t, data.times)
    surfaces = {}
    for link, obs in data.observed.items():
        Ts = transforms_world0_t(model, link, state.q[cols])
        steps = [(pts, sight, T) for pts, sight, T in zip(obs, data.sightlines_of(link), Ts) if pts is not None and len(pts)]
        if not steps:
            surfaces[link] = data.surfaces[link]
            continue
        back = np.concatenate([(pts - T[:3, 3]) @ T[:3, :3] for pts, _, T in steps])
        sight = None if data.sightlines is None else np.concatenate([sight @ T[:3, :3] for _, sight, T in steps])
        surfaces[link] = surface_model(back, data.delta, link, sightlines=sight)
    return dataclasses.replace(data, surfaces=surfaces)


def _converged(before, state: ScrewState, angle: float = 1e-4, distance: float = 1e-5) -> bool:
    """True when a warm-up round moved no axis by more than ``angle`` [rad], no origin by more
    than ``distance`` [m] and no q by more than ``angle`` (correspondences have settled)."""
    axes, origins, q = before
    return bool(np.all(np.abs(axes - state.axes) < angle) and np.all(np.abs(origins - state.origins) < distance)
                and np.all(np.abs(q - state.q) < angle))


def _without_fitted_dynamics(model: ArticulatedModel, original: ArticulatedModel) -> ArticulatedModel:
    """Keep the original joint dynamics when none were fitted."""
    for j in original.movable_joints:
        model = model.with_joint(j.name, dynamics=j.dynamics)
    return model
