"""``kinemaforge synth CASE -o DIR``: generate a benchmark case from ``problems/``."""

from __future__ import annotations

import argparse
import time

from ..errors import KinemaforgeError

DESCRIPTION = """\
Generate one benchmark case of the catalogue in problems/: a procedural object, its
ground-truth physics simulated in MuJoCo (a hand opens a part at its handle, then lets go),
and the rendered RGB-D sequence with a D435-like noise model.

Concealed effects (damping, friction, springs, a tilted axis, …) act in the ground truth
only; the nominal model.urdf does not contain them.  Case groups: protocol_* (5 categories ×
2 instances × 8 views, kinematics), effect_* / null_* (the concealed-effects set), tiny_*
(small cases for tests).
"""

EPILOG = """\
outputs:
  DIR/sequence/                    kinemaforge.rgbd/1 RGB-D sequence (+ wrenches.csv)
  DIR/tracks.csv                   true link poses at the rendered times
  DIR/recording.csv                true q, v and the hand's generalised force tau
  DIR/model.urdf, DIR/meshes/      the nominal model
  DIR/ground_truth/                true_model.urdf, effects.json, labels/, case.json

examples:
  kinemaforge synth --list
  kinemaforge synth tiny_door -o out/tiny_door
  kinemaforge synth effect_door_coulomb_friction -o out/coulomb
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "synth",
        help="generate a benchmark case (data + ground truth) from problems/",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("case", nargs="?", metavar="CASE", help="case name (see --list)")
    p.add_argument("-o", "--out", metavar="DIR", help="output folder")
    p.add_argument("--list", action="store_true", help="list the cases with what each expects, then exit")
    p.set_defaults(func=run)


def _catalogue():
    try:
        import problems.catalogue as catalogue
    except ImportError as e:
        raise KinemaforgeError(
            f"the benchmark catalogue (package 'problems' at the repository root) is not importable ({e}); "
            "run from the repository root or put it on PYTHONPATH"
        ) from None
    return catalogue


def run(args) -> int:
    catalogue = _catalogue()
    if args.list:
        for name, case in catalogue.CASES.items():
            effects = ", ".join(e.type for e in case.effects) or "none"
            print(f"{name:50s} {case.category:14s} effects: {effects}\n    expected: {case.expected}")
        return 0
    if not args.case or not args.out:
        raise KinemaforgeError("synth needs a CASE and -o DIR (or --list)")
    from ..synth.generate import generate_case

    case = catalogue.get_case(args.case)
    t0 = time.perf_counter()
    paths = generate_case(case, args.out)
    print(f"{case.name}: wrote {paths.root} in {time.perf_counter() - t0:.1f} s "
          f"(sequence {paths.sequence}, ground truth {paths.effects.parent})")
    return 0
