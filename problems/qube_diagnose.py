"""Diagnose the real Quanser Qube against the nominal Furuta model, on full recordings.

    PYTHONPATH=. .venv/bin/python -m problems.qube_diagnose [--fit 1] [--others 2 3 5] [--decimate 8]
        [--segment 1.0] [--no-screen] [--max-effects N] [-o OUT]

Reads ``example_csv_fin<k>.csv`` of ../shared/data/real/qube (``read_qube_csv``, every
``decimate``-th sample: ~31 Hz at 8), runs :func:`kinemaforge_opt.physics.diagnose.diagnose` of
models/furuta/furuta.urdf on the fit recording with the others as further recordings, and prints
each tested hypothesis, the selected effects, the acceptance check used and the prediction RMS
before/after on every other recording, with wall and CPU time (the forked fits' included).  Nothing here is tuned to the
Qube: it is the library call a user would make.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from kinemaforge_opt.io.qube import read_qube_csv
from kinemaforge_opt.model import read_urdf
from kinemaforge_opt.parallel import cpu_seconds
from kinemaforge_opt.physics.diagnose import MAX_EFFECTS, SCREEN, diagnose

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "qube" / "QQS2_data_diffx0"
URDF = Path(__file__).resolve().parents[1] / "models" / "furuta" / "furuta.urdf"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fit", type=int, default=1)
    ap.add_argument("--others", type=int, nargs="*", default=[2, 3, 5])
    ap.add_argument("--decimate", type=int, default=8)
    ap.add_argument("--segment", type=float, default=1.0)
    ap.add_argument("--no-screen", action="store_true", help="fit every hypothesis (no linear pre-screen)")
    ap.add_argument("--max-effects", type=int, default=MAX_EFFECTS)
    ap.add_argument("-o", "--out", default=None, help="write diagnosis.json and plots here")
    a = ap.parse_args()
    rec = read_qube_csv(DATA / f"example_csv_fin{a.fit}.csv", decimate=a.decimate)
    others = tuple(read_qube_csv(DATA / f"example_csv_fin{k}.csv", decimate=a.decimate) for k in a.others)
    t0, c0 = time.perf_counter(), cpu_seconds()
    d = diagnose(read_urdf(URDF), rec, segment_s=a.segment, other_recordings=others,
                 screen=None if a.no_screen else SCREEN, max_effects=a.max_effects, progress=lambda s: print("  ..", s, flush=True))
    wall, cpu = time.perf_counter() - t0, cpu_seconds() - c0
    for row in d.tested:
        print({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items() if k not in ("status", "n_eff")})
    print(d.summary())
    print(f"others: fin{a.others}; wall {wall:.1f} s, CPU {cpu:.1f} s")
    if a.out:
        from kinemaforge_opt.physics.report import write_diagnosis

        write_diagnosis(d, rec, a.out, with_drift=False)
        print(json.dumps({"effects": [e.to_dict() for e in d.effects]}, indent=1))


if __name__ == "__main__":
    main()
