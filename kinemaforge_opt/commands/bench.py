"""``kinemaforge bench [--quick] [-o DIR]``: the benchmark tables, JSON and plots."""

from __future__ import annotations

import argparse

# the parts of kinemaforge_opt.bench.run.PARTS, spelled out so `kinemaforge --help` does not import
# the benchmark (a test keeps the two equal)
PARTS = ("discovery", "sturm", "calibration", "scaling", "arm", "reconstruction")

EPILOG = """\
sizes:
  --quick   each concealed effect alone on the door and the drawer plus the null cases, one
            noise seed, one demo-door seed, calibrate scaling at 30/60/120 Hz, the robot-arm
            side-by-side (nominal vs IDIM-LS vs kinemaforge_opt) on a 6 s excitation; RGB-D
            reconstruction (Table 1, Table 2, drift, sensitivity, time per stage) on two
            instances per category at 4 views x 12 steps, 160x120 px, ablations on a
            cabinet (a 300 s budget: runs past it are listed as skipped)
  (full)    adds the effect pairs, three noise seeds, three demo-door seeds, scaling up to
            400 Hz, a 20 s arm excitation; reconstruction on the seed protocol (8 views x 20
            steps at 640x480, 2 instances x 2 seeds per category, every category ablated);
            each run writes its runtime to bench.json ("total_s")

Generated synthetic cases are cached in $KINEMAFORGE_BENCH_CACHE (default
~/.cache/kinemaforge/bench) and reused by later runs; reconstructions go to DIR/reconstruction/.

outputs: DIR/bench.json, DIR/bench.md, DIR/scaling.png, DIR/discovery.png, DIR/drift_horizon.png,
DIR/sensitivity.png, DIR/stage_scaling.png
"""


def register(sub) -> None:
    p = sub.add_parser(
        "bench", help="benchmark: mismatch discovery vs ID-LS and PySINDy, Sturm logs, calibration, timing",
        description="Run the benchmark and write JSON, Markdown tables and PNG plots.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--quick", action="store_true", help="the quick size (< 10 min on 2 cores)")
    p.add_argument("-o", "--out", default="bench_results", help="output folder (default: bench_results)")
    p.add_argument("--cases", nargs="+", metavar="CASE", help="only these discovery cases (default: all)")
    p.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS), metavar="PART",
                   help=f"only these parts of the benchmark: {', '.join(PARTS)} (default: all)")
    p.add_argument("--resume", action="store_true",
                   help="reuse the reconstruction runs an interrupted run of the same code left in "
                        "OUT/reconstruction/records.jsonl instead of making them again")
    p.set_defaults(func=run)


def run(args) -> int:
    from tqdm import tqdm

    from ..bench import FULL, QUICK, run_bench
    from ..bench.report import write_report

    if args.cases:
        from problems.catalogue import get_case

        for c in args.cases:
            get_case(c)  # unknown names exit 2 before any work
    bar = tqdm(desc="bench", unit="step", leave=False)

    def progress(msg: str) -> None:
        bar.set_postfix_str(msg)
        bar.update(1)

    result = run_bench(QUICK if args.quick else FULL, args.cases, progress, out_dir=args.out, parts=tuple(args.parts),
                       resume=args.resume)
    bar.close()
    paths = write_report(result, args.out)
    print(paths["markdown"].read_text())
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
