"""The seed's Table 1 alone: the 20 full-size reconstructions of ``kinemaforge bench`` (5
categories × 2 instances × 2 seeds, 8 views × 20 steps at 640×480), without Table 2 and the sweeps.

    PYTHONPATH=. .venv/bin/python -m problems.table1 -o DIR [--resume] [--categories cabinet ...]

Each run is scored exactly as the benchmark scores it (``bench.reconstruction.evaluate_case``) and
appended to DIR/reconstruction/records.jsonl as it finishes; ``--resume`` reuses the finished runs
there.  Prints one line per run, then the table (mean over the runs per category, and the average).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinemaforge_opt.bench.reconstruction import RECO_FULL, _Runs, cache_root, summarise

from .reco_sizes import protocol_case

COLUMNS = (("axis_error_deg", "axis °", "{:.2f}"), ("origin_error_m", "origin m", "{:.3f}"),
           ("inertia_error", "inertia err", "{:.3f}"),
           ("part_iou", "part IoU", "{:.3f}"), ("moving_part_iou", "moving IoU", "{:.3f}"),
           ("drift_1s_m", "1-s drift m", "{:.3f}"), ("drift_50s_m", "50-s drift m", "{:.3f}"),
           ("energy_residual", "energy", "{:.3f}"), ("type_accuracy", "types", "{:.2f}"),
           ("topology_correct", "topology", "{:.2f}"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, required=True, help="output folder")
    ap.add_argument("--resume", action="store_true", help="reuse the finished runs in OUT/reconstruction/records.jsonl")
    ap.add_argument("--categories", nargs="+", default=list(RECO_FULL.categories), choices=RECO_FULL.categories)
    args = ap.parse_args(argv)
    size = RECO_FULL
    runs = _Runs(args.out / "reconstruction", cache_root(), print, resume=args.resume)
    base = dict(views=size.views, frames=size.frames, width=size.width, height=size.height)
    records = []
    for c in args.categories:
        for n in size.instances:
            for s in size.seeds:
                r = runs(protocol_case(c, n, s, **base))
                records.append(r)
                print(f"  {r['case']}: " + (", ".join(f"{label} {fmt.format(r[k])}" for k, label, fmt in COLUMNS
                                                        if r.get(k) is not None) if r["ok"] else r["error"]), flush=True)
    print("\n| | " + " | ".join(label for _, label, _ in COLUMNS) + " |")
    print("|---" * (len(COLUMNS) + 1) + "|")
    for name, group in [(c, [r for r in records if r["category"] == c]) for c in args.categories] + [("average", records)]:
        s = summarise(group)
        cells = [fmt.format(s[k]["mean"]) if s[k]["mean"] is not None else "–" for k, _, fmt in COLUMNS]
        print(f"| {name} ({s['cases']}) | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
