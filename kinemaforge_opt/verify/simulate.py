"""Simulate an :class:`ArticulatedModel` in Drake: free response or replay of a recorded force.

The generalised force fed to the plant's applied-generalised-force input is

    τ_in(t, q, v) = τ_rec(t) − f ⊙ tanh(v / v_eps) + τ_other(q, v)

- τ_rec: the recording's ``tau`` linearly interpolated in time (first-order hold), time measured
  from the recording's first sample; after its last sample the last value is held.
- Coulomb friction f (``JointDynamics.coulomb``) as a *smooth sign*: −f·tanh(v/v_eps), not a
  stiction model.  v_eps (rad/s or m/s, default :data:`V_EPS`) is the velocity below which the
  friction force fades out linearly; a joint "stopped" by friction creeps with a time constant
  M_jj·v_eps/f and a load below f makes it creep at v_eps·atanh(load/f) instead of sticking.
  The discrete plant applies this force explicitly, which is stable only while the friction's
  slope f/v_eps stays below the joint inertia per step, so there v_eps is raised per joint to
  max(v_eps, 4·h·f_j/M_jj(q0)) with h the 1 ms step and M_jj the mass-matrix diagonal at q0.
- τ_other: every other joint force of the model's dynamics that Drake's joints lack (Stribeck
  friction, constant bias, quadratic drag, a limit contact found by ``diagnose``), the laws of
  :mod:`kinemaforge_opt.physics.effects` with the same smooth sign.
Damping, springs, armature and limits are in the plant (:mod:`.plant`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.symbolic import Expression, Variable
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Adder, SymbolicVectorSystem, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from ..errors import DataError, require_finite
from ..io.recording import Recording
from ..model import ArticulatedModel
from ..physics.effects import dynamics_effects
from .energy import mechanical_energy, model_ordered
from .plant import DISCRETE_TIME_STEP_S, build_plant

V_EPS = 1e-3
"""Default smoothing velocity of the Coulomb friction's tanh [rad/s or m/s]."""

CONTINUOUS_ACCURACY = 1e-7
"""Target accuracy of the continuous plant's error-controlled integrator (Drake RK3)."""


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A simulated motion.

    t: (T,) times [s] from the start of the simulation.  joint_names: the n joints, in q order.
    q: (T, n) positions [rad or m]; v: (T, n) velocities [rad/s or m/s];
    energy: (T,) kinetic + potential (gravity + springs) energy [J], see :mod:`.energy`.
    wall_time_s: seconds the simulation took.
    """

    t: np.ndarray
    joint_names: tuple[str, ...]
    q: np.ndarray
    v: np.ndarray
    energy: np.ndarray
    wall_time_s: float


def simulate(
    model: ArticulatedModel,
    q0,
    v0,
    duration_s: float,
    tau: Recording | None = None,
    dt_out: float = 0.01,
    discrete: bool = True,
    v_eps: float = V_EPS,
) -> Trajectory:
    """Simulate ``model`` from (q0, v0) ((n,) each, q order) for ``duration_s`` seconds.

    tau: None for a free response, or a recording whose ``tau`` is applied (see module docs);
    its joints must be the model's.  dt_out: output sample period [s].  discrete: 1 ms discrete
    plant (joint limits enforced) or a continuous plant with an error-controlled integrator
    (limits ignored, FACTS.md)."""
    if not (duration_s > 0 and dt_out > 0):
        raise DataError(f"duration_s and dt_out must be > 0, got {duration_s} and {dt_out}")
    t_out = np.arange(0.0, duration_s + 0.5 * dt_out, dt_out)
    return simulate_at(model, q0, v0, t_out, tau, discrete, v_eps)


def simulate_at(
    model: ArticulatedModel,
    q0,
    v0,
    t_out: np.ndarray,
    tau: Recording | None = None,
    discrete: bool = True,
    v_eps: float = V_EPS,
) -> Trajectory:
    """Like :func:`simulate` but sampled at the increasing times ``t_out`` (T,) [s], t_out[0] >= 0.
    The discrete plant starts from q0 clipped into the joints' position limits.  Once the replay
    rests past its last force sample (:func:`_at_rest`), the later outputs are that state, unstepped."""
    n = model.nq
    q0 = np.asarray(q0, dtype=float).reshape(-1)
    v0 = np.asarray(v0, dtype=float).reshape(-1)
    for name, a in (("q0", q0), ("v0", v0)):
        if a.shape != (n,):
            raise DataError(f"{name} must have shape ({n},) for joints {list(model.joint_names)}, got {a.shape}")
        require_finite(name, a)
    t_out = np.asarray(t_out, dtype=float)
    if t_out.ndim != 1 or t_out.size == 0 or t_out[0] < 0 or np.any(np.diff(t_out) <= 0):
        raise DataError("t_out must be a non-empty, strictly increasing array of times >= 0")
    if tau is not None:
        tau = model_ordered(model, tau)
        if tau.tau is None:
            raise DataError("the recording passed as tau has no tau:<joint> columns")

    dp = build_plant(model, discrete)
    plant = dp.plant
    if discrete:
        # A start outside the model's own limits (a measured q a noise-width past a fitted limit)
        # is no state of the model; the discrete plant's stiff limit constraint would kick it back
        # with a large impulse (a 0.7 mrad violation gave a door 0.6 rad/s).  Start on the limit.
        q0 = np.clip(q0, plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits())
    builder = DiagramBuilder()
    builder.AddSystem(plant)
    sources = []
    dynamics = [j.dynamics for j in model.movable_joints]
    if any(set(dynamics_effects(d)) - IN_PLANT for d in dynamics):
        # smooth-sign width: the dry-friction level (Coulomb + Stribeck excess) sets the slope
        dry = np.array([d.coulomb + d.stribeck for d in dynamics])
        eps = np.full(n, float(v_eps))
        if discrete:
            ctx = plant.CreateDefaultContext()
            plant.SetPositions(ctx, q0)
            M_diag = np.diag(plant.CalcMassMatrix(ctx))
            eps = np.maximum(eps, 4.0 * DISCRETE_TIME_STEP_S * dry / M_diag)
        sources.append(_joint_force_system(builder, plant, dynamics, eps, discrete))
    if tau is not None:
        lead = 0.5 * DISCRETE_TIME_STEP_S if discrete else 0.0
        sources.append(builder.AddSystem(TrajectorySource(_force_trajectory(tau, t_out[-1], lead))).get_output_port())
    if sources:
        port = sources[0]
        if len(sources) > 1:
            adder = builder.AddSystem(Adder(len(sources), n))
            for i, s in enumerate(sources):
                builder.Connect(s, adder.get_input_port(i))
            port = adder.get_output_port()
        builder.Connect(port, plant.get_applied_generalized_force_input_port())
    diagram = builder.Build()

    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, q0)
    plant.SetVelocities(plant_context, v0)
    if not discrete:
        simulator.get_mutable_integrator().set_target_accuracy(CONTINUOUS_ACCURACY)
    simulator.Initialize()

    q = np.empty((t_out.size, n))
    v = np.empty((t_out.size, n))
    # past the last force sample the inputs are constant, so a state at rest stays at rest
    inputs_end = float(tau.t[-1] - tau.t[0]) if tau is not None else 0.0
    start = time.perf_counter()
    for i, ti in enumerate(t_out):
        if ti > context.get_time():
            simulator.AdvanceTo(ti)
        q[i] = plant.GetPositions(plant_context)
        v[i] = plant.GetVelocities(plant_context)
        # (at least one plant step apart: between two steps a discrete state cannot change)
        if (i and t_out[i - 1] >= inputs_end and ti - t_out[i - 1] >= DISCRETE_TIME_STEP_S
                and _at_rest(q[i - 1 : i + 1], v[i - 1 : i + 1])):
            q[i + 1 :], v[i + 1 :] = q[i], v[i]
            break
    wall = time.perf_counter() - start
    return Trajectory(t_out, model.joint_names, q, v, mechanical_energy(model, q, v), wall)


REST_TOLERANCE = 1e-10
"""A replay whose q moved at most this much [rad or m] between two output times, with |v| at
most this much [rad/s or m/s] at both, is at rest (:func:`_at_rest`)."""


def _at_rest(q: np.ndarray, v: np.ndarray) -> bool:
    """Whether two consecutive output states (2, n) of a replay are one state at rest.

    The plant, its joint forces and (past its last sample) the applied force are time-invariant,
    so such a state is a fixed point (of the 1 ms step map; of the ODE for the continuous plant)
    and every later output equals it: a lid resting on its stop need not be stepped to the 50-s
    horizon (SAP, Drake's discrete solver, spends ~0.1 ms per step even on one joint: 5 s of the
    verification).  A joint creeping under smooth-sign friction, or settling towards rest, moves
    more than this and is stepped."""
    return bool(np.all(np.abs(np.diff(q, axis=0)) <= REST_TOLERANCE) and np.all(np.abs(v) <= REST_TOLERANCE))


IN_PLANT = frozenset({"viscous_damping", "spring"})
"""Joint force effects the Drake plant holds itself (joint damping, spring force elements)."""


def _joint_force_system(builder: DiagramBuilder, plant, dynamics, eps: np.ndarray, discrete: bool):
    """Output port of a symbolic system x = [q; v] -> per joint the sum of the force laws of its
    dynamics that are not :data:`IN_PLANT` (smooth sign of width ``eps`` (n,)), fed by the plant
    state.

    Evaluated in C++ (a Python LeafSystem cost ~3 s per 50 s of 1 ms steps).  Drake's
    SymbolicVectorSystem needs a state, so it carries one inert variable (z' = 0, or z+ = z with
    the plant's period in the discrete case so it adds no integrator events)."""
    nq, nv = plant.num_positions(), plant.num_velocities()
    x = [Variable(f"x{i}") for i in range(nq + nv)]
    z = Variable("inert")
    # numpy's object loops (tanh, exp, log on Drake expressions) report stale floating-point flags
    # as "invalid value" warnings; the expressions themselves are exact
    with np.errstate(invalid="ignore"):
        out = [_joint_force(d, x[i], x[nq + i], float(eps[i])) for i, d in enumerate(dynamics)]
    if discrete:
        system = SymbolicVectorSystem(state=[z], input=x, dynamics=[z], output=out,
                                      time_period=DISCRETE_TIME_STEP_S)
    else:
        system = SymbolicVectorSystem(state=[z], input=x, dynamics=[0.0 * z], output=out)
    builder.AddSystem(system)
    builder.Connect(plant.get_state_output_port(), system.get_input_port())
    return system.get_output_port()


def _joint_force(dynamics, q: Variable, v: Variable, eps: float) -> Expression:
    """The sum of the force laws of ``dynamics`` not :data:`IN_PLANT`, as a Drake expression."""
    return Expression(0.0) + np.asarray(dynamics.passive_force(Expression(q), Expression(v), IN_PLANT, eps)).item()


def _force_trajectory(tau: Recording, t_end: float, lead: float = 0.0) -> PiecewisePolynomial:
    """First-order hold of tau(t − t_0 + lead), extended to ``t_end`` by holding the last sample.

    lead [s]: the discrete plant samples its force input at the start of each step and holds it
    over the step; read half a step ahead, the held value of a first-order hold is its mean over
    the step, so each step gets the recording's impulse.  (Sampled at the start, a push that
    decays by 1.5 N·m/s gave a laptop lid 0.03 rad/s too much after 0.5 s at 1 ms steps.)"""
    t = tau.t - tau.t[0] - lead
    values = tau.tau
    if t_end > t[-1]:
        t = np.append(t, t_end + 1.0)
        values = np.vstack([values, values[-1]])
    return PiecewisePolynomial.FirstOrderHold(t, values.T)
