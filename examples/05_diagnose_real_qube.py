"""05 — Diagnose a real machine: the Quanser Qube against its published model.

The nominal Furuta-pendulum URDF (models/furuta, the vendor's published masses, lengths and
dampings) against a real Qube-Servo 2 swinging freely (../shared/data/real/qube, a 2048-count
encoder, ~4 ms a sample, read every 8th), fitted in 1-s pieces.  Three other recordings of the
same machine: the first judges acceptance if the fit alone cannot (model-form error), the other
two are predicted before and after, never used.  ``--also`` fits further recordings together with
the first (one model for all, each from its own state).  Writes diagnosis.json, the augmented URDF
and the plots to OUT (default out/05_diagnose_real_qube).

    .venv/bin/python examples/05_diagnose_real_qube.py [--fit 12] [--also 2] [--others 1 4 7] [-o OUT]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinemaforge_opt.io.qube import read_qube_csv
from kinemaforge_opt.model import read_urdf
from kinemaforge_opt.physics.diagnose import diagnose
from kinemaforge_opt.physics.report import write_diagnosis

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real" / "qube" / "QQS2_data_diffx0"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", type=int, default=12, help="the recording diagnosed (example_csv_fin<N>.csv)")
    ap.add_argument("--also", type=int, nargs="*", default=[], help="recordings fitted together with --fit")
    ap.add_argument("--others", type=int, nargs="+", default=[1, 4, 7], help="other recordings of the same machine")
    ap.add_argument("-o", "--out", type=Path, default=Path("out/05_diagnose_real_qube"))
    args = ap.parse_args()

    model = read_urdf(ROOT / "models" / "furuta" / "furuta.urdf")
    load = lambda k: read_qube_csv(DATA / f"example_csv_fin{k}.csv", decimate=8)  # noqa: E731
    rec = load(args.fit)
    together = [rec] + [load(k) for k in args.also]
    others = tuple(load(k) for k in args.others)
    d = diagnose(model, together, segment_s=1.0, other_recordings=others, progress=lambda s: print(f"  … {s}"))
    print(d.summary())
    paths = write_diagnosis(d, rec, args.out, with_drift=False)
    print("wrote " + ", ".join(str(p) for p in paths.values()))


if __name__ == "__main__":
    main()
