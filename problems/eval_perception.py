"""Perception + constraint-graph evaluation on the synthetic world (issue 5).

Generates several instances of each category (cabinet, drawer, laptop, refrigerator, microwave)
with the D435-like sensor noise, runs ``perceive`` and ``graph.infer_tree`` on the RGB-D
sequence alone, and scores the result against the generator's ground truth (never read by the
estimators): joint-type accuracy, topology, part IoU of the point labels against the rendered
label images, closed-form axis and origin errors, and wall/CPU time per stage.

    PYTHONPATH=. .venv/bin/python -m problems.eval_perception -o /tmp/eval_perception \\
        [--categories cabinet drawer ...] [--instances 3] [--views 4] [--frames 30] [--size 640x480]

Reusable pieces (the benchmark calls these): :func:`instance_case` (the Case of one instance),
:func:`ground_truth` (joint lines and link labels of a generated case), :func:`score` (metrics of
a perception + graph result against it) and :func:`evaluate` (generate-or-reuse, run, score).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from kinemaforge_opt.bench.metrics import JointRecord, origin_error_m, part_iou_from_counts
from kinemaforge_opt.bench.reconstruction import label_confusion, true_joints
from kinemaforge_opt.graph import infer_tree
from kinemaforge_opt.graph.tree import GraphResult
from kinemaforge_opt.io.sequence import load_sequence
from kinemaforge_opt.perception import perceive
from kinemaforge_opt.perception.perceive import Perception
from kinemaforge_opt.perception.reconstruct import BASE, ENVIRONMENT, pixel_labels, point_labels, track_parts
from kinemaforge_opt.spatial import axis_angle_error
from kinemaforge_opt.synth import generate_case
from kinemaforge_opt.synth.case import Case

CATEGORIES = ("cabinet", "drawer", "laptop", "refrigerator", "microwave")
# Instance seeds: disjoint from the catalogue's (0, 100, 101) so the evaluation sees objects the
# methods were not developed on.
SEED0 = 500


def instance_case(category: str, instance: int, views: int = 4, frames: int = 30, width: int = 640,
                  height: int = 480) -> Case:
    """The Case of instance ``instance`` of ``category`` (seed SEED0 + instance, D435 noise)."""
    return Case(f"eval_{category}_{instance}", category, SEED0 + instance, views=views, frames=frames,
                width=width, height=height, expected="perception: joint types, topology, IoU ≥ 0.95, axis ≤ 3°")


@dataclass(frozen=True, eq=False)
class Truth:
    """Ground truth of a generated case: its movable joints and its folder (label images and
    legend under ground_truth/)."""

    joints: tuple[JointRecord, ...]
    root: Path


def ground_truth(case_root: str | Path) -> Truth:
    """The true movable joint lines (``bench.reconstruction.true_joints``) of a case written by
    ``generate_case``."""
    root = Path(case_root)
    return Truth(tuple(j for j in true_joints(root) if j.type != "fixed"), root)


def _confusion(per: Perception, graph: GraphResult, truth: Truth) -> tuple[dict, list[str], list[str]]:
    """Pixel counts {(predicted part, true label name): n} over every kept pixel of every frame
    (:func:`pixel_labels` with the sequence's RGB images)."""
    part_of = track_parts(graph, per.tracks)
    frames = [v.frame for c in per.clouds for v in c.views]
    seq = load_sequence(truth.root / "sequence")
    C, preds, trues = label_confusion(truth.root, frames, pixel_labels(per, point_labels(per, part_of), seq))
    counts = {(a, b): int(C[i, j]) for i, a in enumerate(preds) for j, b in enumerate(trues) if C[i, j]}
    return counts, sorted({a for a, _ in counts}), sorted({b for _, b in counts})


def _iou(counts: dict, pred: str, true: str, ignore_true=(), ignore_pred=()) -> float:
    inter = counts.get((pred, true), 0)
    p = sum(n for (a, b), n in counts.items() if a == pred and b not in ignore_true)
    t = sum(n for (a, b), n in counts.items() if b == true and a not in ignore_pred)
    return inter / max(p + t - inter, 1)


def score(per: Perception, graph: GraphResult, truth: Truth) -> dict:
    """Metrics of one result against the ground truth.

    Each predicted moving part is matched to the true link it shares most labelled pixels with.
    type_accuracy: share of true movable joints whose matched predicted joint (same child link,
    base parent) has the true type.  topology_ok: the predicted (parent, child, type) set equals
    the true one, with no extra joint.  iou_moving: per true moving link, IoU of the pixels
    labelled with its matched part (0 when unmatched); iou_base: the base part against the root
    link, pixels on the environment (true or predicted) left out.  axis_error_deg: the graph's
    closed-form axis vs the true one; origin_error_m: distance between the joint lines (revolute
    and helical; NaN for prismatic)."""
    counts, preds, trues = _confusion(per, graph, truth)
    tree = graph.best
    true_children = {j.child for j in truth.joints}
    root = next(iter({j.parent for j in truth.joints}), None)
    match = {}
    for p in preds:
        if p in (BASE, ENVIRONMENT):
            continue
        best = max(true_children, key=lambda c: counts.get((p, c), 0), default=None)
        if best is not None and counts.get((p, best), 0) > 0:
            match[p] = best
    predicted = []
    for j in tree.joints:
        parent = root if j.parent == tree.root else match.get(j.parent, f"?{j.parent}")
        child = match.get(j.child, f"?{j.child}")
        jtype = "fixed" if j.type == "rigid" else j.type
        predicted.append((parent, child, jtype, j))
    true_set = {(j.parent, j.child, j.type) for j in truth.joints}
    pred_set = {(a, b, t) for a, b, t, _ in predicted}
    per_joint = []
    for tj in truth.joints:
        cand = [x for x in predicted if x[1] == tj.child]
        row = {"joint": tj.name, "true_type": tj.type, "type": None, "axis_error_deg": np.nan,
               "origin_error_m": np.nan}
        if cand:
            _, _, jtype, j = max(cand, key=lambda x: x[3].hypothesis.confidence)
            h = j.hypothesis
            row["type"] = jtype
            if h.axis_world is not None:
                row["axis_error_deg"] = float(np.degrees(axis_angle_error(h.axis_world, tj.axis_world)))
                if tj.type in ("revolute", "helical") and h.origin_world is not None:
                    row["origin_error_m"] = origin_error_m(h.axis_world, h.origin_world, tj.origin_world)
        per_joint.append(row)
    ious = {}
    for c in sorted(true_children):
        parts = [p for p, t in match.items() if t == c]
        ious[c] = max((_iou(counts, p, c) for p in parts), default=0.0)
    C = np.array([[counts.get((a, b), 0) for b in trues] for a in preds], dtype=np.int64)
    bench = part_iou_from_counts(C, preds, trues, pred_ignore=(ENVIRONMENT,), true_ignore=("nothing", "environment"))
    env_true = ("environment", "nothing")
    iou_base = _iou(counts, BASE, root, ignore_true=env_true, ignore_pred=(ENVIRONMENT,)) if root else np.nan
    return {
        "type_accuracy": float(np.mean([r["type"] == r["true_type"] for r in per_joint])) if per_joint else np.nan,
        "topology_ok": bool(pred_set == true_set and len(predicted) == len(truth.joints)),
        "iou_moving": ious,
        "iou_base": float(iou_base),
        "part_iou": bench.mean_iou,
        "iou_parts": bench.iou,
        "joints": per_joint,
        "predicted": [(a, b, t) for a, b, t, _ in predicted],
        "proposals": len(per.proposals),
    }


def perceive_instance(root: str | Path, category: str, instance: int, **size) -> tuple[Perception, GraphResult, Truth]:
    """Generate instance ``instance`` of ``category`` (``size``: views, frames, width, height as in
    :func:`instance_case`) into ``root`` and return its perception, graph and ground truth."""
    root = Path(root)
    generate_case(instance_case(category, instance, **size), root)
    per, graph, _, _ = run(root / "sequence")
    return per, graph, ground_truth(root)


def run(seq_root: str | Path) -> tuple[Perception, GraphResult, dict, dict]:
    """perceive + infer_tree on a sequence; returns them with wall and CPU seconds per stage."""
    seq = load_sequence(seq_root)
    per = perceive(seq)
    t0, c0 = time.perf_counter(), time.process_time()
    with threadpool_limits(limits=1, user_api="blas"):
        graph = infer_tree(per.tracks)
    wall = {**per.timing_s, "graph": time.perf_counter() - t0}
    cpu = {**per.cpu_s, "graph": time.process_time() - c0}
    return per, graph, wall, cpu


def evaluate(case: Case, out_dir: str | Path, reuse: bool = True) -> dict:
    """Generate ``case`` under ``out_dir/case.name`` (or reuse it), run and score it."""
    root = Path(out_dir) / case.name
    if not (reuse and (root / "ground_truth" / "case.json").is_file()):
        generate_case(case, root)
    truth = ground_truth(root)
    try:
        per, graph, wall, cpu = run(root / "sequence")
    except Exception as e:  # a failed instance is a result (scored as wrong), not a crash
        return {"case": case.name, "category": case.category, "error": f"{type(e).__name__}: {e}",
                "type_accuracy": 0.0, "topology_ok": False, "iou_moving": {j.child: 0.0 for j in truth.joints},
                "iou_base": np.nan, "part_iou": 0.0, "joints": [], "wall_s": {}, "cpu_s": {}}
    out = score(per, graph, truth)
    return {"case": case.name, "category": case.category, **out, "wall_s": wall, "cpu_s": cpu}


def _fmt(x, spec):
    return "  -  " if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, spec)


def table(results: list[dict]) -> str:
    """Per-instance rows and a summary per category and overall."""
    stages = ("load", "clouds", "motion", "proposals+tracks", "resegment", "environment", "graph")
    head = (f"{'case':<22} {'types':>6} {'topo':>5} {'IoU mov':>8} {'IoU base':>8} {'IoU all':>7} {'axis°':>6} {'orig mm':>7} "
            + " ".join(f"{s[:8]:>8}" for s in stages) + f" {'total':>7} {'cpu':>6}")
    lines = [head, "-" * len(head)]
    for r in results:
        axes = [j["axis_error_deg"] for j in r["joints"]]
        origins = [j["origin_error_m"] for j in r["joints"]]
        iou = min(r["iou_moving"].values()) if r["iou_moving"] else np.nan
        w, c = r["wall_s"], r["cpu_s"]
        lines.append(
            f"{r['case']:<22} {_fmt(r['type_accuracy'], '6.2f')} {str(r['topology_ok'])[:5]:>5} {_fmt(iou, '8.3f')} "
            f"{_fmt(r['iou_base'], '8.3f')} {_fmt(r.get('part_iou', np.nan), '7.3f')} {_fmt(np.nanmax(axes) if axes and np.isfinite(axes).any() else np.nan, '6.2f')} "
            f"{_fmt(1e3 * np.nanmax(origins) if origins and np.isfinite(origins).any() else np.nan, '7.1f')} "
            + " ".join(f"{_fmt(w.get(s, np.nan), '8.2f')}" for s in stages)
            + f" {_fmt(sum(w.values()) if w else np.nan, '7.2f')} {_fmt(sum(c.values()) if c else np.nan, '6.2f')}"
            + (f"  ERROR {r['error']}" if "error" in r else ""))
    lines.append("-" * len(head))
    groups = {cat: [r for r in results if r["category"] == cat] for cat in dict.fromkeys(r["category"] for r in results)}
    groups["ALL"] = results
    for name, rs in groups.items():
        joints = [j for r in rs for j in r["joints"]]
        n_true = sum(len(r["iou_moving"]) for r in rs)
        type_ok = sum(j["type"] == j["true_type"] for j in joints)
        ious = [v for r in rs for v in r["iou_moving"].values()]
        part_ious = [r.get("part_iou", 0.0) for r in rs]
        axes = np.array([j["axis_error_deg"] for j in joints], dtype=float)
        origins = np.array([j["origin_error_m"] for j in joints], dtype=float)
        totals = [sum(r["wall_s"].values()) for r in rs if r["wall_s"]]
        cpus = [sum(r["cpu_s"].values()) for r in rs if r["cpu_s"]]
        lines.append(
            f"{name:<12} n={len(rs):<3} types {type_ok}/{n_true} = {type_ok / max(n_true, 1):.1%}  "
            f"topology {sum(r['topology_ok'] for r in rs)}/{len(rs)}  IoU moving mean {np.mean(ious) if ious else np.nan:.3f} "
            f"min {np.min(ious) if ious else np.nan:.3f}  part IoU (bench) mean {np.mean(part_ious):.3f}  axis° median {_fmt(np.nanmedian(axes) if np.isfinite(axes).any() else np.nan, '.2f')} "
            f"max {_fmt(np.nanmax(axes) if np.isfinite(axes).any() else np.nan, '.2f')}  origin mm median "
            f"{_fmt(1e3 * np.nanmedian(origins) if np.isfinite(origins).any() else np.nan, '.1f')}  "
            f"time s median {_fmt(np.median(totals) if totals else np.nan, '.2f')} (cpu {_fmt(np.median(cpus) if cpus else np.nan, '.2f')})")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--out", required=True, help="folder for generated cases and results.json")
    ap.add_argument("--categories", nargs="+", default=list(CATEGORIES))
    ap.add_argument("--instances", type=int, default=3)
    ap.add_argument("--first", type=int, default=0, help="first instance number")
    ap.add_argument("--views", type=int, default=4)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--size", default="640x480", help="WIDTHxHEIGHT [px]")
    ap.add_argument("--keep", action="store_true", help="keep the generated cases (default: delete after scoring)")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    out = Path(args.out)
    results = []
    for cat in args.categories:
        for i in range(args.first, args.first + args.instances):
            case = instance_case(cat, i, args.views, args.frames, w, h)
            r = evaluate(case, out)
            results.append(r)
            print(table([r]).splitlines()[2], flush=True)
            if not args.keep:
                import shutil

                shutil.rmtree(out / case.name, ignore_errors=True)
    print(table(results))
    (out / "results.json").write_text(json.dumps(results, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
