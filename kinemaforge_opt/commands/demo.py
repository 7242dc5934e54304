"""``kinemaforge demo``: the main job on embedded default data (``--joint-space``: the calibration demo)."""

from __future__ import annotations

import argparse

DESCRIPTION = """\
The main job, from nothing: generate a small RGB-D episode (a procedurally generated cabinet
door with a viscous damper of 0.8 N·m·s/rad that no model is told about, pushed by a hand and
released; MuJoCo physics, two static RGB-D cameras with D435-like noise, the hand's force in
wrenches.csv), then from the sequence alone reconstruct the articulated object (URDF + meshes),
verify it in Drake (drift at 1-50 s, energy residual), diagnose the reconstruction (which physics
is missing) and save a meshcat scene.  The summary compares with the ground truth, which the
pipeline never reads.

--joint-space: the calibration demo instead: the same door with a 3° hinge tilt, damping
0.2 N·m·s/rad and Coulomb friction 0.3 N·m, recorded in joint space at 30 Hz with 2 mrad noise;
the joint-space NLP (Pinocchio ABA on casadi.SX, IPOPT) identifies the axis and both coefficients.
"""

EPILOG = """\
outputs (main job):
  OUT/episode/sequence/         the RGB-D sequence (+ wrenches.csv); OUT/episode/ground_truth/
  OUT/reconstruction/           model.urdf, meshes/, reconstruction.json (with "verification"),
                                recording.csv, replay.csv, trajectories.png, scene.html
  OUT/diagnosis/                diagnosis.json, model.urdf (augmented), plots, verification.json
                                (the augmented model checked in Drake like the reconstruction)
  OUT/demo.json                 the summary
"""


def register(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="the main job on generated data: RGB-D -> URDF -> Drake -> diagnosis -> scene",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("-o", "--out", default="out/demo", help="output folder (default: out/demo)")
    p.add_argument("--seed", type=int, default=0, help="object and noise seed (default: 0)")
    p.add_argument("--joint-space", action="store_true",
                   help="run the joint-space calibration demo (tilt, damping, friction) instead")
    p.add_argument("--frames", type=int, default=None, metavar="N",
                   help="RGB-D time steps of the main job (default: %d)" % _default("frames"))
    p.add_argument("--size", default=None, metavar="WxH",
                   help="image size of the main job in pixels (default: %dx%d)" % (_default("width"), _default("height")))
    p.set_defaults(func=run)


def _default(name: str) -> int:
    from ..demo import DEMO_SIZE

    return DEMO_SIZE[name]


def _size(text: str | None) -> tuple[int, int]:
    from ..errors import DataError

    if text is None:
        return _default("width"), _default("height")
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise DataError(f"--size must be WIDTHxHEIGHT in pixels (e.g. 320x240), got {text!r}") from None
    if w < 16 or h < 12:
        raise DataError(f"--size {text}: images must be at least 16x12 px")
    return w, h


def run(args) -> int:
    if args.joint_space:
        return _joint_space(args)
    from ..demo import NoJointFound, run_main_demo

    width, height = _size(args.size)
    frames = args.frames if args.frames is not None else _default("frames")
    print("kinemaforge demo: RGB-D episode -> reconstruction -> Drake verification -> diagnosis -> scene", flush=True)
    try:
        report = run_main_demo(args.out, seed=args.seed, frames=frames, width=width, height=height,
                               say=lambda line: print(line, flush=True))
    except NoJointFound as e:
        import sys

        print(f"kinemaforge demo: {e}", file=sys.stderr)
        return 1
    print()
    print(report.summary())
    return 0


def _joint_space(args) -> int:
    from ..demo import run_demo

    print("kinemaforge demo --joint-space: simulating the door in MuJoCo and fitting it with IPOPT …", flush=True)
    report = run_demo(args.out, seed=args.seed)
    cal = report.calibration
    print(report.table())
    state = "converged" if cal.success else f"did NOT converge ({cal.status})"
    print(f"\nIPOPT {state} in {cal.iterations} iterations, {cal.solve_time_s:.1f} s; "
          f"fit RMS {1000 * max(cal.rms_q.values()):.2f} mrad (noise 2 mrad)")
    for line in cal.identifiability:
        print(f"note: {line}")
    print(f"files: {report.out_dir}/model.urdf (nominal), calibrated.urdf, recording.csv, demo.json")
    return 0 if cal.success else 1
