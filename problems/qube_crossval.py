"""Every real Qube recording in turn as the one `diagnose` fits, three others predicted.

    PYTHONPATH=. .venv/bin/python -m problems.qube_crossval [--fits 1 2 ... 12] [--decimate 8] [--with 2]

For the fit recording fin<k> the others are fin<k+1>, fin<k+4>, fin<k+7> (numbered cyclically over
the 12 files of ../shared/data/real/qube): the first of them judges acceptance when the fit alone
cannot (the effects' figures then are not independent there, marked *).  Prints per fit the wall
time, the effects named, the prediction RMS [rad] of each other recording before → after (1-s
pieces, each from its own fitted state), and at the end how many independent predictions got
better, worse or stayed within ±5 %.  The same library call as ``problems.qube_diagnose``, nothing
tuned to a recording.  ``--with D ...``: fin<k+D> too are fitted together with fin<k> (one model
for all, each from its own state), the same three others predicted.
"""

from __future__ import annotations

import argparse
import time

from kinemaforge_opt.io.qube import read_qube_csv
from kinemaforge_opt.model import read_urdf
from problems.qube_diagnose import DATA, URDF

FILES = 12
SAME = 0.05  # a prediction within ±5 % of the nominal one counts as unchanged


def others_of(k: int) -> tuple[int, int, int]:
    """The three other recordings (1-based file numbers) predicted for fit recording ``k``."""
    return tuple((k - 1 + d) % FILES + 1 for d in (1, 4, 7))


def main() -> None:
    from kinemaforge_opt.physics.diagnose import diagnose

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fits", type=int, nargs="*", default=list(range(1, FILES + 1)))
    ap.add_argument("--decimate", type=int, default=8)
    ap.add_argument("--with", dest="together", type=int, nargs="*", default=[], metavar="D",
                    help="offsets of recordings fitted together with fin<k> (not 1, 4, 7: those are predicted)")
    a = ap.parse_args()
    if set(a.together) & {1, 4, 7}:
        ap.error("--with offsets 1, 4 and 7 are the predicted recordings")
    model = read_urdf(URDF)
    load = lambda k: read_qube_csv(DATA / f"example_csv_fin{k}.csv", decimate=a.decimate)  # noqa: E731
    tally = {"better": 0, "worse": 0, "unchanged": 0}
    print("| fit | wall [s] | effects | other recordings: prediction RMS before → after [rad] |")
    print("|---|---|---|---|")
    for k in a.fits:
        others = others_of(k)
        t0 = time.perf_counter()
        fitted = [k] + [(k - 1 + d) % FILES + 1 for d in a.together]
        recs = [load(f) for f in fitted]
        d = diagnose(model, recs, segment_s=1.0,
                     other_recordings=tuple(load(o) for o in others))
        wall = time.perf_counter() - t0
        cells = []
        for i, (o, h) in enumerate(zip(others, d.held_out_others)):
            used = i == d.other_used_for_selection
            cells.append(f"fin{o} {h.rms_before:.3f} → {h.rms_after:.3f}" + ("*" if used else ""))
            if not used:
                ratio = h.rms_after / h.rms_before
                tally["better" if ratio < 1 - SAME else "worse" if ratio > 1 + SAME else "unchanged"] += 1
        effects = ", ".join(f"{e.joint} {e.type.replace('_', ' ')}" for e in d.effects) or "none"
        print(f"| {' + '.join(f'fin{f}' for f in fitted)} | {wall:.1f} | {effects} | {'; '.join(cells)} |", flush=True)
    print(f"independent predictions: {tally['better']} better, {tally['worse']} worse, "
          f"{tally['unchanged']} within ±{SAME:.0%} (* judged acceptance: not counted)")


if __name__ == "__main__":
    main()
