"""Wall time of ``kinemaforge reconstruct`` per object, by stage (issue 6's figure: goal ≤ 10 s
median on 2 cores for a 30-step, 4-view episode).

    PYTHONPATH=. .venv/bin/python -m problems.time_reconstruct [-o DIR] [--repeat 2] [--categories ...]

Generates instance 0 of each category (``problems.eval_perception.instance_case``: 4 static views
× 30 steps at 640×480, D435-like noise) into DIR/data once, then runs the command as a user does
(a new process: imports, perception, graph, NLP, model, files, Drake verification) ``--repeat``
times per object, interleaved, and prints each run's wall, the stages the command itself times
(reconstruction.json ``timing_s`` and ``verification.timing_s``), and the median over objects of
each object's best run.  Wall is what a user waits for; the stages leave out the imports
(~2–4 s).  The machine lines before and after (CPU, cores, load, a speed probe:
:mod:`problems.machine`) say what the figures were measured on.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

from kinemaforge_opt.synth import generate_case

from .eval_perception import instance_case
from .machine import machine_line

DEFAULT_CATEGORIES = ("cabinet", "laptop", "microwave", "refrigerator")
STAGES = ("load", "clouds", "motion", "proposals+tracks", "resegment", "graph", "nlp", "model")


def time_run(sequence: Path, out: Path) -> dict:
    """One ``kinemaforge reconstruct SEQUENCE -o OUT`` in a new process: its wall [s] and the
    stage times [s] it wrote."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "kinemaforge_opt.cli", "reconstruct", str(sequence), "-o", str(out)],
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"kinemaforge reconstruct {sequence} exited {proc.returncode}: {proc.stderr.strip()[-500:]}")
    doc = json.loads((out / "reconstruction.json").read_text())
    stages = dict(doc["timing_s"])
    stages["verify"] = doc.get("verification", {}).get("timing_s", {}).get("total", float("nan"))
    return {"wall": wall, "stages": stages}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("/tmp/time_reconstruct"), help="working folder")
    ap.add_argument("--repeat", type=int, default=2, help="runs per object, interleaved (the best counts)")
    ap.add_argument("--categories", nargs="+", default=list(DEFAULT_CATEGORIES))
    args = ap.parse_args(argv)
    print(machine_line())
    cases = {c: instance_case(c, 0) for c in args.categories}
    for c, case in cases.items():
        root = args.out / "data" / case.name
        if not (root / "ground_truth" / "case.json").is_file():
            generate_case(case, root)
    runs: dict[str, list[dict]] = {c: [] for c in cases}
    for k in range(args.repeat):
        for c, case in cases.items():
            r = time_run(args.out / "data" / case.name / "sequence", args.out / f"run{k}" / case.name)
            runs[c].append(r)
            stages = ", ".join(f"{s} {r['stages'][s]:.1f}" for s in (*STAGES, "verify") if s in r["stages"])
            print(f"  {case.name} run {k + 1}: wall {r['wall']:.2f} s ({stages})", flush=True)
    best = {c: min(r["wall"] for r in rs) for c, rs in runs.items()}
    print("best wall per object [s]: " + ", ".join(f"{c} {w:.2f}" for c, w in best.items()))
    per_run = [statistics.median(rs[k]["wall"] for rs in runs.values()) for k in range(args.repeat)]
    print(f"median over objects of the best run: {statistics.median(best.values()):.2f} s "
          f"(median of each round: {', '.join(f'{m:.2f}' for m in per_run)})")
    print(machine_line("machine after"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
