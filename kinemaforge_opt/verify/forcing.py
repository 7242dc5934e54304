"""From a reconstruction to a joint-space recording: joint values from part pose tracks, and the
applied forces of ``wrenches.csv`` mapped to joint forces through the model.

Joint values (:func:`joint_values`).  Each link of the model is followed by one *representative*
pose track: of the tracks listed for it (``reconstruction.json`` ``links[].tracks``), the one
observed most often (the first such in the list on ties); the root link stays at the world frame.
The *zero step* s0 is the first time step at which every moving link's representative is
observed (the reconstruction's convention: q = 0 there); where no step sees them all, a link
unseen at s0 takes its zero pose from the nearest step that sees it with its parent
(:func:`~kinemaforge_opt.io.tracks.zero_configuration`; its joint is 0 there).  For a joint from
parent P to child C, with T_world_P(t), T_world_C(t) the representatives' poses (identity for
the root) and T_world_P⁰, T_world_C⁰ their poses at q = 0,

    M(t) = T_world_P(t)⁻¹ T_world_C(t),    D(t) = M(t) M⁰⁻¹   (the child's motion since q = 0,
                                                               expressed in P's track frame;
                                                               M⁰ = (T_world_P⁰)⁻¹ T_world_C⁰)
    a_P = (R_world_P⁰)ᵀ a_world                               (the joint axis in that frame)
    revolute / helical:  q(t) = twist of R_D(t) about a_P, on the branch its position gives   [rad]
    prismatic:           q(t) = (p_M(t) − p_M⁰) · a_P                                          [m]

with a_world the joint axis in the world at q = 0 (forward kinematics of the model).  Where the
joint values were measured otherwise (a reconstruction's visual fit under its final joints,
``measured`` of :func:`joint_values`), those values replace the tracks' at the steps the tracks
observe.  Steps at which a joint's two tracks are not both observed are filled by linear
interpolation in time and reported.  The values span the steps from the first at which every
joint is measured to the last (where no step measures them all, those that measure the most):
before and after, a value could only be held, and a held value is no measurement (a door whose
track starts late, pushed open while it was near shut, held at its first tracked angle under the
push's force, replayed 6.6 cm off within a second).

A track's *orientation* can be off by a half-turn: registration fits a symmetric part (a door or
lid slab, a drawer front) equally well turned over, and a tracker may switch between the fits.
On protocol_microwave_0 the door's track turned by π about the hinge direction (q jumped by π, the
replay drifted 0.43 m); on protocol_microwave_1 it turned over about horizontal axes (R_D then
holds no rotation about the hinge at all).  The track's *position* (a point of the part) has no
such ambiguity, so it decides:

* prismatic: the displacement of the child track's origin, not the translation of D (which a
  turned-over orientation carries off by up to twice the origin's lever arm); equal when the
  orientation is constant;
* revolute / helical: q_pos(t) = ∠(u⊥(s0), u⊥(t)) about a_P, the angle the child track's origin
  sweeps about the joint line (u⊥ its offset from the line c_P, perpendicular to a_P), unwrapped.
  Where R_D keeps a_P upright (a_P · R_D a_P > 0: not turned over across the axis), q is R_D's
  twist about a_P on the half-turn branch nearest q_pos, twist + π round((q_pos − twist)/π): the
  orientation gives the value, finer than q_pos (biased by the joint origin's error and the
  centroid's drift, ~0.1 rad on that door); elsewhere q = q_pos.  When the origin lies near the
  line (its radius, at s0 or typically, within 3 RMS of its scatter about the mean radius, or a
  micrometre) q_pos says nothing: q is the unwrapped twist of the upright steps, and a turned-over
  step counts as unobserved.

Joint forces (:func:`map_wrenches`).  A wrench row is a force f (N) at a world point p (m) but
does not say which link it pushes.  The rows are cut into *contacts*: runs of non-zero force whose
point moves less than :data:`CONTACT_JUMP_M` between rows.  Each contact is given to the link that
carries its point best: the smallest ``spread + distance``, where spread is the RMS scatter of p
expressed in the link's frame over the contact (a grip moves with its link: ~0 on the right link)
and distance the median distance from p to the link's point cloud (when clouds are given; it
decides when nothing moves).  Then τ(t) = J_p(q(t))ᵀ f(t), J_p the (3, n) Jacobian of the link's
material point at p (Pinocchio, world-aligned), q(t) linearly interpolated from the joint values.

The recording (:func:`joint_recording`) keeps the tracks' time steps (the q measured there) and
gives each step the mean τ over the wrench rows closest to it (the midpoints to its neighbours
bound the window), so the force's impulse survives a coarse visual rate; the full-rate τ is
returned as well, for the Drake replay.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ..errors import DataError
from ..io.recording import Recording
from ..io.sequence import Wrenches
from ..io.tracks import PoseTracks, zero_configuration
from ..model import ArticulatedModel
from ..model.pinocchio import build_pin_model
from ..spatial import rms_radius

CONTACT_JUMP_M = 0.05
"""A wrench point moving further than this between two rows starts a new contact [m] (a hand
moving 5 cm in one row at ≥ 30 Hz would be faster than 1.5 m/s: it let go and grabbed again)."""

CLOUD_POINTS = 20000
"""Points per link cloud used for the wrench-to-link distance (evenly strided; a reconstruction's
cloud holds millions, and the median distance needs only the surface's extent)."""

FORCE_EPS_N = 1e-9
"""Rows whose force norm is at most this [N] apply nothing (they end a contact)."""


@dataclass(frozen=True, eq=False)
class JointValues:
    """Joint values measured from pose tracks.

    t: (T,) the tracks' times over the measured span (module docs) [s].  joint_names: the
    model's movable joints (q order).
    q: (T, n) joint values [rad or m], q = 0 at the zero step.  observed: (T, n) bool, False
    where the value was filled by interpolation.  zero_step: index of s0.
    representatives: link name -> the track that follows it (None for the root).
    zero_t: joint name -> the time [s] at which it is 0 (s0's, but where its child is unseen at
    s0, the step its zero pose was taken at: module docs)."""

    t: np.ndarray
    joint_names: tuple[str, ...]
    q: np.ndarray
    observed: np.ndarray
    zero_step: int
    representatives: dict[str, str | None]
    zero_t: dict[str, float]


@dataclass(frozen=True, eq=False)
class MappedWrenches:
    """Wrench rows as joint forces.  t: (W,) [s]; tau: (W, n) [N·m or N];
    link: (W,) the link each row pushes (None where the force is zero);
    contacts: one (first row, last row, link) per contact."""

    t: np.ndarray
    tau: np.ndarray
    link: np.ndarray
    contacts: tuple[tuple[int, int, str], ...]


@dataclass(frozen=True, eq=False)
class JointRecording:
    """recording: q at the tracks' steps and the windowed mean τ (module docs).
    forcing: τ at the wrench rows (q interpolated there), for simulation; None without wrenches.
    values, wrenches: the two stages' results."""

    recording: Recording
    forcing: Recording | None
    values: JointValues
    wrenches: MappedWrenches | None


def _representative(tracks: PoseTracks, members: Sequence[str], link: str) -> int:
    known = [m for m in members if m in tracks.names]
    if not known:
        raise DataError(f"link {link!r}: none of its tracks {list(members)} is in the tracks "
                        f"(tracks: {', '.join(tracks.names)})")
    obs = tracks.observed().sum(axis=1)
    best = max(obs[tracks.names.index(m)] for m in known)
    return next(tracks.names.index(m) for m in known if obs[tracks.names.index(m)] == best)


def joint_values(model: ArticulatedModel, tracks: PoseTracks, link_tracks: Mapping[str, Sequence[str]],
                 measured: Recording | None = None) -> JointValues:
    """q per track time step for every movable joint of ``model`` (module docs).

    measured: joint values measured otherwise at the tracks' times (a reconstruction's visual fit
    under its final joints, ``measured_q.csv``), in the model's own coordinates; each joint it
    holds takes them at the steps its tracks observe instead of the tracks' values (the steps,
    the span and the zero step stay the tracks').

    link_tracks: link name -> the names of the tracks that move with it (the root's may be
    omitted).  The zero configuration is :func:`~kinemaforge_opt.io.tracks.zero_configuration`'s
    (the reconstruction's).  Raises :class:`DataError` naming the link or joint when a moving
    link has no track, tracks have no orientation, a link is never seen with its parent, a joint
    is seen at fewer than two steps, or ``measured`` names a joint the model lacks."""
    if measured is not None and (unknown := [n for n in measured.joint_names if n not in model.joint_names]):
        raise DataError(f"the measured joint values name {', '.join(map(repr, unknown))}, not a movable joint of the "
                        f"model; its joints: {', '.join(model.joint_names)}")
    if not tracks.has_orientation:
        raise DataError("joint values need full-pose tracks (x,y,z,qx,qy,qz,qw); these are position-only")
    root = model.root.name
    moving = [j.child for j in model.joints]
    reps: dict[str, int | None] = {root: None}
    for link in moving:
        if link not in link_tracks:
            raise DataError(f"link {link!r} has no tracks listed; links with tracks: {', '.join(link_tracks)}")
        reps[link] = _representative(tracks, link_tracks[link], link)
    obs = tracks.observed()
    T = tracks.times.size
    zero = zero_configuration(tracks, reps, {j.child: j.parent for j in model.joints})
    s0 = zero.step

    def poses(link: str) -> tuple[np.ndarray, np.ndarray]:
        k = reps.get(link)
        if k is None:
            return np.broadcast_to(np.eye(4), (T, 4, 4)), np.ones(T, dtype=bool)
        return tracks.Ts_world_track(k), obs[k]

    pm = build_pin_model(model, check_dynamics=False)
    data = pm.createData()
    pin.forwardKinematics(pm, data, np.zeros(model.nq))
    q = np.zeros((T, model.nq))
    observed = np.zeros((T, model.nq), dtype=bool)
    for i, j in enumerate(model.movable_joints):
        jid = pm.getJointId(j.name)
        a_world = data.oMi[jid].rotation @ (np.asarray(j.axis, dtype=float) / np.linalg.norm(j.axis))
        Tp, op = poses(j.parent)
        Tc, oc = poses(j.child)
        ok = op & oc
        if ok.sum() < 2:
            raise DataError(f"joint {j.name!r}: its parent {j.parent!r} and child {j.child!r} are seen together "
                            f"at {int(ok.sum())} time step(s); at least 2 are needed")
        idx = np.flatnonzero(ok)
        M = np.linalg.inv(Tp[idx]) @ Tc[idx]
        M0 = np.linalg.inv(zero.poses[j.parent]) @ zero.poses[j.child]  # the child in its parent at q = 0
        a_P = zero.poses[j.parent][:3, :3].T @ a_world
        if j.type == "prismatic":
            qi = (M[:, :3, 3] - M0[:3, 3]) @ a_P
        else:
            c_P = (np.linalg.inv(zero.poses[j.parent]) @ np.r_[data.oMi[jid].translation, 1.0])[:3]
            qi, valid = _revolute_values((M @ np.linalg.inv(M0))[:, :3, :3], M[:, :3, 3] - c_P, M0[:3, 3] - c_P, a_P)
            idx, qi = idx[valid], qi[valid]
            if idx.size < 2:
                raise DataError(f"joint {j.name!r}: the track of {j.child!r} is turned over about an axis across "
                                f"the joint at all but {idx.size} step(s), and its position lies on the joint line")
            qi -= 2 * np.pi * np.round(np.interp(zero.steps[j.child], idx, qi) / (2 * np.pi))
        if measured is not None and j.name in measured.joint_names:
            qi = _measured_at(measured, j.name, tracks.times[idx])
        q[:, i] = np.interp(np.arange(T), idx, qi)
        observed[idx, i] = True
    names = {link: (None if k is None else tracks.names[k]) for link, k in reps.items()}
    # the measured span: before the first step at which every joint is measured (or after the
    # last) a value would be held, not measured; where no step measures them all, the steps that
    # measure the most
    count = observed.sum(axis=1)
    every = np.flatnonzero(count == count.max())
    first, last = min(every[0], s0), max(every[-1], s0)
    if last - first < 1:
        raise DataError(f"the joints {', '.join(model.joint_names)} are measured together at fewer than 2 time steps")
    span = slice(first, last + 1)
    zero_t = {j.name: float(tracks.times[zero.steps[j.child]]) for j in model.movable_joints}
    return JointValues(tracks.times[span].copy(), model.joint_names, q[span], observed[span], s0 - first, names, zero_t)


def _measured_at(measured: Recording, joint: str, t: np.ndarray) -> np.ndarray:
    """(N,) ``joint``'s measured values at the times ``t`` (N,) [s], each one of ``measured``'s
    own times; raises :class:`DataError` naming the first time it lacks."""
    rows = np.searchsorted(measured.t, t).clip(0, measured.t.size - 1)
    missing = ~np.isclose(measured.t[rows], t, rtol=0.0, atol=1e-9)
    if missing.any():
        raise DataError(f"the measured joint values have no sample at t = {t[missing][0]:.6g} s, a time "
                        f"step of the tracks (joint {joint!r})")
    return measured.q[rows, measured.joint_names.index(joint)]


POSITION_FLOOR_M = 1e-6
"""Scatter floor [m] below which a track origin's radius about a joint line is numerical noise."""


def _revolute_values(R_D: np.ndarray, u: np.ndarray, u0: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q (N,) [rad], valid (N,) bool) of a revolute joint from the child's rotations since the zero
    step R_D (N, 3, 3) and its track origin's offsets u (N, 3) from a point of the joint line (u0
    (3,) at the zero step) [m], all in the parent's track frame; axis (3,) unit (module docs)."""
    quat = Rotation.from_matrix(R_D).as_quat()  # (x, y, z, w)
    twist = 2 * np.arctan2(quat[:, :3] @ axis, quat[:, 3])
    twist = (twist + np.pi) % (2 * np.pi) - np.pi
    upright = np.einsum("i,nij,j->n", axis, R_D, axis) > 0
    u_perp = u - np.outer(u @ axis, axis)
    u0_perp = u0 - (u0 @ axis) * axis
    r, r0 = np.linalg.norm(u_perp, axis=1), float(np.linalg.norm(u0_perp))
    scatter = max(float(np.sqrt(np.mean((r - r.mean()) ** 2))), POSITION_FLOOR_M)
    if min(r0, float(np.median(r))) <= 3 * scatter:  # the position says nothing about the angle
        q = np.full(len(R_D), np.nan)
        q[upright] = np.unwrap(twist[upright])
        return q, upright
    q_pos = np.unwrap(np.arctan2(np.cross(u0_perp, u_perp) @ axis, u_perp @ u0_perp))
    q = np.where(upright, twist + np.pi * np.round((q_pos - twist) / np.pi), q_pos)
    return q, np.ones(len(R_D), dtype=bool)


def _contacts(w: Wrenches) -> list[tuple[int, int]]:
    """(first, last) row index of each run of non-zero force with a continuous point."""
    active = np.linalg.norm(w.forces_world, axis=1) > FORCE_EPS_N
    jump = np.r_[True, np.linalg.norm(np.diff(w.points_world, axis=0), axis=1) > CONTACT_JUMP_M]
    out, start = [], None
    for r in range(len(w.t)):
        if start is not None and (not active[r] or jump[r]):
            out.append((start, r - 1))
            start = None
        if active[r] and start is None:
            start = r
    if start is not None:
        out.append((start, len(w.t) - 1))
    return out


def _strided(points: np.ndarray, n: int) -> np.ndarray:
    """At most ``n`` of the (N, 3) ``points``, evenly strided (deterministic)."""
    return points if len(points) <= n else points[np.linspace(0, len(points) - 1, n).astype(int)]


def map_wrenches(
    model: ArticulatedModel,
    t_q: np.ndarray,
    q: np.ndarray,
    wrenches: Wrenches,
    clouds_world: Mapping[str, np.ndarray] | None = None,
) -> MappedWrenches:
    """Joint forces τ (W, n) of the wrench rows (module docs).

    t_q: (T,) [s] and q: (T, n) the joint values, interpolated linearly to the wrench times
    (held outside).  clouds_world: optional link name -> (N, 3) points of the link at q = 0 [m]
    (``clouds.npz``), used to tell links apart when the wrench point does not move."""
    q = np.asarray(q, dtype=float).reshape(len(t_q), model.nq)
    tw = np.asarray(wrenches.t, dtype=float)
    qw = np.column_stack([np.interp(tw, t_q, q[:, k]) for k in range(model.nq)]) if model.nq else np.zeros((len(tw), 0))
    pm = build_pin_model(model, check_dynamics=False)
    data = pm.createData()
    links = list(model.link_names)
    fids = [pm.getFrameId(name) for name in links]
    P, F = np.asarray(wrenches.points_world, dtype=float), np.asarray(wrenches.forces_world, dtype=float)
    trees = {name: cKDTree(_strided(np.asarray(c, dtype=float), CLOUD_POINTS)) for name, c in (clouds_world or {}).items()
             if name in links and len(c)}
    # every link's pose at q = 0 (the clouds' configuration) and at each row
    T0 = {}
    pin.framesForwardKinematics(pm, data, np.zeros(model.nq))
    for name, fid in zip(links, fids):
        T0[name] = data.oMf[fid].homogeneous.copy()
    tau = np.zeros((len(tw), model.nq))
    link_of = np.full(len(tw), None, dtype=object)
    contacts = []
    for first, last in _contacts(wrenches):
        rows = np.arange(first, last + 1)
        local = {name: np.empty((len(rows), 3)) for name in links}
        for r_i, r in enumerate(rows):
            pin.framesForwardKinematics(pm, data, qw[r])
            for name, fid in zip(links, fids):
                local[name][r_i] = data.oMf[fid].actInv(P[r])
        score = {}
        for name in links:
            spread = rms_radius(local[name])
            dist = 0.0
            if name in trees:  # the point carried back to q = 0, against the link's cloud there
                p0 = local[name] @ T0[name][:3, :3].T + T0[name][:3, 3]
                dist = float(np.median(trees[name].query(p0)[0]))
            score[name] = spread + dist
        link = min(score, key=score.get)
        fid = fids[links.index(link)]
        for r in rows:
            pin.computeJointJacobians(pm, data, qw[r])
            pin.framesForwardKinematics(pm, data, qw[r])
            J = pin.getFrameJacobian(pm, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            r_op = P[r] - data.oMf[fid].translation
            J_p = J[:3] - pin.skew(r_op) @ J[3:]  # v_p = v_o + ω × (p − o)
            tau[r] = J_p.T @ F[r]
        link_of[rows] = link
        contacts.append((int(first), int(last), link))
    return MappedWrenches(tw, tau, link_of, tuple(contacts))


def window_means(t_out: np.ndarray, t_in: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(T, k) mean of ``values`` (W, k) over the rows of ``t_in`` (W,) nearest each time of
    ``t_out`` (T,): the window of t_out[i] runs between the midpoints to its neighbours (the ends
    extend by half the first/last interval).  A window holding no row takes the value linearly
    interpolated at t_out[i]."""
    t_out = np.asarray(t_out, dtype=float)
    mid = 0.5 * (t_out[1:] + t_out[:-1])
    lo = np.r_[t_out[0] - (mid[0] - t_out[0]) if len(mid) else -np.inf, mid]
    hi = np.r_[mid, t_out[-1] + (t_out[-1] - mid[-1]) if len(mid) else np.inf]
    out = np.empty((len(t_out), values.shape[1]))
    for i in range(len(t_out)):
        m = (t_in >= lo[i]) & (t_in < hi[i])
        if m.any():
            out[i] = values[m].mean(axis=0)
        else:
            out[i] = [np.interp(t_out[i], t_in, values[:, k]) for k in range(values.shape[1])]
    return out


def joint_recording(
    model: ArticulatedModel,
    tracks: PoseTracks,
    link_tracks: Mapping[str, Sequence[str]],
    wrenches: Wrenches | None = None,
    clouds_world: Mapping[str, np.ndarray] | None = None,
    measured: Recording | None = None,
) -> JointRecording:
    """The joint-space recording of a reconstruction (module docs): q from ``tracks`` (or, at the
    steps they observe, from ``measured``: :func:`joint_values`) and, when ``wrenches`` are given,
    τ from them; times span the steps where every joint is measured."""
    values = joint_values(model, tracks, link_tracks, measured)
    if wrenches is None:
        rec = Recording(values.t, values.joint_names, values.q)
        return JointRecording(rec, None, values, None)
    mapped = map_wrenches(model, values.t, values.q, wrenches, clouds_world)
    tau = window_means(values.t, mapped.t, mapped.tau)
    rec = Recording(values.t, values.joint_names, values.q, tau=tau)
    # the forcing starts at the first track time (simulations start there)
    tw = np.r_[values.t[0], mapped.t[mapped.t > values.t[0]]]
    tau_w = np.column_stack([np.interp(tw, mapped.t, mapped.tau[:, k]) for k in range(model.nq)])
    qw = np.column_stack([np.interp(tw, values.t, values.q[:, k]) for k in range(model.nq)])
    forcing = Recording(tw, values.joint_names, qw, tau=tau_w) if len(tw) >= 2 else None
    return JointRecording(rec, forcing, values, mapped)
