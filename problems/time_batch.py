"""Batch throughput: the same diagnose inputs run on a local Ray cluster with 1 and with 2 workers.

    PYTHONPATH=. .venv/bin/python -m problems.time_batch [-n 8] [-o /tmp/time_batch]

Inputs are concealed-effect door/drawer recordings from the catalogue (model.urdf + recording.csv
per folder, noise re-drawn when cases repeat); prints wall time per worker count (Ray start-up
included), the span from the first item's start to the last one's end, and both speed-ups."""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

from kinemaforge_opt.batch import JOBS, run_batch
from kinemaforge_opt.batch.runner import STATUS
from kinemaforge_opt.bench.recordings import effect_recording
from kinemaforge_opt.io.recording import write_recording
from kinemaforge_opt.model import write_urdf

CASES = ("effect_door_viscous_damping", "effect_door_coulomb_friction", "effect_door_spring",
         "effect_door_constant_bias", "effect_drawer_viscous_damping", "effect_drawer_coulomb_friction",
         "effect_drawer_spring", "effect_drawer_constant_bias")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-n", type=int, default=16, help="number of inputs (default 16; the cases repeat with new noise)")
    ap.add_argument("-o", "--out", type=Path, default=Path("/tmp/time_batch"))
    args = ap.parse_args()
    inputs = []
    for k in range(args.n):
        case, noise_seed = CASES[k % len(CASES)], k // len(CASES)
        er = effect_recording(case, noise_seed)
        d = args.out / "inputs" / f"{case}-{noise_seed}"
        write_urdf(er.model, d / "model.urdf")
        write_recording(d / "recording.csv", er.recording)
        inputs.append(d)
    wall, span = {}, {}
    for workers in (1, 2):
        out = args.out / f"workers{workers}"
        shutil.rmtree(out, ignore_errors=True)
        t0 = time.perf_counter()
        items = run_batch(inputs, out, JOBS["diagnose"], workers=workers, progress=False)
        wall[workers] = time.perf_counter() - t0
        failed = [it.name for it in items if it.status != "ok"]
        docs = [json.loads((out / it.name / STATUS).read_text()) for it in items]
        span[workers] = max(d["finished_unix_s"] for d in docs) - min(d["started_unix_s"] for d in docs)
        cpu = sum(d["time_s"] for d in docs)
        print(f"{workers} worker(s): {len(inputs)} inputs in {wall[workers]:.1f} s wall "
              f"({span[workers]:.1f} s from first start to last finish; items' own time {cpu:.1f} s)"
              + (f"; failed: {failed}" if failed else ""))
    print(f"throughput 2 vs 1 workers: {wall[1] / wall[2]:.2f}x wall with Ray start-up and shutdown, "
          f"{span[1] / span[2]:.2f}x without")


if __name__ == "__main__":
    main()
