"""``kinemaforge bench [--quick] [-o DIR]``: the benchmark tables, JSON and plots."""

from __future__ import annotations

import argparse

EPILOG = """\
sizes:
  --quick   each concealed effect alone on the door and the drawer plus the null cases, one
            noise seed, one demo-door seed, calibrate scaling at 30/60/120 Hz, the robot-arm
            side-by-side (nominal vs IDIM-LS vs kinemaforge_opt) on a 6 s excitation
  (full)    adds the effect pairs, three noise seeds, three demo-door seeds, scaling up to
            400 Hz, a 20 s arm excitation; each run writes its runtime to bench.json ("total_s")

outputs: DIR/bench.json, DIR/bench.md, DIR/scaling.png, DIR/discovery.png
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

    result = run_bench(QUICK if args.quick else FULL, args.cases, progress)
    bar.close()
    paths = write_report(result, args.out)
    print(paths["markdown"].read_text())
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
