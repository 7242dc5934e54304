"""``kinemaforge verify MODEL.urdf [RECORDING.csv] -o OUT``: Drake replay, drift and energy."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..errors import DataError
from ..io.atomic import write_text_atomic

DESCRIPTION = """\
Check a model in Drake (the physics engine that did not fit it).

With RECORDING.csv: start Drake from the recording's first state, apply its recorded tau
(linear interpolation; the last value is held after the recording ends) and report
  drift_m      largest position error of any moving link's origin or centre of mass [m]
               at each horizon (seconds after the first sample); past the end of the
               recording the reference is its last pose, held (the object at rest);
  joint_rms    joint-space RMS error over [0, horizon] [rad or m];
  drift_range_m  (--drift-range) the least and largest drift_m with each moving link's mass
               and inertia 1 % up and down: a wide range marks a knife edge;
  energy_residual  |ΔE − W_applied − W_dissipative| / scale over the recording's spans in
               which no joint moves into one of its stops or is pressed past one (a stop's
               work is in no model term; resting on a stop or leaving it is booked), a
               dimensionless ratio (0 = the model's energy books balance on the data).
Without a recording: a conservative check.  Damping and friction are removed, the model
starts mid-range with 1 rad/s (0.1 m/s for sliders) and its energy must stay constant.

Damping, springs, armature and joint limits are Drake plant elements; Coulomb friction
(ignored by Drake's URDF parser) is applied as −f·tanh(v/v_eps).
"""

EPILOG = """\
outputs:
  OUT/verification.json   drift per horizon, energy residual, timings
  OUT/trajectories.png    recorded vs simulated joint trajectories (+ energy)

examples:
  kinemaforge verify out/cal/model.urdf rec.csv -o out/verify
  kinemaforge verify models/laptop/laptop.urdf -o out/verify_free     conservative check
  kinemaforge verify model.urdf rec.csv -o out/v --horizons 1,5 --continuous
  kinemaforge verify model.urdf rec.csv -o out/v --drift-range       drift with link masses ±1 %
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "verify",
        help="Drake replay of a recording: drift per horizon and energy residual",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", metavar="MODEL.urdf", help="the model to check")
    p.add_argument("recording", metavar="RECORDING.csv", nargs="?",
                   help="joint-space recording t,q:<joint>[,v:<joint>][,tau:<joint>] (optional)")
    p.add_argument("-o", "--out", required=True, metavar="OUT", help="output folder (created)")
    p.add_argument("--horizons", default="1,5,10,20,50", metavar="S,S,…",
                   help="drift horizons in seconds after the first sample (default: %(default)s)")
    p.add_argument("--continuous", action="store_true",
                   help="continuous plant with an error-controlled integrator instead of the 1 ms "
                        "discrete plant (faster, but joint limits are ignored)")
    p.add_argument("--drift-range", action="store_true",
                   help="with a recording: also replay with each moving link's mass and inertia 1 %% up and "
                        "down and report the drift's range per horizon; a wide range marks a knife edge "
                        "(a lid pushed just over its balance point), where the drift measures that 1 %%")
    p.add_argument("--duration", type=float, default=10.0, metavar="S",
                   help="length of the conservative check without a recording (default: %(default)s s)")
    p.set_defaults(func=run)


def _horizons(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise DataError(f"--horizons must be comma-separated seconds, got {text!r}") from None


def run(args) -> int:
    from ..io.recording import read_recording
    from ..model import read_urdf
    from ..verify.report import energy_text, range_text, verify_free, verify_recording

    horizons = _horizons(args.horizons)
    model = read_urdf(args.model)
    recording = read_recording(args.recording) if args.recording else None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plot = out / "trajectories.png"
    if recording is None:
        result = verify_free(model, plot, args.duration)
    else:
        result = verify_recording(model, recording, plot, horizons, discrete=not args.continuous,
                                  with_range=args.drift_range)
    result = {"model": str(args.model), "recording": args.recording, **result}
    path = out / "verification.json"
    write_text_atomic(path, json.dumps(result, indent=2) + "\n")
    ranges = result.get("drift_range_m", {})
    summary = ", ".join(f"{h} s: {d:.3g} m{range_text(ranges, h)}" for h, d in result["drift_m"].items())
    print(f"energy residual {energy_text(result['energy_residual'])}" + (f"; drift {summary}" if summary else ""))
    print(path)
    return 0
