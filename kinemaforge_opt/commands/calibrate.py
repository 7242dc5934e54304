"""``kinemaforge calibrate MODEL.urdf RECORDING.csv -o OUT``."""

from __future__ import annotations

import argparse
import json

EPILOG = """\
parameter names (--free, comma separated):
  <joint>.damping  .coulomb  .stribeck  .v_stribeck  .spring_stiffness  .spring_rest
  <joint>.bias  .drag  .axis  .origin  .pitch  .armature
  <link>.inertia (10 inertial parameters)  <link>.inertia_ratio (one scale of them)  gravity
default: <joint>.damping and <joint>.coulomb for every joint in the model.

several recordings of the same system (--also): fitted together, one model for all, each
followed from its own state (joined end to end with a pause the fit does not cross); what one
recording cannot determine another may (a free swing fixes no inertia scale, a push does).
They must record the same joints at sample rates within a factor of 2.

examples:
  kinemaforge calibrate models/laptop/laptop.urdf rec.csv -o out/cal \\
      --free hinge.axis,hinge.damping,hinge.coulomb,hinge.spring_stiffness,hinge.spring_rest
  kinemaforge calibrate door.urdf swing.csv --also push.csv -o out/cal --free hinge.damping,rod.inertia_ratio
"""


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="fit joint dynamics / axes / inertias of a URDF to a joint-space recording",
        description="Fit the chosen parameters of MODEL.urdf to RECORDING.csv (t, q:<joint>, "
        "optional v:<joint>, tau:<joint>) with a CasADi/IPOPT collocation NLP on Pinocchio's ABA. "
        "Writes OUT/model.urdf (calibrated) and OUT/calibration.json (estimates, 95 % intervals, "
        "identifiability notes).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", help="URDF of the nominal model")
    p.add_argument("recording", help="recording.csv")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument("--also", nargs="+", default=(), metavar="CSV",
                   help="further recordings of the same system, fitted together with RECORDING.csv")
    p.add_argument("--free", default=None, help="comma-separated parameter names (see below)")
    p.add_argument("--energy", choices=("soft", "hard", "off"), default="soft",
                   help="energy balance as a soft penalty, a hard constraint, or off (default soft)")
    p.add_argument("--substeps", type=int, default=1, help="collocation intervals per sample (default 1)")
    p.add_argument("--method", choices=("collocation", "inverse_dynamics"), default="collocation",
                   help="output error by collocation (any recording) or torque error by inverse "
                   "dynamics (needs recorded tau; long high-rate robot recordings)")
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from ..calibration import calibrate
    from ..io.atomic import write_text_atomic
    from ..io.recording import read_recording
    from ..model import read_urdf, write_urdf

    model = read_urdf(args.model)
    recs = [read_recording(p) for p in (args.recording, *args.also)]
    free = [s.strip() for s in args.free.split(",") if s.strip()] if args.free else None
    from ..nlp.joint_space import fit_spans, join_recordings

    join_recordings(fit_spans(model, recs)[0])  # names the joint or recording at fault before any work
    print(f"calibrating {sum(len(r.t) for r in recs)} samples × {len(recs[0].joint_names)} joints"
          + (f" from {len(recs)} recordings" if len(recs) > 1 else "") + " …", flush=True)
    from tqdm import tqdm

    with tqdm(desc="calibrate", unit="it", leave=False) as bar:  # one tick per IPOPT iteration
        def progress(iteration: int, objective: float) -> None:
            bar.set_postfix_str(f"objective {objective:.4g}", refresh=False)
            bar.update(1)

        cal = calibrate(model, recs, free=free, energy=args.energy, substeps=args.substeps, method=args.method,
                        on_iteration=progress)
    print(f"IPOPT: {cal.iterations} iterations, {cal.solve_time_s:.1f} s")
    out = Path(args.out)
    write_urdf(cal.model, out / "model.urdf")
    write_text_atomic(out / "calibration.json", json.dumps(cal.to_dict(), indent=2))
    for name, e in cal.estimates.items():
        print(f"  {name:28s} {e.interval_text()} {e.unit}")
    for line in cal.identifiability:
        print(f"  note: {line}")
    print(f"{'converged' if cal.success else 'NOT converged: ' + cal.status}; wrote {out}/model.urdf, {out}/calibration.json")
    return 0 if cal.success else 1
