"""Reconstruction of the catalogue's cases that no table runs: a drawer above a door
(protocol_cabinet_multi_0, _1) and two doors seen by one moving camera (protocol_moving_cabinet),
scored exactly as Table 1 scores its runs (``bench.reconstruction.evaluate_case``).

    PYTHONPATH=. .venv/bin/python -m problems.outside_table1 -o DIR [--resume] [--cases NAME ...]

The static-camera cases run at Table 1's size (8 views × 20 steps at 640×480); the moving camera
at its catalogue size.  Each run is appended to DIR/reconstruction/records.jsonl as it finishes
(``--resume`` reuses them); prints one line per run.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from kinemaforge_opt.bench.reconstruction import RECO_FULL, _Runs, cache_root

from .catalogue import get_case

CASES = ("protocol_cabinet_multi_0", "protocol_cabinet_multi_1", "protocol_moving_cabinet")
COLUMNS = (("part_iou", "part IoU", "{:.3f}"), ("axis_error_deg", "axis °", "{:.2f}"),
           ("origin_error_m", "origin m", "{:.3f}"), ("inertia_error", "inertia err", "{:.3f}"),
           ("drift_1s_m", "1-s drift m", "{:.3f}"), ("truth_continued_drift_50s_m", "50-s vs true m", "{:.3f}"),
           ("energy_residual", "energy", "{:.3f}"), ("topology_correct", "topology", "{}"), ("wall_s", "wall s", "{:.0f}"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, required=True, help="output folder")
    ap.add_argument("--resume", action="store_true", help="reuse the finished runs in OUT/reconstruction/records.jsonl")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    args = ap.parse_args(argv)
    runs = _Runs(args.out / "reconstruction", cache_root(), print, resume=args.resume)
    for name in args.cases:
        case = get_case(name)
        if not case.moving_camera:
            case = dataclasses.replace(case, views=RECO_FULL.views, frames=RECO_FULL.frames,
                                       width=RECO_FULL.width, height=RECO_FULL.height)
        r = runs(case)
        cells = (f"{label} {fmt.format(r[k])}" for k, label, fmt in COLUMNS if r.get(k) is not None)
        print(f"  {r['case']}: " + (", ".join(cells) if r["ok"] else r["error"]), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
