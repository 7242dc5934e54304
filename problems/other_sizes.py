"""Table 1's objects at rig sizes Table 1 never uses: fewer or more views, fewer or more steps,
other resolutions (new repetition seeds, so new dimensions and noise), scored exactly as Table 1
scores its runs (``bench.reconstruction.evaluate_case``).

    PYTHONPATH=. .venv/bin/python -m problems.other_sizes -o DIR [--resume]

Each run is appended to DIR/reconstruction/records.jsonl as it finishes (``--resume`` reuses
them); prints one line per run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinemaforge_opt.bench.reconstruction import _Runs, cache_root

from .outside_table1 import COLUMNS
from .reco_sizes import protocol_case

# (category, instance, repetition seed, views, steps, width, height)
SIZES = (
    ("microwave", 0, 7, 2, 15, 320, 240),
    ("drawer", 1, 8, 3, 40, 424, 240),
    ("laptop", 1, 9, 1, 20, 640, 480),
    ("cabinet", 0, 10, 6, 12, 320, 240),
    ("refrigerator", 1, 11, 4, 25, 480, 360),
    ("drawer", 1, 8, 3, 40, 640, 480),
    ("drawer", 1, 8, 4, 40, 424, 240),
    ("drawer", 1, 8, 3, 20, 424, 240),
    ("drawer", 0, 12, 3, 40, 424, 240),
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, required=True, help="output folder")
    ap.add_argument("--resume", action="store_true", help="reuse the finished runs in OUT/reconstruction/records.jsonl")
    args = ap.parse_args(argv)
    runs = _Runs(args.out / "reconstruction", cache_root(), print, resume=args.resume)
    for category, instance, seed, views, steps, width, height in SIZES:
        r = runs(protocol_case(category, instance, seed, views=views, frames=steps, width=width, height=height))
        cells = [f"{label} {fmt.format(r[k])}" for k, label, fmt in COLUMNS if r.get(k) is not None]
        if r["ok"]:
            cells.append(f"types {r['type_accuracy']:.2f}")
        print(f"  {r['case']}: " + (", ".join(cells) if r["ok"] else r["error"]), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
