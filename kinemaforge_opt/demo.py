"""The main job on embedded default data (``kinemaforge demo``).

A procedurally generated cabinet door whose true hinge is tilted and which has viscous damping and
Coulomb friction that the nominal model does not know, driven by a hand and released, simulated
in MuJoCo (the independent ground-truth engine) and sampled at 30 Hz with 2 mrad encoder noise.
kinemaforge_opt then identifies the axis and both coefficients with the joint-space NLP on the
Pinocchio→CasADi bridge (IPOPT), and reports true vs estimated with 95 % intervals.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .calibration import Calibration, calibrate
from .io.atomic import write_text_atomic
from .io.recording import Recording, write_recording
from .model import write_urdf
from .spatial import axis_angle_error


@dataclass(frozen=True)
class DemoReport:
    """True vs estimated values of the demo, plus the calibration and where files went."""

    truth: dict[str, float]
    calibration: Calibration
    axis_error_deg: float
    out_dir: Path

    def table(self) -> str:
        e = self.calibration.estimates
        j = self.joint
        rows = [
            ("axis tilt error [deg]", "0", f"{self.axis_error_deg:.3f}",
             f"≤ {np.rad2deg(e[f'{j}.axis'].ci95_angle_rad or 0):.3f}"),
            ("viscous damping [N·m·s/rad]", f"{self.truth['damping']:.3f}", f"{e[f'{j}.damping'].value[0]:.3f}",
             "[{:.3f}, {:.3f}]".format(e[f"{j}.damping"].ci95_low[0], e[f"{j}.damping"].ci95_high[0])),
            ("Coulomb friction [N·m]", f"{self.truth['coulomb']:.3f}", f"{e[f'{j}.coulomb'].value[0]:.3f}",
             "[{:.3f}, {:.3f}]".format(e[f"{j}.coulomb"].ci95_low[0], e[f"{j}.coulomb"].ci95_high[0])),
        ]
        head = f"{'parameter':30s} {'true':>8s} {'estimated':>10s}  95% interval"
        return "\n".join([head] + [f"{a:30s} {b:>8s} {c:>10s}  {d}" for a, b, c, d in rows])

    @property
    def joint(self) -> str:
        return next(iter(self.calibration.effects))


def run_demo(out_dir: str | Path, seed: int = 0, noise_rad: float = 2e-3, rate_hz: int = 30) -> DemoReport:
    """Simulate, identify, and write ``out_dir/{model.urdf, recording.csv, calibrated.urdf,
    demo.json}``.  Deterministic for a given ``seed``."""
    from .synth.effects import ConcealedEffect
    from .synth.groundtruth import HandPlan, simulate
    from .synth.objects import make_object

    out_dir = Path(out_dir)
    obj = make_object("cabinet", seed)
    model = obj.model
    joint = model.movable_joints[0].name
    truth = {"tilt_rad": np.deg2rad(3.0), "damping": 0.2, "coulomb": 0.3}
    effects = (
        ConcealedEffect("axis_tilt", joint, truth["tilt_rad"], (("azimuth", 0.6),)),
        ConcealedEffect("viscous_damping", joint, truth["damping"]),
        ConcealedEffect("coulomb_friction", joint, truth["coulomb"]),
    )
    # One stroke that stays inside the joint range: the stop (a different effect) is never reached.
    plan = HandPlan(goals=(0.5,), push_s=0.8, free_s=1.7, release_speed=0.15)
    episode = simulate(model, obj.handles, effects, plan=plan, record_hz=rate_hz)
    rng = np.random.default_rng(seed)
    q = episode.q + rng.normal(0.0, noise_rad, episode.q.shape)
    rec = Recording(episode.t, episode.joint_names, q, tau=episode.tau)

    from .synth.effects import true_model

    true_axis = true_model(model, effects).joint(joint).axis
    cal = calibrate(model, rec, free=[f"{joint}.axis", f"{joint}.damping", f"{joint}.coulomb"])
    err = np.rad2deg(axis_angle_error(cal.estimates[f"{joint}.axis"].value, true_axis))

    out_dir.mkdir(parents=True, exist_ok=True)
    write_urdf(model, out_dir / "model.urdf")
    write_recording(out_dir / "recording.csv", rec)
    write_urdf(cal.model, out_dir / "calibrated.urdf")
    report = DemoReport(truth, cal, float(err), out_dir)
    write_text_atomic(
        out_dir / "demo.json",
        json.dumps({"truth": truth, "axis_error_deg": report.axis_error_deg, "calibration": cal.to_dict()}, indent=2),
    )
    return report
