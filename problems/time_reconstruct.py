"""Wall time of ``kinemaforge reconstruct`` per object, by stage (issue 6's figure: goal ≤ 10 s
median on 2 cores for a 30-step, 4-view episode).

    PYTHONPATH=. .venv/bin/python -m problems.time_reconstruct [-o DIR] [--repeat 2] [--categories ...]
        [--against TREE]

Generates instance 0 of each category (``problems.eval_perception.instance_case``: 4 static views
× 30 steps at 640×480, D435-like noise) into DIR/data once, then runs the command as a user does
(a new process: imports, perception, graph, NLP, model, files, Drake verification) ``--repeat``
times per object, interleaved, and prints each run's wall, the stages the command itself times
(reconstruction.json ``timing_s`` and ``verification.timing_s``), and the median over objects of
each object's best run.  Wall is what a user waits for; the stages leave out the imports
(~2–4 s).  The machine lines before and after (CPU, cores, load, a speed probe:
:mod:`problems.machine`) say what the figures were measured on.

``--against TREE``: another source tree (e.g. ``git worktree add /tmp/old <commit>``, with the
native bridge copied in) is timed as well, each object's runs of the two trees back to back, the
order alternating per round, so that a drift in the machine's speed falls on both alike; one
summary per tree.
"""

from __future__ import annotations

import argparse
import json
import os
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


def time_run(sequence: Path, out: Path, tree: Path | None = None) -> dict:
    """One ``kinemaforge reconstruct SEQUENCE -o OUT`` in a new process (``tree``: the source tree
    it runs from; default the installed package): its wall [s] and the stage times [s] it wrote."""
    env = None if tree is None else dict(os.environ, PYTHONPATH=str(tree), KF_TREE=str(tree))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "kinemaforge_opt.cli", "reconstruct", str(sequence), "-o", str(out)],
                          capture_output=True, text=True, env=env, cwd=tree)
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
    ap.add_argument("--against", type=Path, default=None,
                    help="another source tree to time alongside, run for run (an A/B on the same machine)")
    args = ap.parse_args(argv)
    if args.against is not None and not (args.against / "kinemaforge_opt" / "cli.py").is_file():
        raise SystemExit(f"--against {args.against}: not a kinemaforge_opt source tree (no kinemaforge_opt/cli.py)")
    trees = {"this tree": None} if args.against is None else {"this tree": None, str(args.against): args.against.resolve()}
    print(machine_line())
    cases = {c: instance_case(c, 0) for c in args.categories}
    for c, case in cases.items():
        root = args.out / "data" / case.name
        if not (root / "ground_truth" / "case.json").is_file():
            generate_case(case, root)
    runs: dict[str, dict[str, list[dict]]] = {name: {c: [] for c in cases} for name in trees}
    for k in range(args.repeat):
        for c, case in cases.items():
            for name, tree in (trees.items() if k % 2 == 0 else reversed(trees.items())):
                out = args.out / f"run{k}" / (case.name if tree is None else f"{case.name}-against")
                r = time_run(args.out / "data" / case.name / "sequence", out, tree)
                runs[name][c].append(r)
                stages = ", ".join(f"{s} {r['stages'][s]:.1f}" for s in (*STAGES, "verify") if s in r["stages"])
                label = "" if len(trees) == 1 else f" [{name}]"
                print(f"  {case.name} run {k + 1}{label}: wall {r['wall']:.2f} s ({stages})", flush=True)
    for name, per_object in runs.items():
        label = "" if len(trees) == 1 else f"{name}: "
        best = {c: min(r["wall"] for r in rs) for c, rs in per_object.items()}
        print(f"{label}best wall per object [s]: " + ", ".join(f"{c} {w:.2f}" for c, w in best.items()))
        per_run = [statistics.median(rs[k]["wall"] for rs in per_object.values()) for k in range(args.repeat)]
        print(f"{label}median over objects of the best run: {statistics.median(best.values()):.2f} s "
              f"(median of each round: {', '.join(f'{m:.2f}' for m in per_run)})")
    print(machine_line("machine after"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
