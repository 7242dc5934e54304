"""Part IoU of a reconstruction's pixel labels without and with the parts' solids over their
fitted motion (``perception/solids.py``), on generated cases.

    PYTHONPATH=. .venv/bin/python -m problems.solid_labels CASE_ROOT [CASE_ROOT ...]

A CASE_ROOT is a generated case folder (``sequence/`` and ``ground_truth/``), e.g. the held-out
instances that ``problems.eval_perception --keep -o DIR`` leaves in DIR.  Each case runs
perception, the graph and the screw NLP (``refine_model``, as ``kinemaforge reconstruct`` does);
"without" is the perception stage's point labels, "with" the labels the reconstruction reports.
Both are scored like the benchmark (``bench.reconstruction.label_metrics``).  Prints a line per
case and the means.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinemaforge_opt.bench.reconstruction import label_metrics
from kinemaforge_opt.graph import infer_tree
from kinemaforge_opt.io.sequence import load_sequence
from kinemaforge_opt.nlp.reconstruction import ScrewOptions
from kinemaforge_opt.perception import perceive
from kinemaforge_opt.perception.reconstruct import DEFAULT_DENSITY, point_labels, refine_model, track_parts


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+", type=Path, help="generated case folders")
    args = ap.parse_args(argv)
    rows = []
    for root in args.cases:
        seq = load_sequence(root / "sequence")
        per = perceive(seq)
        graph = infer_tree(per.tracks)
        labels = refine_model(per, graph, seq, DEFAULT_DENSITY, ScrewOptions())[4]
        rows.append((label_metrics(root, seq, per, point_labels(per, track_parts(graph, per.tracks))).mean_iou,
                     label_metrics(root, seq, per, labels).mean_iou))
        print(f"{root.name}: part IoU without solids {rows[-1][0]:.4f}, with {rows[-1][1]:.4f}", flush=True)
    print(f"mean over {len(rows)}: without {sum(r[0] for r in rows) / len(rows):.4f}, "
          f"with {sum(r[1] for r in rows) / len(rows):.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
