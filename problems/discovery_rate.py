"""diagnose on the concealed-effects set recorded at another rate than the benchmark's 30 Hz.

    PYTHONPATH=. .venv/bin/python -m problems.discovery_rate [--hz 100] [--cases NAME ...]

Same cases, noise and scoring as ``kinemaforge bench --parts discovery`` (diagnose only), but the
MuJoCo episodes are sampled at ``--hz``: a check that the search on block means (see
``physics.diagnose.SEARCH_RATE_HZ``) finds what the 30-Hz recordings show.  Prints per case the
truth, what was found, the CPU time, and the summary (precision, recall, F1, null FPs).
"""

from __future__ import annotations

import argparse
import time

from kinemaforge_opt.bench.discovery import HOLDOUT, _score, summarise
from kinemaforge_opt.bench.recordings import effect_recording
from kinemaforge_opt.bench.run import discovery_cases
from kinemaforge_opt.physics.diagnose import diagnose


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hz", type=int, default=100)
    ap.add_argument("--cases", nargs="*", help="catalogue cases (default: the quick discovery set)")
    ap.add_argument("--noise-seed", type=int, default=0)
    args = ap.parse_args(argv)
    scores, cpu_total = [], 0.0
    for case in args.cases or discovery_cases(pairs=False):
        er = effect_recording(case, args.noise_seed, rate_hz=args.hz)
        truth = {e.type: e.value for e in er.shown_effects}
        c0, w0 = time.process_time(), time.perf_counter()
        d = diagnose(er.model, er.recording, holdout_fraction=HOLDOUT)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        cpu_total += cpu
        eq = {e.type: {a["type"]: a["value"] for a in e.params.get("equivalent", ()) if a["joint"] == e.joint}
              for e in d.effects}
        found = {e.type: e.value for e in d.effects}
        s = _score(case, "diagnose", truth, found, (d.held_out.rms_before if d.held_out else None,
                                                    d.held_out.rms_after if d.held_out else None), wall, eq)
        scores.append(s)
        print(f"{case:48s} truth {','.join(sorted(truth)) or '-':30s} found "
              f"{','.join(f'{k}={v:.4g}' for k, v in found.items()) or '-':40s} {cpu:5.2f} s CPU", flush=True)
    m = summarise(scores)["diagnose"]
    print(f"{args.hz} Hz, {len(scores)} cases: precision {m['precision']:.2f}, recall {m['recall']:.2f}, F1 {m['f1']:.2f} "
          f"(equivalents credited {m['f1_equivalence_classes']:.2f}), null FPs {m['null_false_positives']}, "
          f"median value error {100 * m['median_value_error']:.1f} %, CPU {cpu_total:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
