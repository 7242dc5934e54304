"""Drake verification of a reconstruction (the last stage of ``kinemaforge reconstruct``).

The reconstructed model is replayed in Drake under the recording's forcing and compared with the
motion the reconstruction measured:

1. the joint-space recording of the reconstruction (:mod:`.forcing`): q at every time step of
   the part tracks, τ from ``SEQ/wrenches.csv`` mapped to joint forces through the model (no
   wrenches: no τ, a free response from the first measured state).  Where the reconstruction
   measured its joint values with the images under its final joints (``OUT/measured_q.csv``, the
   screw NLP's ``measure`` stages: the visual term alone, every axis and origin held), q is that
   measurement at the steps the tracks observe: each track pose is a six-degree-of-freedom ICP
   fit of its own, and a pose off by a few millirad at one step — a door's track at the shut
   step, where the door lies flush with its carcass — puts that offset into every value since
   the zero step (protocol_cabinet_0@s1: 0.011 rad, its energy residual 0.027 where the true
   model reads 0.002; measured: 0.005);
2. the replay (:func:`.drift.drift`): Drake from the first measured q, under the full-rate τ, on
   the discrete 1 ms plant (joint limits enforced); the initial velocity is the one whose replay
   best matches the first 0.25 s (:func:`.drift.fit_initial_velocity`: finite differences of q
   at a visual rate are too coarse a velocity);
3. drift at each horizon h = 1, 5, 10, 20, 50 s after the first time step: the largest distance
   between where a moving link's origin or centre of mass is in the replay and where it is in
   the measured motion.  **Past the end of the recording** (``beyond_recording``) the measured
   motion is its last pose held and the replay keeps the last τ: the drift then says whether the
   model comes to rest where the real object did, the only observation there is.  The same
   replays with each moving link's mass and inertia 1 % up and down give ``drift_range_m``
   (:func:`.drift.drift_range`): a wide range marks a knife edge the drift cannot judge the fit by;
4. the energy residual of the measured motion under the model (:func:`.energy.energy_residual`),
   evaluated at the force's rate on a cubic spline of the measured q, broken at each stop impact
   the samples show (:func:`fine_motion`), over the spans where no joint is on one of the model's
   stops, less the measured intervals around each stop contact and each impact the samples show
   (the impact happened somewhere between two samples and the spline's error spreads to the next
   knots; ``energy_books_share``: the share of the recording left; a stop's impact work is not in
   the books).  On the synthetic protocol this took the true model's
   residual from 0.209 to 0.029 (a laptop lid slammed shut: 0.96 to 0.09).

Outputs in OUT: ``recording.csv`` (the joint-space recording, so ``diagnose`` and ``view`` can use
it), ``replay.csv`` (the Drake replay, same time base, up to the longest horizon), ``tracks.csv``
and ``measured_q.csv`` (when the tracks and the measurement come from memory),
``trajectories.png``, and ``reconstruction.json["verification"]`` = {"drift_m": {"1": …, "50":
…}, "energy_residual": …, …} written atomically with the rest of the document.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from ..errors import InputFileError
from ..io.atomic import write_text_atomic
from ..io.recording import Recording, read_recording, write_recording
from ..io.sequence import load_sequence
from ..io.tracks import PoseTracks, read_tracks, write_tracks
from ..model import ArticulatedModel, read_urdf
from ..stops import stop_impacts
from .drift import (DEFAULT_HORIZONS_S, MASS_SHARE, DriftReport, drift, drift_range, fit_initial_velocity,
                    per_horizon, range_record)
from .energy import energy_residual, free_segments
from .forcing import JointRecording, joint_recording
from .plot import plot_trajectories

MEASURED_Q = "measured_q.csv"
"""The reconstruction's joint values measured by the visual fit under its final joints (a
joint-space recording with q only, at the perception's time steps, in the model's coordinates)."""

DRIFT_DEFINITION = (
    "max over moving links' origins and centres of mass of |p_replay(t0+h) - p_measured(t0+h)| [m]; "
    "Drake replay from the first measured q (initial velocity fitted to the first 0.25 s) under the recorded "
    "forcing; past the recording's end "
    "the measured pose is its last one, held, and the last applied force is held"
)


def load_reconstruction(out: str | os.PathLike) -> tuple[ArticulatedModel, dict]:
    """(model, reconstruction.json document) of a reconstruct output folder; the error names the
    missing file."""
    out = Path(out)
    for name in ("model.urdf", "reconstruction.json"):
        if not (out / name).is_file():
            raise InputFileError(f"{out / name}: missing; {str(out)!r} is not the output of "
                                 "`kinemaforge reconstruct SEQ -o OUT`")
    try:
        doc = json.loads((out / "reconstruction.json").read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise InputFileError(f"{out / 'reconstruction.json'}: not valid JSON ({e})") from None
    return read_urdf(out / "model.urdf"), doc


def link_tracks(doc: dict, source: str = "reconstruction.json") -> dict[str, list[str]]:
    """link name -> its track names, from the document's ``links[].tracks``."""
    try:
        return {link["name"]: list(link.get("tracks", ())) for link in doc["links"]}
    except (KeyError, TypeError):
        raise InputFileError(f"{source}: field 'links' must be a list of {{'name', 'tracks'}}") from None


def load_clouds(out: str | os.PathLike) -> dict[str, np.ndarray]:
    """OUT/clouds.npz as link name -> (N, 3) points [m] (empty if the file is absent)."""
    path = Path(out) / "clouds.npz"
    if not path.is_file():
        return {}
    try:
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError) as e:
        raise InputFileError(f"{path}: not a readable .npz of per-link (N, 3) point arrays ({e})") from None


def reconstruction_recording(
    out: str | os.PathLike,
    sequence: str | os.PathLike,
    model: ArticulatedModel | None = None,
    doc: dict | None = None,
    tracks: PoseTracks | None = None,
    clouds: dict[str, np.ndarray] | None = None,
    measured: Recording | None = None,
) -> JointRecording:
    """The joint-space recording of the reconstruction in ``out`` (:mod:`.forcing`), with τ from
    ``sequence``/wrenches.csv.  Anything not given is read from ``out`` (model.urdf,
    reconstruction.json, tracks.csv, clouds.npz, and measured_q.csv where the reconstruction
    wrote one: module docs, step 1)."""
    out = Path(out)
    if model is None or doc is None:
        model, doc = load_reconstruction(out)
    if tracks is None:
        path = out / "tracks.csv"
        if not path.is_file():
            raise InputFileError(f"{path}: missing; the part tracks of the reconstruction are needed "
                                 "(re-run `kinemaforge reconstruct SEQ -o OUT`, which writes them)")
        tracks = read_tracks(path)
    if clouds is None:
        clouds = load_clouds(out)
    if measured is None:
        measured = load_measured(out)
    seq = load_sequence(sequence)
    return joint_recording(model, tracks, link_tracks(doc, str(out / "reconstruction.json")), seq.wrenches, clouds,
                           measured)


def load_measured(out: str | os.PathLike) -> Recording | None:
    """OUT/measured_q.csv (module docs, step 1), or None where the reconstruction wrote none."""
    path = Path(out) / MEASURED_Q
    return read_recording(path) if path.is_file() else None


def joint_values_source(joint_names: Sequence[str], measured: Recording | None) -> str:
    """Where the verified joint values come from (``verification.joint_values``): the measurement
    for the joints it holds, the tracks for the rest, naming them."""
    if measured is None:
        return "tracks.csv"
    text = f"{MEASURED_Q}: the visual fit under the final joints, at the steps the tracks observe"
    from_tracks = [n for n in joint_names if n not in measured.joint_names]
    return text + (f"; tracks.csv for {', '.join(from_tracks)} (not in {MEASURED_Q})" if from_tracks else "")


def fine_motion(jr: JointRecording) -> Recording:
    """The measured motion at the force's rate: q through a cubic spline (not-a-knot) of the measured
    steps, broken at each stop impact (:func:`impact_broken_spline`), v its derivative, τ the
    full-rate forcing, at the forcing's rows inside the measured span (without forcing: at the
    measured steps, τ none).  The energy books need ∫τ·v dt at the rate the force changes; a ~10 Hz
    finite-difference v misses most of a 0.8 s push (on a synthetic door with true physics:
    residual 0.094 at 8 Hz vs 0.019 this way, 0.020 from MuJoCo's own 120 Hz record)."""
    rec = jr.recording
    if jr.forcing is None:
        return Recording(rec.t, rec.joint_names, *impact_broken_spline(rec.t, rec.q, rec.t))
    keep = (jr.forcing.t >= rec.t[0]) & (jr.forcing.t <= rec.t[-1])
    t = jr.forcing.t[keep]
    return Recording(t, rec.joint_names, *impact_broken_spline(rec.t, rec.q, t), jr.forcing.tau[keep])


def impact_broken_spline(times: np.ndarray, q: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """q (T, n) [rad or m] measured at ``times`` (T,) [s], interpolated at ``t`` (M,) [s]: (q, v),
    each (M, n), from a not-a-knot cubic spline per joint, broken where the joint hit a stop
    (:func:`~kinemaforge_opt.stops.stop_impacts` on the measured steps): the samples
    before and after each impact get splines of their own and the interval holding the impact a
    straight line.  An impact is a kink of q; one spline through it rings for knots on either side
    (protocol_laptop_0's lid, slammed shut between 1.267 and 1.425 s at 8.8 rad/s: the spline had
    it falling at 4.1 rad/s at 1.108 s, MuJoCo at 2.8, and the true model's energy books 9 % out)."""
    q = np.asarray(q, dtype=float).reshape(times.size, -1)
    whole = CubicSpline(times, q, axis=0)
    fine_q, fine_v = whole(t), whole(t, 1)
    impacts = stop_impacts(times, q)
    for k in range(q.shape[1]):
        cuts = sorted({e.i for e in impacts if e.k == k})
        if not cuts:
            continue
        bounds = [0, *cuts, times.size]
        for a, b in zip(bounds[:-1], bounds[1:]):  # the samples a .. b-1 between impacts
            inside = (t >= times[a]) & (t <= times[b - 1])
            if b - a >= 2:
                piece = CubicSpline(times[a:b], q[a:b, k])
                fine_q[inside, k], fine_v[inside, k] = piece(t[inside]), piece(t[inside], 1)
            else:
                fine_q[inside, k], fine_v[inside, k] = q[a, k], 0.0
        for c in cuts:  # the interval that holds the impact
            inside = (t > times[c - 1]) & (t < times[c])
            slope = (q[c, k] - q[c - 1, k]) / (times[c] - times[c - 1])
            fine_q[inside, k] = q[c - 1, k] + slope * (t[inside] - times[c - 1])
            fine_v[inside, k] = slope
    return fine_q, fine_v


def replay_check(model: ArticulatedModel, jr: JointRecording, horizons_s=DEFAULT_HORIZONS_S,
                 discrete: bool = True, with_range: bool = False) -> tuple[dict, DriftReport]:
    """Steps 2-4 of the module docs for ``model`` on the joint recording ``jr``: (JSON-ready
    {drift_m, energy_residual, drift_definition, beyond_recording, max_drift_m, joint_rms, v0},
    the :class:`~.drift.DriftReport`).  ``with_range``: also ``drift_range_m``, {horizon: [least,
    largest]} over the replays with each moving link's mass and inertia scaled by 1 ± MASS_SHARE
    (:func:`.drift.drift_range`; two more replays per moving link)."""
    rec = jr.recording
    v0 = fit_initial_velocity(model, rec, jr.forcing, discrete=discrete)
    report = drift(model, rec, horizons_s, discrete=discrete, forcing=jr.forcing, v0=v0)
    fine = fine_motion(jr)
    residual = energy_residual(model, fine, sample_t=rec.t)
    books = sum(fine.t[b] - fine.t[a] for a, b in free_segments(model, fine.q, fine.v, t=fine.t, sample_t=rec.t))
    out = {
        "drift_m": per_horizon(report.horizons_s, report.drift_m),
        # None: the motion never leaves the model's stops, so no span has energy books to check
        "energy_residual": None if np.isnan(residual) else float(residual),
        "energy_books_share": float(books / max(fine.t[-1] - fine.t[0], 1e-12)),
        "drift_definition": DRIFT_DEFINITION,
        "beyond_recording": per_horizon(report.horizons_s, report.beyond_recording, bool),
        "max_drift_m": per_horizon(report.horizons_s, report.max_drift_m),
        "joint_rms": per_horizon(report.horizons_s, report.joint_rms),
        "v0": v0.tolist(),
    }
    if with_range:
        spread = drift_range(model, rec, horizons_s, discrete=discrete, forcing=jr.forcing, v0=v0)
        out["drift_range_m"] = range_record(report.horizons_s, spread)
        out["drift_range_definition"] = (f"least and largest drift_m over the replays with one moving link's mass "
                                         f"and inertia scaled by 1 ± {MASS_SHARE:g} (a wide range: a knife edge)")
    return out, report


def verify_model(model: ArticulatedModel, out: str | os.PathLike, sequence: str | os.PathLike,
                 horizons_s=DEFAULT_HORIZONS_S, discrete: bool = True, with_range: bool = False) -> dict:
    """The same check for another model of the reconstruction in ``out`` (e.g. the one diagnosis
    augmented; its joints must be the reconstruction's): the measured motion and forcing of
    ``out`` and ``sequence``, replayed with ``model``.  Writes nothing; returns
    :func:`replay_check`'s dict."""
    _, doc = load_reconstruction(out)
    jr = reconstruction_recording(out, sequence, model, doc)
    return replay_check(model, jr, horizons_s, discrete, with_range)[0]


def verify_reconstruction(
    out: str | os.PathLike,
    sequence: str | os.PathLike,
    reconstruction=None,
    horizons_s=DEFAULT_HORIZONS_S,
    discrete: bool = True,
    with_range: bool = False,
) -> dict:
    """Verify the reconstruction in ``out`` against ``sequence`` in Drake (module docs) and add the
    result to OUT/reconstruction.json as ``verification``; returns that dict.

    reconstruction: the in-memory :class:`~kinemaforge_opt.perception.reconstruct.Reconstruction`
    (its model, document, tracks and clouds are used and OUT/tracks.csv is written), or None to
    read everything from ``out``.  with_range: also the drift's range over ±1 % of each moving
    link's mass (``drift_range_m``, :func:`replay_check`)."""
    start = time.perf_counter()
    out = Path(out)
    if reconstruction is not None:
        model, doc = reconstruction.model, dict(reconstruction.document)
        tracks, clouds = reconstruction.perception.tracks, reconstruction.clouds_world
        measured = reconstruction.measured_q
        write_tracks(out / "tracks.csv", tracks)
        if measured is not None:
            write_recording(out / MEASURED_Q, measured)
        else:  # an earlier run's measurement is not this reconstruction's
            (out / MEASURED_Q).unlink(missing_ok=True)
    else:
        model, doc = load_reconstruction(out)
        tracks = clouds = None
        measured = load_measured(out)
    jr = reconstruction_recording(out, sequence, model, doc, tracks, clouds, measured)
    rec = jr.recording
    write_recording(out / "recording.csv", rec)
    checked, report = replay_check(model, jr, horizons_s, discrete, with_range)
    sim = report.simulated
    write_recording(out / "replay.csv", Recording(sim.t + rec.t[0], sim.joint_names, sim.q, sim.v))
    plot_trajectories(out / "trajectories.png", report.simulated, rec.t - rec.t[0], rec.q,
                      title=f"{model.name}: measured (dots) vs Drake replay")
    result = {
        **checked,
        "recording_duration_s": float(rec.t[-1] - rec.t[0]),
        "zero_step_t_s": float(rec.t[jr.values.zero_step]),
        "joint_zero_t_s": jr.values.zero_t,
        "forcing": "wrenches.csv" if jr.forcing is not None else "none (free response)",
        "contacts": [] if jr.wrenches is None else [
            {"link": link, "t_s": [float(jr.wrenches.t[a]), float(jr.wrenches.t[b])]}
            for a, b, link in jr.wrenches.contacts],
        "interpolated_samples": {n: int((~jr.values.observed[:, i]).sum()) for i, n in enumerate(model.joint_names)},
        "joint_values": joint_values_source(model.joint_names, measured),
        "plant": "discrete_1ms" if discrete else "continuous",
        "files": ["recording.csv", "replay.csv", "trajectories.png"],
        "timing_s": {"replay": report.simulated.wall_time_s, "total": time.perf_counter() - start},
    }
    doc["verification"] = result
    timing = dict(doc.get("timing_s", {}))
    previous = float(timing.get("verify", 0.0))  # a re-run replaces the earlier verification
    timing["verify"] = result["timing_s"]["total"]
    if "total" in timing:
        timing["total"] = float(timing["total"]) - previous + timing["verify"]
    doc["timing_s"] = timing
    write_text_atomic(out / "reconstruction.json", json.dumps(doc, indent=2))
    return result


def open_limits(model: ArticulatedModel) -> ArticulatedModel:
    """``model`` with every movable joint's position limits removed (effort and velocity kept).

    A reconstruction's limits are the observed range of motion (or where a joint rests against a
    stop it hit, :func:`~kinemaforge_opt.stops.stop_limits`), not stops the object is
    known to have: every joint reaches them by construction.  The mismatch discovery treats a
    declared stop as nominal physics and stops reading the recording there, so it gets the joints
    unlimited instead; a real stop in the data then shows as a ``limit_contact`` effect."""
    from ..model import JointLimits

    for j in model.movable_joints:
        if j.limits is not None:
            model = model.with_joint(j.name, limits=JointLimits(-np.inf, np.inf, j.limits.effort, j.limits.velocity))
    return model


def limits_from(model: ArticulatedModel, source: ArticulatedModel) -> ArticulatedModel:
    """``model`` with the position limits of ``source``'s joints of the same names."""
    for j in source.movable_joints:
        if j.name in model.joint_names:
            model = model.with_joint(j.name, limits=j.limits)
    return model
