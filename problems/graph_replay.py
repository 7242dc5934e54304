"""Replay the constraint graph on saved perception tracks, scored against ground truth (issue 6).

Perception costs tens of CPU seconds per case; the graph a fraction of one.  ``dump`` runs
``perceive`` once on a generated case and saves, under OUT/<case folder>/, the proposal tracks
(``tracks.csv``) and ``labels.json``: for every proposal the true link it shares most labelled
pixels with (each proposal labelled as its own part).  ``score`` reruns ``graph.infer_tree`` on
saved tracks and scores joint types, topology and closed-form axis errors against the case's
ground truth (``bench.reconstruction.true_joints``), with the CPU time of the graph.

    PYTHONPATH=. .venv/bin/python -m problems.graph_replay dump -o /tmp/graph_replay CASE_ROOT...
    PYTHONPATH=. .venv/bin/python -m problems.graph_replay score -o /tmp/graph_replay [CASE_FOLDER...]

CASE_ROOT: a folder written by ``generate_case`` (e.g. ~/.cache/kinemaforge/bench/protocol_microwave_0-…).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from kinemaforge_opt.bench.reconstruction import label_confusion, true_joints
from kinemaforge_opt.graph import infer_tree
from kinemaforge_opt.io.tracks import read_tracks, write_tracks
from kinemaforge_opt.spatial import axis_angle_error


def dump(case_root: Path, out: Path) -> None:
    """perceive ``case_root``/sequence; write OUT/tracks.csv, OUT/labels.json and OUT/case_root.txt."""
    from kinemaforge_opt.io.sequence import load_sequence
    from kinemaforge_opt.perception import perceive
    from kinemaforge_opt.perception.reconstruct import pixel_labels, point_labels

    seq = load_sequence(case_root / "sequence")
    c0 = time.process_time()
    per = perceive(seq)
    cpu = time.process_time() - c0
    own = {n: n for n in per.tracks.names}
    frames = [v.frame for c in per.clouds for v in c.views]
    C, preds, trues = label_confusion(case_root, frames, pixel_labels(per, point_labels(per, own), seq))
    counts = {p: {t: int(C[i, j]) for j, t in enumerate(trues) if C[i, j]} for i, p in enumerate(preds)}
    out.mkdir(parents=True, exist_ok=True)
    write_tracks(out / "tracks.csv", per.tracks)
    (out / "labels.json").write_text(json.dumps({"case_root": str(case_root), "counts": counts,
                                                 "perception_cpu_s": cpu}, indent=1))


def score(folder: Path) -> dict:
    """infer_tree on folder/tracks.csv, scored against the ground truth of the case it came from."""
    meta = json.loads((folder / "labels.json").read_text())
    counts = meta["counts"]
    tracks = read_tracks(folder / "tracks.csv")
    truth = [j for j in true_joints(Path(meta["case_root"])) if j.type != "fixed"]
    c0 = time.process_time()
    graph = infer_tree(tracks)
    cpu = time.process_time() - c0
    tree = graph.best
    root = next(iter({j.parent for j in truth}), None)
    children = {j.child for j in truth}

    def true_link(part: str) -> str:
        if part == tree.root:
            return root
        votes = {c: sum(counts.get(m, {}).get(c, 0) for m in tree.parts[part]) for c in children}
        best = max(votes, key=votes.get, default=None)
        return best if best is not None and votes[best] > 0 else f"?{part}"

    pred = [(true_link(j.parent), true_link(j.child), "fixed" if j.type == "rigid" else j.type, j) for j in tree.joints]
    rows = []
    for tj in truth:
        cand = [x for x in pred if x[1] == tj.child]
        row = {"joint": tj.name, "true_type": tj.type, "type": None, "axis_error_deg": None}
        if cand:
            _, _, jtype, j = max(cand, key=lambda x: x[3].hypothesis.confidence)
            row["type"] = jtype
            if j.hypothesis.axis_world is not None:
                row["axis_error_deg"] = float(np.degrees(axis_angle_error(j.hypothesis.axis_world, tj.axis_world)))
        rows.append(row)
    topology = {(a, b, t) for a, b, t, _ in pred} == {(j.parent, j.child, j.type) for j in truth} and len(pred) == len(truth)
    return {"case": folder.name, "joints": rows, "topology_ok": bool(topology), "graph_cpu_s": cpu,
            "predicted": [(a, b, t, j.parent, j.child) for a, b, t, j in pred]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("command", choices=("dump", "score"))
    ap.add_argument("-o", "--out", required=True, help="folder of the saved tracks (one subfolder per case)")
    ap.add_argument("cases", nargs="*", help="dump: case roots; score: case subfolders (default: all under OUT)")
    args = ap.parse_intermixed_args(argv)
    out = Path(args.out)
    if args.command == "dump":
        for c in args.cases:
            root = Path(c).expanduser()
            dump(root, out / root.name)
            print(f"dumped {root.name}", flush=True)
        return 0
    folders = [out / c for c in args.cases] if args.cases else sorted(p.parent for p in out.glob("*/labels.json"))
    n_ok = n_joints = n_topo = 0
    axes = []
    for f in folders:
        r = score(f)
        n_joints += len(r["joints"])
        n_ok += sum(j["type"] == j["true_type"] for j in r["joints"])
        n_topo += r["topology_ok"]
        axes += [j["axis_error_deg"] for j in r["joints"] if j["type"] == j["true_type"] and j["axis_error_deg"] is not None]
        joints = ", ".join(f"{j['joint']}:{j['type']}" + (f" {j['axis_error_deg']:.1f}°" if j["axis_error_deg"] is not None else "")
                           for j in r["joints"])
        est = " ".join(f"{pp}→{pc}:{t}" for _, _, t, pp, pc in r["predicted"])
        print(f"{r['case']:<40} topo {str(r['topology_ok']):<5} cpu {r['graph_cpu_s']:5.2f}s  {joints}  | {est}", flush=True)
    print(f"types {n_ok}/{n_joints}  topology {n_topo}/{len(folders)}  axis° (correct type) "
          f"max {max(axes) if axes else float('nan'):.2f} median {np.median(axes) if axes else float('nan'):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
