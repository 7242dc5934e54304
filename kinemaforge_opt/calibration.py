"""``calibrate``: fit chosen parameters of a model to a joint-space recording.

The library entry point for calibration inside control code::

    from kinemaforge_opt import calibrate, read_urdf
    from kinemaforge_opt.io.recording import read_recording
    cal = calibrate(read_urdf("door.urdf"), read_recording("rec.csv"),
                    free=["hinge.axis", "hinge.damping", "hinge.coulomb"])
    cal.success, cal.estimates["hinge.damping"].value, cal.model  # calibrated ArticulatedModel
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .errors import KinemaforgeError
from .io.recording import Recording
from .model.articulated import ArticulatedModel, Inertial
from .nlp.joint_space import JointSpaceFit, build_joint_space_fit, fit_spans, join_recordings, joined_words
from .nlp.parameters import FORCE_PARAMS
from .nlp.sensitivity import fit_sensitivity

_UNITS = {
    "damping": ("N*m*s/rad", "N*s/m"), "coulomb": ("N*m", "N"), "stribeck": ("N*m", "N"),
    "v_stribeck": ("rad/s", "m/s"), "spring_stiffness": ("N*m/rad", "N/m"), "spring_rest": ("rad", "m"),
    "bias": ("N*m", "N"), "drag": ("N*m*s^2/rad^2", "N*s^2/m^2"), "limit_stop": ("rad", "m"),
    "limit_stiffness": ("N*m/rad", "N/m"), "limit_damping": ("N*m*s/rad^2", "N*s/m^2"),
    "axis": ("1", "1"), "origin": ("m", "m"), "pitch": ("m/rad", "m/rad"),
    "armature": ("kg*m^2", "kg"), "inertia_ratio": ("1", "1"), "inertia": ("kg, kg*m, kg*m^2", "kg, kg*m, kg*m^2"), "gravity": ("m/s^2", "m/s^2"),
}


# The entries of a ``<link>.inertia`` block as the identifiability words spell them: Pinocchio's
# dynamic parameters about the link origin (model.pinocchio.DYNAMIC_PARAMETER_NAMES, same order).
_INERTIA_ENTRIES = ("mass", "m*cx", "m*cy", "m*cz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")


@dataclass(frozen=True)
class Estimate:
    """A fitted parameter block: value, nominal (prior) and 95 % interval, element-wise
    (shape (size,)); for an axis, ``ci95_angle_rad`` is the 95 % bound of its direction error.
    ``determined`` False: the block is part of a combination the recording cannot determine (the
    calibration's identifiability words name it); its interval is then no bound at all, and
    ``to_dict`` gives it as null."""

    name: str
    value: np.ndarray
    nominal: np.ndarray
    ci95_low: np.ndarray
    ci95_high: np.ndarray
    unit: str
    ci95_angle_rad: float | None = None
    determined: bool = True

    def to_dict(self) -> dict:
        d = {
            "name": self.name, "value": self.value.tolist(), "nominal": self.nominal.tolist(),
            "ci95": [self.ci95_low.tolist(), self.ci95_high.tolist()] if self.determined else None,
            "unit": self.unit, "determined": self.determined,
        }
        if self.ci95_angle_rad is not None:
            d["ci95_angle_rad"] = self.ci95_angle_rad if self.determined else None
        return d

    def interval_text(self) -> str:
        """"v [lo, hi]" per element (", "-joined), or the values and "(undetermined: see the notes)"."""
        if not self.determined:
            return ", ".join(f"{v:.4g}" for v in self.value) + " (undetermined: see the notes)"
        return ", ".join(f"{v:.4g} [{a:.4g}, {b:.4g}]" for v, a, b in zip(self.value, self.ci95_low, self.ci95_high))


@dataclass(frozen=True)
class Calibration:
    """The outcome of :func:`calibrate`.  ``success`` False means IPOPT did not converge
    (``status`` says how); the estimates are then IPOPT's last iterate."""

    success: bool
    status: str
    iterations: int
    estimates: dict[str, Estimate]
    model: ArticulatedModel
    effects: dict[str, tuple[str, ...]]
    identifiability: tuple[str, ...]
    costs: dict[str, float]
    violations: dict[str, float]
    rms_q: dict[str, float]
    q_fit: np.ndarray
    v_fit: np.ndarray
    recording: Recording
    solve_time_s: float

    def to_dict(self) -> dict:
        return {
            "success": self.success, "status": self.status, "iterations": self.iterations,
            "estimates": {k: e.to_dict() for k, e in self.estimates.items()},
            "effects": {k: list(v) for k, v in self.effects.items()},
            "identifiability": list(self.identifiability), "costs": self.costs,
            "violations": self.violations, "rms_q": self.rms_q, "solve_time_s": self.solve_time_s,
        }


def apply_parameters(model: ArticulatedModel, values: dict[str, np.ndarray],
                     stops: dict[str, tuple[float, float]] | None = None) -> ArticulatedModel:
    """A copy of ``model`` with the named parameter blocks set to ``values`` (physical units).
    stops: per joint, (side, initial position) of its limit-contact stop as the fit had it (side
    +1 upper, -1 lower); a fitted ``limit_stop`` takes that side (default: the side the joint's
    dynamics already hold)."""
    out = model
    for name, value in values.items():
        value = np.asarray(value, dtype=float)
        owner, field = name.rsplit(".", 1) if "." in name else ("", name)
        if field == "gravity" or name == "gravity":
            out = dataclasses.replace(out, gravity=value)
        elif field in FORCE_PARAMS:
            j = out.joint(owner)
            changes = {field: float(value[0])}
            if field == "limit_stop" and stops and owner in stops:
                changes["limit_side"] = float(stops[owner][0])
            out = out.with_joint(owner, dynamics=dataclasses.replace(j.dynamics, **changes))
        elif field == "axis":
            out = out.with_joint(owner, axis=value / np.linalg.norm(value))
        elif field == "origin":
            T = out.joint(owner).T_parent_joint.copy()
            T[:3, 3] = value
            out = out.with_joint(owner, T_parent_joint=T)
        elif field == "pitch":
            out = out.with_joint(owner, pitch=float(value[0]))
        elif field == "armature":
            j = out.joint(owner)
            out = out.with_joint(owner, dynamics=dataclasses.replace(j.dynamics, armature=float(value[0])))
        elif field == "inertia":
            out = out.with_link(owner, inertial=Inertial.from_dynamic_parameters(value))
        elif field == "inertia_ratio":
            base = model.link(owner).inertial
            out = out.with_link(owner, inertial=Inertial.from_dynamic_parameters(base.dynamic_parameters() * value[0]))
    return out


def calibrate(
    model: ArticulatedModel,
    recording: Recording | Sequence[Recording],
    free: tuple[str, ...] | list[str] | None = None,
    effects: dict[str, tuple[str, ...]] | None = None,
    energy: str = "soft",
    energy_weight: float = 1.0,
    max_iter: int = 300,
    print_level: int = 0,
    substeps: int = 1,
    friction_eps: float | None = None,
    method: str = "collocation",
    segment_s: float | None = None,
    on_iteration: Callable[[int, float], None] | None = None,
) -> Calibration:
    """Fit ``free`` parameters of ``model`` to ``recording`` (joint-space NLP, IPOPT).

    free: parameter names (``kinemaforge_opt.nlp.parameters``); default: viscous damping and
    Coulomb friction of every movable joint.  effects: extra force effects per joint.
    energy: "soft" | "hard" | "off" (see :mod:`kinemaforge_opt.nlp.joint_space`).
    method: "collocation" (output error on q by direct collocation; any recording) or
    "inverse_dynamics" (torque error through RNEA on filtered states; needs recorded tau, scales
    to long high-rate recordings such as a 1 kHz robot arm; :mod:`kinemaforge_opt.nlp.inverse_dynamics`).
    The fit reads the recording without isolated spikes and between the stops the model declares,
    whose force it has no law for (:func:`~kinemaforge_opt.nlp.joint_space.fit_span`;
    ``Calibration.recording`` is what was read, the identifiability words say what was left out).
    Several recordings of the same system are fitted together, one model for all, each followed
    from its own state: joined end to end with a pause between them that fits and derivatives do
    not cross (:func:`~kinemaforge_opt.nlp.joint_space.join_recordings`); ``Calibration.recording``
    and ``q_fit`` are then on that joined time axis.
    on_iteration: called with (IPOPT iteration, objective) after each iteration (a progress bar).
    What the recording cannot determine of a freed ``<link>.inertia`` (on one hinge: the mass, the
    first moment along it, the inertia about other axes) is that of the physical body nearest the
    model's with the rest as fitted; ``identifiability`` names those entries.
    Raises for bad input (unknown names, missing joints, no motion) before any work starts.
    """
    if method not in ("collocation", "inverse_dynamics"):
        raise KinemaforgeError(f"method must be 'collocation' or 'inverse_dynamics', got {method!r}")
    spans, left_out = fit_spans(model, recording)
    rec = join_recordings(spans)
    if len(spans) > 1:
        left_out += (joined_words(spans, rec),)
    if method == "inverse_dynamics":
        from .nlp.inverse_dynamics import calibrate_inverse_dynamics

        # Near-unidentifiable directions make IPOPT crawl: allow it more iterations.
        cal = calibrate_inverse_dynamics(model, rec, free=free, effects=effects, max_iter=max(max_iter, 1000),
                                         on_iteration=on_iteration)
    else:
        if free is None:
            free = [f"{j}.{p}" for j in model.joint_names for p in ("damping", "coulomb")]
        start = time.perf_counter()
        fit = build_joint_space_fit(
            model, rec, tuple(free), effects, energy=energy, energy_weight=energy_weight,
            substeps=substeps, friction_eps=friction_eps, segment_s=segment_s,
        )
        res = fit.problem.solve(max_iter=max_iter, print_level=print_level, on_iteration=on_iteration)
        X = res.values["x"]
        z = np.concatenate([np.atleast_1d(res.values[f"p:{b.name}"]) for b in fit.blocks]) if fit.blocks else np.zeros(0)
        cal = _result(fit, res, X, z, time.perf_counter() - start)
    return dataclasses.replace(cal, identifiability=left_out + cal.identifiability) if left_out else cal


def _undetermined_inertia(blocks, z: np.ndarray, null_z: np.ndarray) -> np.ndarray:
    """``z`` (scaled parameters, ``blocks`` order) with the combinations of each ``<link>.inertia``
    block that the recording cannot determine (``null_z`` (nz, k), the directions
    :attr:`~kinemaforge_opt.nlp.sensitivity.Sensitivity.null_z` lying within that block) chosen
    anew: the physical body nearest the model's (least log-det divergence of its pseudo-inertia,
    :func:`~kinemaforge_opt.nlp.inverse_dynamics.entropic_divergence`, over log-Cholesky
    parameters, so it stays physical) among those with the determined part as fitted.

    The inertial parameters enter the dynamics linearly, so such a combination changes nothing
    along any motion like the recorded one, and IPOPT leaves it wherever its steps took it: a
    laptop lid on a fixed hinge, its ten parameters free, came out at 97 kg and a rod at 162 kg
    (the mass alone moves no single hinge), dynamically the same.  Nor is the model's own value
    of such a combination always right: a rod whose hinge shows more first moment than the model's
    mass can carry at that inertia needs more mass to be a body at all.  If no physical body has the
    determined part (noise at the boundary), the least change from the model's values is taken.
    Combinations reaching other blocks (a free swing's damping with its inertia ratio) are left
    as fitted; the identifiability words name them."""
    import casadi as ca
    from scipy.linalg import null_space

    from .nlp.inverse_dynamics import dynamic_from_log_cholesky, entropic_divergence, log_cholesky_from_dynamic
    from .nlp.problem import Problem

    z = z.copy()
    offsets = np.cumsum([0] + [b.size for b in blocks])
    for b, o in zip(blocks, offsets):
        if not b.name.endswith(".inertia"):
            continue
        sl = slice(o, o + b.size)
        own = [k for k in range(null_z.shape[1]) if np.linalg.norm(np.delete(null_z[:, k], np.arange(o, o + b.size))) < 1e-9]
        if not own:
            continue
        N = null_z[sl, own]  # (10, k): what the recording cannot see, in this block's scaled coordinates
        Q = null_space(N.T)  # (10, 10 - k): what it determines
        x0 = log_cholesky_from_dynamic(b.nominal)
        prob = Problem("nearest_body")
        x = prob.variable("log_cholesky", 10, init=x0)
        prob.add_cost("divergence", entropic_divergence(x, x0))
        prob.add_constraint("determined", ca.mtimes(ca.DM(Q.T), dynamic_from_log_cholesky(x) / ca.DM(b.scale))
                            - ca.DM(Q.T @ z[sl]))
        res = prob.solve(tol=1e-10)
        if res.success:
            z[sl] = dynamic_from_log_cholesky(np.asarray(res.values["log_cholesky"]).ravel()) / b.scale
        else:
            dz = z[sl] - b.nominal / b.scale
            z[sl] = b.nominal / b.scale + dz - N @ np.linalg.lstsq(N, dz, rcond=None)[0]
    return z


def _result(fit: JointSpaceFit, res, X: np.ndarray, z: np.ndarray, elapsed: float) -> Calibration:
    model, rec = fit.model, fit.recording
    n = model.nq
    words: list[str] = []
    sens = fit_sensitivity(fit, X, z) if z.size else None
    if sens is not None:
        z = _undetermined_inertia(fit.blocks, z, sens.null_z)
    # blocks in a combination the data cannot determine ("hinge.axis[tilt 0]" -> "hinge.axis")
    undetermined = {label.split("[")[0] for combo in (sens.unidentifiable if sens else ()) for label in combo}
    estimates, values, offset = {}, {}, 0
    for b in fit.blocks:
        zb = z[offset : offset + b.size]
        value = np.clip(zb * b.scale, b.lower, b.upper)  # IPOPT may overstep bounds by ~1e-8
        if b.name.endswith(".axis"):
            value = value / np.linalg.norm(value)
        sd = np.sqrt(np.maximum(np.diag(sens.cov_z)[offset : offset + b.size], 0.0)) * b.scale if sens else np.zeros(b.size)
        angle = None
        if b.name.endswith(".axis") and sens is not None:
            C = sens.cov_z[offset : offset + 3, offset : offset + 3]
            angle = float(1.96 * np.sqrt(max(np.linalg.eigvalsh(C).max(), 0.0)))
        field = b.name.rsplit(".", 1)[-1]
        joint_or_link = b.name.rsplit(".", 1)[0]
        linear = joint_or_link in model.joint_names and model.joint(joint_or_link).type == "prismatic"
        unit = _UNITS.get(field, ("", ""))[1 if linear else 0]
        estimates[b.name] = Estimate(b.name, value, b.nominal, value - 1.96 * sd, value + 1.96 * sd, unit, angle,
                                     determined=b.name not in undetermined)
        values[b.name] = value
        offset += b.size
    if sens is not None:
        tilts: dict[str, int] = {}  # axis block -> its undetermined directions
        unseen_inertia: dict[str, list[str]] = {}  # link inertia block -> its undetermined entries
        for combo in sens.unidentifiable:
            blocks = {k.split("[")[0] for k in combo}
            if len(blocks) == 1 and next(iter(blocks)).endswith(".inertia"):
                entries = unseen_inertia.setdefault(next(iter(blocks)), [])
                entries += [_INERTIA_ENTRIES[int(k.split("[")[1][:-1])] for k in combo]
                continue
            if len(blocks) == 1 and all("[tilt" in k for k in combo):
                axis = blocks.pop()
                tilts[axis] = tilts.get(axis, 0) + 1
                continue
            names = ", ".join(f"{k} ({w:+.2f})" for k, w in combo.items())
            words.append(
                f"this recording cannot determine the combination {names}: only directions orthogonal to it "
                "are fitted (e.g. without applied forces, friction and damping are known only relative to inertia)"
            )
        for block, entries in unseen_inertia.items():
            words.append(
                f"this recording cannot determine {block} in {', '.join(dict.fromkeys(entries))} (alone or combined: "
                "no motion like the recorded one depends on them): they are those of the physical body nearest the "
                "model's that has the rest as fitted"
            )
        for axis, n_dirs in tilts.items():
            which = "in any direction" if n_dirs > 1 else "in one direction"
            words.append(
                f"this recording cannot determine {axis} {which}: tilting it so changes the motion by nothing "
                "to first order (e.g. a hinge turned about the vertical meets gravity alike)"
            )
        for name, e in estimates.items():
            half = (e.ci95_high - e.ci95_low) / 2
            rel = half / np.maximum(np.abs(e.value), 1e-12)
            if e.value.size == 1 and rel[0] > 1.0 and not name.endswith(".axis") and e.determined:
                words.append(f"{name} is poorly determined: {e.value[0]:.4g} ± {half[0]:.2g} {e.unit}")
    X = X[:, :: fit.substeps]
    rms = np.sqrt(np.mean((X[:n, :].T - rec.q) ** 2, axis=0))
    return Calibration(
        success=res.success, status=res.status, iterations=res.iterations, estimates=estimates,
        model=apply_parameters(model, values, fit.stop_side), effects=fit.effects, identifiability=tuple(words),
        costs=res.costs, violations=res.violations, rms_q=dict(zip(model.joint_names, map(float, rms))),
        q_fit=X[:n, :].T.copy(), v_fit=X[n:, :].T.copy(), recording=rec, solve_time_s=elapsed,
    )
