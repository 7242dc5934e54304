"""``kinemaforge diagnose MODEL.urdf RECORDING.csv -o OUT``: locate, explain, model, show."""

from __future__ import annotations

import argparse

EPILOG = """\
what it does:
  1. fits the nominal model and locates the residual (joint, time windows, state regions);
  2. tests the effect library (viscous_damping, coulomb_friction, stribeck_friction, spring,
     constant_bias, quadratic_drag, axis_tilt, inertia_error) as competing hypotheses and keeps
     those with ΔBIC < -10 that move the fit by more than the noise;
  3. re-fits with them and writes the augmented model;
  4. compares nominal vs augmented on the held-out last part of the recording and in Drake.

outputs: OUT/diagnosis.json, OUT/model.urdf, OUT/residual_time.png, OUT/residual_state.png,
         OUT/fit_before_after.png

example:
  kinemaforge diagnose models/furuta/furuta.urdf qube.csv -o out/qube
"""


def register(sub) -> None:
    p = sub.add_parser(
        "diagnose",
        help="find the physics a model leaves out of a recording, model it, show the fit improve",
        description="Locate where RECORDING.csv and MODEL.urdf disagree, name the missing physics "
        "with values and 95%% intervals, re-fit, and show the held-out improvement.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", help="URDF of the nominal model")
    p.add_argument("recording", help="recording.csv (t, q:<joint>, optional v:, tau:)")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument("--holdout", type=float, default=0.25, help="fraction held out at the end (default 0.25)")
    p.add_argument("--no-drift", action="store_true", help="skip the Drake drift comparison")
    p.add_argument("--segment", type=float, default=None, metavar="S",
                   help="fit and predict in segments of S seconds (long oscillating recordings)")
    p.add_argument("--other", nargs="*", default=(), metavar="CSV",
                   help="further recordings of the same system, used only to compare predictions")
    p.set_defaults(func=run)


def run(args) -> int:
    from tqdm import tqdm

    from ..io.recording import read_recording
    from ..model import read_urdf
    from ..physics.diagnose import diagnose
    from ..physics.report import write_diagnosis

    from ..nlp.joint_space import match_recording

    model = read_urdf(args.model)
    rec = read_recording(args.recording)
    match_recording(model, rec)  # bad input fails before any work (and before the progress bar)
    bar = tqdm(desc="diagnose", unit="fit", leave=False)

    def progress(msg: str) -> None:
        bar.set_postfix_str(msg)
        bar.update(1)

    others = tuple(read_recording(p) for p in args.other)
    for other in others:
        match_recording(model, other)
    d = diagnose(model, rec, holdout_fraction=args.holdout, progress=progress, segment_s=args.segment,
                 other_recordings=others)
    bar.close()
    paths = write_diagnosis(d, rec, args.out, with_drift=not args.no_drift)
    print(d.summary())
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
