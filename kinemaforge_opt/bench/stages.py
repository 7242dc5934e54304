"""The non-discovery parts of the benchmark: the graph stage on the real Sturm logs, calibration
accuracy and time on the demo door, time per stage, and how ``calibrate``'s time grows with the
number of samples."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

STURM_TYPES = {"left_door": "revolute", "right_door": "revolute", "dishwasher": "revolute", "drawer": "prismatic"}


def shared_data_dir() -> Path:
    """The shared real recordings: ``../shared/data`` beside the repository (override with
    KINEMAFORGE_SHARED_DATA)."""
    env = os.environ.get("KINEMAFORGE_SHARED_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[3] / "shared" / "data"


def sturm_logs(root: Path | None = None) -> dict:
    """Joint-type accuracy and fitted radii [m] on the real Sturm articulation logs, per
    mechanism; the folder is the ground-truth type.  Empty dict if the data is absent."""
    from ..graph import infer_tree
    from ..io.tracks import read_sturm_log

    base = (root or shared_data_dir()) / "real" / "articulation" / "mechanisms_iros_2010"
    out = {}
    for kind, want in STURM_TYPES.items():
        logs = sorted((base / kind).glob("*.log"))
        if not logs:
            continue
        types, radii, times = [], [], []
        for log in logs:
            t0 = time.perf_counter()
            (j, *_) = infer_tree(read_sturm_log(log)).best.joints
            times.append(time.perf_counter() - t0)
            types.append(j.type)
            if j.hypothesis.radius is not None:
                radii.append(j.hypothesis.radius)
        out[kind] = {"logs": len(logs), "true_type": want, "correct": sum(t == want for t in types),
                     "types": types, "radius_mean_m": float(np.mean(radii)) if radii else None,
                     "radius_std_m": float(np.std(radii)) if radii else None, "time_per_log_s": float(np.mean(times))}
    return out


def demo_door(seeds: tuple[int, ...], rate_hz: int = 30) -> list[dict]:
    """Calibration accuracy and time on the demo door (3° tilt, damping 0.2, Coulomb 0.3) for
    each object/noise seed: axis error [deg], relative damping and friction errors, IPOPT time."""
    import tempfile

    from ..demo import run_demo

    rows = []
    for seed in seeds:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            rep = run_demo(tmp, seed=seed, rate_hz=rate_hz)
            wall = time.perf_counter() - t0
        e, j = rep.calibration.estimates, rep.joint
        rows.append({
            "seed": seed, "converged": rep.calibration.success, "axis_error_deg": rep.axis_error_deg,
            "damping": float(e[f"{j}.damping"].value[0]), "damping_true": rep.truth["damping"],
            "damping_rel_error": abs(e[f"{j}.damping"].value[0] - rep.truth["damping"]) / rep.truth["damping"],
            "coulomb": float(e[f"{j}.coulomb"].value[0]), "coulomb_true": rep.truth["coulomb"],
            "coulomb_rel_error": abs(e[f"{j}.coulomb"].value[0] - rep.truth["coulomb"]) / rep.truth["coulomb"],
            "solve_time_s": rep.calibration.solve_time_s, "wall_time_s": wall,
            "samples": int(rep.calibration.recording.t.size),
        })
    return rows


def calibrate_scaling(rates_hz: tuple[int, ...]) -> dict:
    """``calibrate`` time vs number of samples: the demo door episode recorded at each rate
    (same 2.5 s motion, 2 mrad noise), damping + Coulomb + axis free.  Returns the points and
    the exponent p of time ∝ samples^p (least squares in log-log)."""
    from ..calibration import calibrate
    from ..io.recording import Recording
    from ..synth.effects import ConcealedEffect
    from ..synth.groundtruth import simulate
    from ..synth.objects import make_object
    from .recordings import NOISE, stroke_plan

    obj = make_object("cabinet", 0)
    joint = obj.model.movable_joints[0].name
    effects = (ConcealedEffect("axis_tilt", joint, np.deg2rad(3.0), (("azimuth", 0.6),)),
               ConcealedEffect("viscous_damping", joint, 0.2), ConcealedEffect("coulomb_friction", joint, 0.3))
    points = []
    for hz in rates_hz:
        ep = simulate(obj.model, obj.handles, effects, plan=stroke_plan(), record_hz=hz)
        q = ep.q + np.random.default_rng(0).normal(0.0, NOISE, ep.q.shape)
        rec = Recording(ep.t, ep.joint_names, q, tau=ep.tau)
        cal = calibrate(obj.model, rec, free=[f"{joint}.axis", f"{joint}.damping", f"{joint}.coulomb"])
        points.append({"rate_hz": hz, "samples": int(ep.t.size), "time_s": cal.solve_time_s,
                       "iterations": cal.iterations, "converged": cal.success})
    n = np.log([p["samples"] for p in points])
    t = np.log([p["time_s"] for p in points])
    exponent = float(np.polyfit(n, t, 1)[0]) if len(points) > 1 else None
    return {"points": points, "exponent": exponent}
