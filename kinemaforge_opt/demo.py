"""The demos of ``kinemaforge demo``.

The main job (:func:`run_main_demo`, ``kinemaforge demo``): a procedurally generated cabinet door
with a viscous damper the nominal physics does not know is pushed by a hand and released,
simulated in MuJoCo (the independent ground-truth engine) and filmed by two RGB-D cameras with
D435-like noise.  From the RGB-D sequence alone kinemaforge_opt reconstructs the kinematic tree,
writes a URDF with meshes, replays it in Drake (drift and energy residual), runs the mismatch
discovery on the reconstruction and saves a meshcat scene; the summary compares with the
ground truth, which stays in its own folder and is read only for that comparison.

The joint-space calibration demo (:func:`run_demo`, ``kinemaforge demo --joint-space``): the same
door with a tilted hinge, damping and Coulomb friction, recorded in joint space at 30 Hz with
2 mrad encoder noise; the joint-space NLP on the Pinocchio→CasADi bridge (IPOPT) identifies the
axis and both coefficients and reports true vs estimated with 95 % intervals.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .io.atomic import write_text_atomic
from .io.recording import Recording, write_recording
from .spatial import axis_angle_error

if TYPE_CHECKING:  # loaded where the joint-space demo calibrates (CasADi, the bridge)
    from .calibration import Calibration


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


def hidden_physics_door(seed: int = 0, noise_rad: float = 2e-3, rate_hz: int = 30):
    """(nominal model, recording, truth, true axis) of the joint-space demo's door: a procedurally
    generated cabinet door whose hinge is tilted 3° and which has viscous damping 0.2 N·m·s/rad and
    Coulomb friction 0.3 N·m, none of it in the nominal model; simulated in MuJoCo, one hand stroke
    recorded at ``rate_hz`` (q with ``noise_rad`` [rad] of noise, and the hand's joint torque).
    truth: {"tilt_rad", "damping", "coulomb"}; true axis: (3,) the tilted hinge in the parent frame."""
    from .synth.effects import ConcealedEffect, true_model
    from .synth.groundtruth import HandPlan, simulate
    from .synth.objects import make_object

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
    return model, rec, truth, true_model(model, effects).joint(joint).axis


def run_demo(out_dir: str | Path, seed: int = 0, noise_rad: float = 2e-3, rate_hz: int = 30) -> DemoReport:
    """Simulate (:func:`hidden_physics_door`), identify, and write ``out_dir/{model.urdf,
    recording.csv, calibrated.urdf, demo.json}``.  Deterministic for a given ``seed``."""
    from .calibration import calibrate
    from .model import write_urdf

    out_dir = Path(out_dir)
    model, rec, truth, true_axis = hidden_physics_door(seed, noise_rad, rate_hz)
    joint = model.movable_joints[0].name
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


# --- the main job: RGB-D -> URDF -> Drake -> diagnosis -> scene -----------------------------------

class NoJointFound(RuntimeError):
    """The demo's reconstruction found nothing that moves (a result, not bad input: exit 1)."""


DEMO_DAMPING = 0.8
"""The concealed viscous damping of the main demo's door [N·m·s/rad]."""


DEMO_SIZE = {"frames": 30, "width": 320, "height": 240, "views": 2}
"""The main demo's episode: RGB-D time steps, image size [px], static cameras."""


def demo_case(seed: int = 0, views: int = DEMO_SIZE["views"], frames: int = DEMO_SIZE["frames"],
              width: int = DEMO_SIZE["width"], height: int = DEMO_SIZE["height"]):
    """The main demo's synthetic case: a procedural cabinet (seed 0: the single door of the
    catalogue's ``effect_door_*`` cases) with a concealed viscous damper on its first door, the
    catalogue's hand plan (a 0.8 s push to 60 % of the range, released, 2.2 s free; the door
    reaches its stop), 120 Hz forces, ``frames`` RGB-D time steps from ``views`` static cameras."""
    from .synth.case import Case
    from .synth.effects import ConcealedEffect
    from .synth.objects import make_object

    joint = make_object("cabinet", seed).model.movable_joints[0].name
    effects = (ConcealedEffect("viscous_damping", joint, DEMO_DAMPING),)
    return Case("demo_door_damped", "cabinet", seed, effects, views=views, frames=frames, width=width,
                height=height, expected=f"a revolute door joint; diagnose finds viscous damping ≈ {DEMO_DAMPING:g}")


@dataclass(frozen=True)
class MainDemoReport:
    """What the main demo did.  joints: per reconstructed joint, its record plus ``axis_error_deg``
    and ``origin_error_m`` against the matched true joint (None when unmatched).
    verification: reconstruction.json's verification; verification_diagnosed: the same check of the
    model the diagnosis augmented (None when it added nothing).  effects: the diagnosis' effects (dicts).
    truth_effects: the concealed effects.  timing_s: per stage.  paths: what was written where."""

    joints: list[dict]
    verification: dict
    verification_diagnosed: dict | None
    effects: list[dict]
    truth_effects: list[dict]
    diagnosis_summary: str
    timing_s: dict[str, float]
    paths: dict[str, Path]

    def summary(self) -> str:
        from .verify.report import energy_text

        lines = ["reconstructed joints (errors against the ground truth):"]
        for j in self.joints:
            err = ("  (no true joint left to match: spurious)" if j.get("axis_error_deg") is None else
                   f"  axis error {j['axis_error_deg']:.2f}°, origin error {100 * j['origin_error_m']:.1f} cm "
                   f"(true joint {j['true_joint']})")
            lines.append(f"  {j['name']}: {j['type']} {j['parent']} -> {j['child']}{err}")
            if j.get("dynamics"):
                lines.append("    fitted by the screw NLP: " + _dynamics_words(j))
        v = self.verification

        def drift(check: dict) -> str:
            return ", ".join(f"{h} s {100 * d:.1f} cm" + ("*" if v["beyond_recording"][h] else "")
                             for h, d in check["drift_m"].items())

        lines.append(f"Drake verification: drift {drift(v)}; energy residual {energy_text(v['energy_residual'], '.3f')}")
        lines.append(f"  (* past the {v['recording_duration_s']:.1f} s recording: distance to its last pose, held)")
        lines.append("mismatch discovery on the reconstruction:")
        lines += ["  " + line for line in self.diagnosis_summary.splitlines()]
        truth = ", ".join(f"{e['type']} = {e['value']:g} {e.get('unit', '')} on {e['joint']}" for e in self.truth_effects)
        lines.append(f"  concealed in the ground truth: {truth or 'nothing'}")
        a = self.verification_diagnosed
        if a is None:
            lines.append("Drake verification of the diagnosed model: no effect was added (same model as above)")
        else:
            lines.append(f"Drake verification of the diagnosed model: drift {drift(a)}; energy residual "
                         f"{energy_text(a['energy_residual'], '.3f')}")
        lines.append("time per stage: " + ", ".join(f"{k} {v:.1f} s" for k, v in self.timing_s.items()))
        lines.append("files:")
        for k, p in self.paths.items():
            lines.append(f"  {k:15s} {p}")
        return "\n".join(lines)


def _true_lines(true_model, q: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """joint name -> (axis_world, origin_world) of the true model at q."""
    import pinocchio as pin

    from .model.pinocchio import build_pin_model

    pm = build_pin_model(true_model, check_dynamics=False)
    data = pm.createData()
    pin.forwardKinematics(pm, data, q)
    out = {}
    for j in true_model.movable_joints:
        T = data.oMi[pm.getJointId(j.name)]
        out[j.name] = (T.rotation @ (np.asarray(j.axis) / np.linalg.norm(j.axis)), T.translation.copy())
    return out


def _dynamics_words(joint: dict) -> str:
    """The joint's fitted damping and Coulomb friction with the NLP's verdict on each, e.g.
    "damping 0.61 N·m·s/rad (identified), Coulomb 0.23 N·m (not identified)"."""
    units = {"revolute": ("N·m·s/rad", "N·m"), "prismatic": ("N·s/m", "N")}
    damping_unit, coulomb_unit = units.get(joint["type"], ("", ""))
    status = joint.get("identifiability", {})
    words = []
    for key, label, unit in (("damping", "damping", damping_unit), ("coulomb", "Coulomb", coulomb_unit)):
        verdict = status.get(f"{key}:{joint['name']}", {}).get("status")
        words.append(f"{label} {joint['dynamics'][key]:.3g} {unit}"
                     + (f" ({verdict.replace('_', ' ')})" if verdict else ""))
    return ", ".join(words)


def _match_joints(records: list[dict], true_lines: dict, true_types: dict) -> list[dict]:
    """Each reconstructed movable joint with the closest true joint (axis error + origin error,
    greedily, each true joint used once)."""
    from .bench.metrics import origin_error_m
    from .spatial import axis_angle_error

    pairs = []
    for r in records:
        if r["type"] == "fixed":
            continue
        for name, (a, o) in true_lines.items():
            ang = axis_angle_error(np.asarray(r["axis_world"]), a)
            if true_types[name] == "prismatic":
                dist = 0.0  # a slider's line is only a direction
            else:
                dist = origin_error_m(np.asarray(r["axis_world"]), np.asarray(r["origin_world"]), o)
            pairs.append((ang + dist, r["name"], name, ang, dist))
    used_r, used_t, match = set(), set(), {}
    for _, rn, tn, ang, dist in sorted(pairs):
        if rn in used_r or tn in used_t:
            continue
        used_r.add(rn)
        used_t.add(tn)
        match[rn] = (tn, ang, dist)
    out = []
    for r in records:
        m = match.get(r["name"])
        out.append({**r, "true_joint": m and m[0], "axis_error_deg": m and float(np.rad2deg(m[1])),
                    "origin_error_m": m and float(m[2])})
    return out


def run_main_demo(out_dir: str | Path, seed: int = 0, frames: int = DEMO_SIZE["frames"],
                  width: int = DEMO_SIZE["width"], height: int = DEMO_SIZE["height"], say=print) -> MainDemoReport:
    """Generate the demo episode into OUT/episode, reconstruct it into OUT/reconstruction (URDF,
    meshes, reconstruction.json with the Drake verification, recording.csv, scene.html), diagnose
    the reconstruction into OUT/diagnosis; ``say`` gets one line per stage."""
    import dataclasses
    import shutil
    import time

    from .commands.view import write_scene
    from .io.recording import read_recording
    from .model import read_urdf
    from .perception.reconstruct import reconstruct_sequence
    from .physics.diagnose import diagnose
    from .physics.report import write_diagnosis
    from .synth.generate import generate_case
    from .verify.reconstruction import limits_from, open_limits, verify_model, verify_reconstruction

    out_dir = Path(out_dir)
    timing = {}
    case = demo_case(seed, frames=frames, width=width, height=height)
    t0 = time.perf_counter()
    say(f"1/5 generating the episode: a cabinet door with a hidden damper, pushed and released; "
        f"{case.views} RGB-D cameras {case.width}×{case.height}, {case.frames} time steps (MuJoCo + ray casting) …")
    paths = generate_case(case, out_dir / "episode")
    timing["generate"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    say("2/5 reconstructing from the RGB-D sequence alone (clouds -> parts -> tracks -> graph -> URDF) …")
    rec_dir = out_dir / "reconstruction"
    rec = reconstruct_sequence(paths.sequence, rec_dir)
    timing["reconstruct"] = time.perf_counter() - t0
    for warning in rec.document["graph_warnings"]:
        say(f"    warning: {warning['message']}")
    if not rec.model.movable_joints:
        raise NoJointFound(f"the reconstruction in {rec_dir} found no movable joint: nothing to verify or diagnose "
                           f"(try more --frames or a larger --size)")

    t0 = time.perf_counter()
    say("3/5 verifying in Drake (replay under the recorded hand force) …")
    verification = verify_reconstruction(rec_dir, paths.sequence, reconstruction=rec)
    timing["verify"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    say("4/5 diagnosing the reconstruction (locate -> explain -> model -> re-fit) …")
    recording = read_recording(rec_dir / "recording.csv")
    d = diagnose(open_limits(rec.model), recording)
    d = dataclasses.replace(d, model=limits_from(d.model, rec.model))
    diag_dir = out_dir / "diagnosis"
    written = write_diagnosis(d, recording, diag_dir)
    shutil.copytree(rec_dir / "meshes", diag_dir / "meshes", dirs_exist_ok=True)
    timing["diagnose"] = time.perf_counter() - t0

    after = None
    if d.effects:
        t0 = time.perf_counter()
        say("    … and the diagnosed model verified in Drake the same way")
        after = verify_model(d.model, rec_dir, paths.sequence)
        write_text_atomic(diag_dir / "verification.json", json.dumps(after, indent=2))
        timing["verify diagnosed"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    say("5/5 writing the meshcat scene …")
    scene = write_scene(rec_dir)
    timing["scene"] = time.perf_counter() - t0

    true_model = read_urdf(paths.true_urdf)
    truth_rec = read_recording(paths.recording)
    t_zero = verification["zero_step_t_s"]  # the reconstruction's q = 0
    q_true = np.array([np.interp(t_zero, truth_rec.t, truth_rec.q[:, k]) for k in range(true_model.nq)])
    truth_doc = json.loads(Path(paths.effects).read_text(encoding="utf-8"))
    identifiability = rec.document.get("nlp", {}).get("identifiability", {})
    joints = _match_joints([{**j, "identifiability": {k: v for k, v in identifiability.items()
                                                      if k.endswith(":" + j["name"])}}
                            for j in rec.document["joints"]],
                           _true_lines(true_model, q_true),
                           {j.name: j.type for j in true_model.movable_joints})
    diag_doc = json.loads(Path(written["diagnosis"]).read_text(encoding="utf-8"))
    report = MainDemoReport(
        joints, verification, after, diag_doc.get("effects", []), truth_doc.get("effects", []), d.summary(), timing,
        {"URDF": rec_dir / "model.urdf", "report": rec_dir / "reconstruction.json",
         "diagnosis": Path(written["diagnosis"]), "diagnosed URDF": diag_dir / "model.urdf", "scene": scene, "plots": rec_dir / "trajectories.png",
         "truth": paths.root / "ground_truth"},
    )
    write_text_atomic(out_dir / "demo.json", json.dumps(
        {"joints": joints, "verification": verification, "verification_diagnosed": after, "effects": report.effects, "truth_effects": report.truth_effects,
         "timing_s": timing, "paths": {k: str(v) for k, v in report.paths.items()}}, indent=2))
    return report
