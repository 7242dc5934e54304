"""Batch throughput: the same inputs run on a local Ray cluster with 1 and with 2 workers.

    PYTHONPATH=. .venv/bin/python -m problems.time_batch [--job diagnose|reconstruct] [-n 16] [-o /tmp/time_batch]

``--job diagnose`` (default): concealed-effect door/drawer recordings from the catalogue
(model.urdf + recording.csv per folder, noise re-drawn when cases repeat), ~2 s per item.
``--job reconstruct``: the quick benchmark's RGB-D sequences (seed-protocol objects, 4 views,
12 steps, 160×120, generated once into the benchmark cache), reconstruction + Drake
verification, ~4–10 s per item — the batch's main use, many sequences; with ``--size full``
the full benchmark's sequences instead (8 views × 20 steps at 640×480, ~1 min per item).

Prints wall time per worker count (Ray start-up and shutdown included), the span from the first
item's start to the last one's end, and both speed-ups (throughput = items per second)."""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

from kinemaforge_opt.batch import JOBS, run_batch
from kinemaforge_opt.batch.runner import STATUS

EFFECT_CASES = ("effect_door_viscous_damping", "effect_door_coulomb_friction", "effect_door_spring",
                "effect_door_constant_bias", "effect_drawer_viscous_damping", "effect_drawer_coulomb_friction",
                "effect_drawer_spring", "effect_drawer_constant_bias")


def diagnose_inputs(n: int, root: Path) -> list[Path]:
    """``n`` folders of model.urdf + recording.csv (the effect cases in turn, new noise per round)."""
    from kinemaforge_opt.bench.recordings import effect_recording
    from kinemaforge_opt.io.recording import write_recording
    from kinemaforge_opt.model import write_urdf

    inputs = []
    for k in range(n):
        case, noise_seed = EFFECT_CASES[k % len(EFFECT_CASES)], k // len(EFFECT_CASES)
        er = effect_recording(case, noise_seed)
        d = root / f"{case}-{noise_seed}"
        write_urdf(er.model, d / "model.urdf")
        write_recording(d / "recording.csv", er.recording)
        inputs.append(d)
    return inputs


def reconstruct_inputs(n: int, root: Path, full: bool = False) -> list[Path]:
    """``n`` RGB-D sequence folders: the quick (or ``full``) benchmark's protocol cases
    (categories in turn, then instances, then repetition seeds), linked under ``root`` with
    distinct names."""
    from kinemaforge_opt.bench.reconstruction import CATEGORIES, RECO_FULL, RECO_QUICK, cached_case
    from problems.reco_sizes import protocol_case

    reco = RECO_FULL if full else RECO_QUICK
    size = dict(views=reco.views, frames=reco.frames, width=reco.width, height=reco.height)
    root.mkdir(parents=True, exist_ok=True)
    inputs = []
    for k in range(n):
        category = CATEGORIES[k % len(CATEGORIES)]
        instance, seed = (k // len(CATEGORIES)) % 2, k // (2 * len(CATEGORIES))
        case = protocol_case(category, instance, seed, **size)
        link = root / case.name.replace("@", "-").replace(",", "-")
        if not link.exists():
            link.symlink_to(cached_case(case) / "sequence")
        inputs.append(link)
    return inputs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--job", choices=("diagnose", "reconstruct"), default="diagnose")
    ap.add_argument("-n", type=int, default=16, help="number of inputs (default 16; cases repeat with new noise / seeds)")
    ap.add_argument("--size", choices=("quick", "full"), default="quick",
                    help="reconstruct job: the quick or the full benchmark's sequences (default quick)")
    ap.add_argument("-o", "--out", type=Path, default=Path("/tmp/time_batch"))
    args = ap.parse_args()
    if args.job == "diagnose":
        inputs = diagnose_inputs(args.n, args.out / "inputs-diagnose")
    else:
        inputs = reconstruct_inputs(args.n, args.out / f"inputs-reconstruct-{args.size}", full=args.size == "full")
    wall, span = {}, {}
    for workers in (1, 2):
        out = args.out / f"{args.job}-workers{workers}"
        shutil.rmtree(out, ignore_errors=True)
        t0 = time.perf_counter()
        items = run_batch(inputs, out, JOBS[args.job], workers=workers, progress=False)
        wall[workers] = time.perf_counter() - t0
        failed = [f"{it.name}: {it.error}" for it in items if it.status != "ok"]
        docs = [json.loads((out / it.name / STATUS).read_text()) for it in items]
        span[workers] = max(d["finished_unix_s"] for d in docs) - min(d["started_unix_s"] for d in docs)
        busy = sum(d["time_s"] for d in docs)
        print(f"{workers} worker(s): {len(inputs)} {args.job} inputs in {wall[workers]:.1f} s wall "
              f"({span[workers]:.1f} s from first start to last finish; items' own time {busy:.1f} s)"
              + (f"; failed: {failed}" if failed else ""))
    print(f"throughput 2 vs 1 workers: {wall[1] / wall[2]:.2f}x wall with Ray start-up and shutdown, "
          f"{span[1] / span[2]:.2f}x without")


if __name__ == "__main__":
    main()
