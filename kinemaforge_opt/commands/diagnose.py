"""``kinemaforge diagnose MODEL.urdf RECORDING.csv -o OUT`` or ``kinemaforge diagnose RECON_OUT
--sequence SEQ -o OUT``: locate, explain, model, show."""

from __future__ import annotations

import argparse

EPILOG = """\
what it does:
  1. fits the nominal model and locates the residual (joint, time windows, state regions);
  2. tests the effect library (viscous_damping, coulomb_friction, spring, constant_bias,
     quadratic_drag, stribeck_friction, axis_tilt, inertia_error, limit_contact) as competing
     hypotheses and keeps those with ΔBIC < -10 that move the fit by more than the noise;
  3. re-fits with them and writes the augmented model;
  4. compares nominal vs augmented on the held-out last part of the recording and in Drake.
  When the fit stays far above the noise with any effect (model-form error the library cannot
  express), the effects must also predict data outside the fit better: the held-out span if the
  nominal model errs there by 3 noise sigmas or more, else the first --other recording that does
  (it is then not independent; the summary and diagnosis.json "acceptance_check" say which).
  With --other, an effect that is strong by ΔBIC but smaller than that model-form error is
  accepted only if it predicts the first such --other recording better by more than the noise.

several recordings of the same system (--also): fitted together, one model for all, each
  followed from its own state (joined end to end with a pause the fits do not cross), each with
  its own held-out last part; windows and plots are on the joined time axis (the summary gives
  where each recording starts).  What one recording cannot determine another may: a free swing
  fixes no inertia scale, a push does.  Unlike --other, these recordings shape the fit.

on a reconstruction (first argument = a folder written by `kinemaforge reconstruct SEQ -o R`):
  the joint-space recording is built from it: q per time step as the images show it under the
  joints of R/model.urdf (R/measured_q.csv, at the steps the part tracks R/tracks.csv observe; from
  the tracks themselves where the reconstruction wrote no measurement) and tau from SEQ/wrenches.csv mapped
  to joint forces through the model (each contact given to the link that carries its point);
  it is written to OUT/recording.csv, R/meshes is copied to OUT/meshes, then as above, except
  that the joints are searched without position limits (a reconstruction's limits are only the
  observed range; a real stop in the data shows as limit_contact); OUT/model.urdf keeps them.

outputs: OUT/diagnosis.json, OUT/model.urdf, OUT/residual_time.png, OUT/residual_state.png,
         OUT/fit_before_after.png, OUT/other_<k>_before_after.png per --other recording
         (+ OUT/recording.csv, OUT/meshes/ on a reconstruction, and
         OUT/verification.json: the augmented model through the reconstruction's Drake check,
         when an effect was added)

examples:
  kinemaforge diagnose models/furuta/furuta.urdf qube.csv -o out/qube
  kinemaforge diagnose models/furuta/furuta.urdf qube1.csv --also qube2.csv --other qube3.csv -o out/q
  kinemaforge reconstruct seq -o out/rec && kinemaforge diagnose out/rec --sequence seq -o out/diag
"""


def register(sub) -> None:
    p = sub.add_parser(
        "diagnose",
        help="find the physics a model leaves out of a recording, model it, show the fit improve",
        description="Locate where RECORDING.csv and MODEL.urdf disagree, name the missing physics "
        "with values and 95% intervals, re-fit, and show the held-out improvement.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", metavar="MODEL.urdf|RECON_OUT",
                   help="URDF of the nominal model, or a `kinemaforge reconstruct` output folder")
    p.add_argument("recording", nargs="?", metavar="RECORDING.csv",
                   help="recording.csv (t, q:<joint>, optional v:, tau:); not with a reconstruction folder")
    p.add_argument("--sequence", metavar="SEQ", default=None,
                   help="the RGB-D sequence a reconstruction folder was made from (its wrenches.csv gives tau)")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument("--holdout", type=float, default=0.25, help="fraction held out at the end (default 0.25)")
    p.add_argument("--no-drift", action="store_true", help="skip the Drake drift comparison")
    p.add_argument("--segment", type=float, default=None, metavar="S",
                   help="fit and predict in segments of S seconds (long oscillating recordings)")
    p.add_argument("--max-effects", type=int, default=None, metavar="N",
                   help="stop the selection after N effects (default: physics.selection.MAX_EFFECTS)")
    p.add_argument("--also", nargs="+", default=(), metavar="CSV",
                   help="further recordings of the same system, fitted together with RECORDING.csv (see below)")
    p.add_argument("--other", nargs="*", default=(), metavar="CSV",
                   help="further recordings of the same system: compared before/after; under model-form error "
                        "the first one with signal also judges acceptance (see below)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="processes that fit a selection round's hypotheses side by side (default: the CPUs "
                        "this process may use, or OMP_NUM_THREADS; 1: all in this process); the findings do "
                        "not depend on it")
    p.add_argument("--cpu-cap", type=float, default=None, metavar="S",
                   help="IPOPT CPU-time cap of each hypothesis fit [s] (default: 100 derivative evaluations, at "
                        "least 1 s); 'inf' for none: the findings are then the same on every machine, but a "
                        "hypothesis stuck in IPOPT's restoration phase can take minutes")
    p.set_defaults(func=run)


def run(args) -> int:
    from tqdm import tqdm

    from ..errors import InputFileError
    from ..physics.selection import MAX_EFFECTS

    if args.max_effects is not None and args.max_effects < 1:
        raise InputFileError(f"--max-effects must be at least 1, got {args.max_effects}")

    from ..io.recording import read_recording
    from ..physics.diagnose import diagnose
    from ..physics.report import write_diagnosis

    from ..nlp.joint_space import fit_spans, join_recordings, match_recording

    model, rec, reconstructed = _inputs(args)
    nominal = model
    if reconstructed:  # its limits are the observed range, not known stops (verify.reconstruction.open_limits)
        from ..verify.reconstruction import open_limits

        model = open_limits(model)
    recs = [rec] + [read_recording(p) for p in args.also]
    join_recordings(fit_spans(model, recs)[0])  # bad input fails before any work (and before the progress bar)
    bar = tqdm(desc="diagnose", unit="fit", leave=False)

    def progress(msg: str) -> None:
        bar.set_postfix_str(msg)
        bar.update(1)

    others = tuple(read_recording(p) for p in args.other)
    for other in others:
        match_recording(model, other)
    d = diagnose(model, recs, holdout_fraction=args.holdout, progress=progress, segment_s=args.segment,
                 other_recordings=others, max_effects=args.max_effects or MAX_EFFECTS, workers=args.workers,
                 cpu_cap_s=args.cpu_cap)
    bar.close()
    if reconstructed:
        import dataclasses

        from ..verify.reconstruction import limits_from

        d = dataclasses.replace(d, model=limits_from(d.model, nominal))
    paths = write_diagnosis(d, rec, args.out, with_drift=not args.no_drift)
    print(d.summary())
    if reconstructed and not args.no_drift and d.effects:  # the augmented model through the reconstruction's Drake check
        import json
        from pathlib import Path

        from ..io.atomic import write_text_atomic
        from ..verify.reconstruction import verify_model
        from ..verify.report import energy_text

        after = verify_model(d.model, args.model, args.sequence)
        paths["verification"] = Path(args.out) / "verification.json"
        write_text_atomic(paths["verification"], json.dumps(after, indent=2))
        drift = ", ".join(f"{h} s: {v:.3g}" for h, v in after["drift_m"].items())
        print(f"Drake check of the augmented model: drift [m] {drift}; energy residual {energy_text(after['energy_residual'])}")
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


def _inputs(args):
    """(model, recording) from MODEL.urdf + RECORDING.csv, or from a reconstruction folder + --sequence
    (then OUT/recording.csv and OUT/meshes/ are written first)."""
    import shutil
    from pathlib import Path

    from ..errors import InputFileError
    from ..io.recording import read_recording, write_recording
    from ..model import read_urdf

    src = Path(args.model)
    if not src.is_dir():
        if args.sequence is not None:
            raise InputFileError(f"--sequence goes with a reconstruction folder, but {str(src)!r} is not a folder")
        if args.recording is None:
            raise InputFileError(f"{src}: a URDF needs a RECORDING.csv (or give a reconstruction folder and --sequence SEQ)")
        return read_urdf(src), read_recording(args.recording), False
    if args.recording is not None:
        raise InputFileError(f"{src} is a reconstruction folder: give --sequence SEQ, not a recording "
                             f"({args.recording!r})")
    if args.sequence is None:
        raise InputFileError(f"{src} is a reconstruction folder: --sequence SEQ (the RGB-D sequence it was made "
                             "from) is required")
    from ..verify.reconstruction import load_reconstruction, reconstruction_recording

    model, doc = load_reconstruction(src)
    jr = reconstruction_recording(src, args.sequence, model, doc)
    out = Path(args.out)
    write_recording(out / "recording.csv", jr.recording)
    if (src / "meshes").is_dir() and src.resolve() != out.resolve():
        shutil.copytree(src / "meshes", out / "meshes", dirs_exist_ok=True)
    return model, jr.recording, True
