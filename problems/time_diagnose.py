"""Time ``diagnose`` on a 1-DOF recording and how its cost grows with the recording's length.

    PYTHONPATH=. .venv/bin/python -m problems.time_diagnose [CASE] [--hz 100] [--lengths 2.5 5 10 20]
        [--repeat 1] [--workers N] [--profile OUT.prof] [--noise-seed 0]

The recording is catalogue case CASE (default ``effect_door_coulomb_friction+viscous_damping``)
simulated in MuJoCo with the benchmark's stroke plan repeated until it lasts the longest length
(2.5 s per stroke), sampled at ``--hz`` with the benchmark's encoder noise, then cut to each
length.  Prints per length the wall and CPU time of ``diagnose`` (CPU of this process and of the
processes it forked for the hypothesis fits, so BLAS threads and the second core count), the
samples and the effects it reported; with ``--repeat N`` each length runs N times and the best
and median wall and CPU are printed (the spread of one machine's timings is often larger than a
change being measured; the machine lines before and after, :mod:`problems.machine`, say how fast
the host let this process run).  ``--workers 1`` keeps every fit in this process (the default: the
CPUs this process may use).  With ``--profile`` the longest run is profiled by cProfile (this
process only) and the functions with the most cumulative time are printed.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from kinemaforge_opt.parallel import cpu_seconds

from .machine import machine_line


def make_recording(case_name: str, hz: int, seconds: float, noise_seed: int = 0):
    """(model, recording, effects) of ``case_name`` lasting ``seconds`` at ``hz`` (benchmark noise)."""
    from kinemaforge_opt.bench.recordings import NOISE, stroke_plan
    from kinemaforge_opt.io.recording import Recording
    from kinemaforge_opt.synth.groundtruth import HandPlan, simulate
    from kinemaforge_opt.synth.objects import make_object
    from problems.catalogue import get_case

    case = get_case(case_name)
    obj = make_object(case.category, case.seed)
    base = stroke_plan()
    n = int(np.ceil(seconds / base.stroke_s))
    goals = tuple(base.goals[k % len(base.goals)] if k < 2 else (0.6 if k % 2 == 0 else 0.25) for k in range(n))
    plan = HandPlan(goals=goals, push_s=base.push_s, free_s=base.free_s, release_speed=base.release_speed)
    ep = simulate(obj.model, obj.handles, case.effects, plan=plan, record_hz=hz)
    q = ep.q + np.random.default_rng(noise_seed).normal(0.0, NOISE, ep.q.shape)
    keep = ep.t <= ep.t[0] + seconds + 1e-9
    return obj.model, Recording(ep.t[keep], ep.joint_names, q[keep], tau=ep.tau[keep]), case.effects


def _spread(seconds: list[float]) -> str:
    """"best B, median M" of repeated timings [s], or the one timing."""
    if len(seconds) == 1:
        return f"{seconds[0]:5.2f}"
    return f"best {min(seconds):5.2f}, median {float(np.median(seconds)):5.2f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", nargs="?", default="effect_door_coulomb_friction+viscous_damping")
    ap.add_argument("--hz", type=int, default=100)
    ap.add_argument("--lengths", type=float, nargs="+", default=[10.0])
    ap.add_argument("--repeat", type=int, default=1, help="runs per length (best and median wall and CPU printed)")
    ap.add_argument("--profile", help="write a cProfile of the longest run here and print its top entries")
    ap.add_argument("--noise-seed", type=int, default=0)
    ap.add_argument("--workers", type=int, help="processes for the hypothesis fits (default: the CPUs this process may use)")
    args = ap.parse_args(argv)
    from kinemaforge_opt.physics.diagnose import diagnose

    print(machine_line())
    model, full, effects = make_recording(args.case, args.hz, max(args.lengths), args.noise_seed)
    print(f"{args.case} at {args.hz} Hz; concealed: " + ", ".join(f"{e.type}={e.value:g}" for e in effects))
    for seconds in sorted(args.lengths):
        rec = full.window(full.t[0], full.t[0] + seconds)
        prof = None
        if args.profile and seconds == max(args.lengths):
            import cProfile

            prof = cProfile.Profile()
            prof.enable()
        walls, cpus = [], []
        for _ in range(max(args.repeat, 1)):
            w0, c0 = time.perf_counter(), cpu_seconds()
            d = diagnose(model, rec, workers=args.workers)
            walls.append(time.perf_counter() - w0)
            cpus.append(cpu_seconds() - c0)
        if prof is not None:
            prof.disable()
            prof.dump_stats(args.profile)
        found = ", ".join(f"{e.type}={e.value:.4g}" for e in d.effects) or "nothing"
        print(f"{seconds:5.1f} s, {rec.t.size:5d} samples: wall {_spread(walls)} s, CPU {_spread(cpus)} s"
              f"{f' ({len(walls)} runs)' if len(walls) > 1 else ''}; found {found}")
    print(machine_line("machine after"))
    if args.profile:
        import pstats

        pstats.Stats(args.profile).sort_stats("cumulative").print_stats(25)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
