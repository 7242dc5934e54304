"""``kinemaforge batch INPUTS... -o OUT``: many diagnose/calibrate/reconstruct jobs in parallel on Ray."""

from __future__ import annotations

import argparse

EPILOG = """\
each INPUT is a folder holding model.urdf and recording.csv (jobs diagnose, calibrate) or an RGB-D
sequence folder with sequence.json (job reconstruct: reconstruction + Drake verification); its
results go to OUT/<folder name>/
(the job's usual outputs plus status.json).  A failing input is recorded and the rest go on;
re-running skips inputs whose status.json says ok.  Exit status 1 if any input failed.

examples:
  kinemaforge batch data/*/ -o out/batch                    diagnose each, local Ray cluster
  kinemaforge batch data/*/ -o out/batch --workers 2
  kinemaforge batch data/*/ -o out/batch --address auto     an existing Ray cluster
  kinemaforge batch seqs/*/ -o out/rec --job reconstruct    reconstruct many RGB-D sequences
"""


def register(sub) -> None:
    p = sub.add_parser("batch", help="run diagnose/calibrate/reconstruct on many inputs in parallel (Ray)",
                       description="Run a job over many inputs in parallel on Ray, isolating failures.",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("inputs", nargs="+", help="input folders (model.urdf + recording.csv, or RGB-D sequences)")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument("--job", choices=("diagnose", "calibrate", "reconstruct"), default="diagnose", help="job per input (default diagnose)")
    p.add_argument("--address", help="address of an existing Ray cluster (default: start a local one)")
    p.add_argument("--workers", type=int, help="CPUs of the local cluster (default: all)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..batch import JOBS, run_batch, summary_table

    items = run_batch(args.inputs, args.out, JOBS[args.job], address=args.address, workers=args.workers)
    print(summary_table(items))
    return 1 if any(it.status == "error" for it in items) else 0
