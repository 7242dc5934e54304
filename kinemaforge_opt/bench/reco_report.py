"""Markdown tables and PNG plots of the reconstruction benchmark (:mod:`.reconstruction`): the
seed's Table 1 beside the seed paper's numbers, Table 2 ablations, drift vs horizon, sensitivity
to the energy weight and to the number of views, time per stage vs frames / views / joints."""

from __future__ import annotations

from pathlib import Path

from .report import save_png

NOT_AVAILABLE = "not available"
# (result key, column header, format); drift, energy: from reconstruction.json["verification"]
COLUMNS = (
    ("axis_error_deg", "axis error [deg]", ".2f"),
    ("origin_error_m", "origin error [m]", ".3f"),
    ("inertia_error", "inertia error", ".3f"),
    ("part_iou", "part IoU", ".3f"),
    ("moving_part_iou", "moving-part IoU", ".3f"),
    ("drift_1s_m", "1-s drift [m]", ".3f"),
    ("drift_50s_m", "50-s drift [m]", ".3f"),
    ("energy_residual", "energy residual", ".3f"),
    ("joints_found", "joints found", ".2f"),
    ("type_accuracy", "joint type correct", ".2f"),
    ("topology_correct", "topology correct", ".2f"),
)


# the true model replayed by the same verifier on the same protocol (the floor the protocol sets)
TRUTH_COLUMNS = (
    ("truth_drift_1s_m", "1-s drift [m]", ".3f"),
    ("truth_drift_50s_m", "50-s drift [m]", ".3f"),
    ("truth_energy_residual", "energy residual", ".3f"),
)

# the reconstruction's replay against the true model simulated on (bench only; see
# reconstruction.drift_vs_true_model), beside the tool's held-last-pose definition
CONTINUED_COLUMNS = (
    ("drift_1s_m", "1-s drift, tool definition [m]", ".3f"),
    ("truth_continued_drift_1s_m", "1-s drift vs true model continued [m]", ".3f"),
    ("drift_50s_m", "50-s drift, tool definition (last pose held) [m]", ".3f"),
    ("truth_continued_drift_50s_m", "50-s drift vs true model continued [m]", ".3f"),
)


def _table(head: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def _cell(stat: dict, spec: str) -> str:
    """'mean ± std (n)' of a :func:`.reconstruction.summarise` entry; n/a when nothing measured."""
    if not stat or not stat.get("n"):
        return "n/a"
    return f"{stat['mean']:{spec}} ± {stat['std']:{spec}} ({stat['n']})"


def _count(s: dict) -> str:
    notes = [f"{s[k]} {k}" for k in ("failed", "skipped") if s.get(k)]
    return f"{s['cases']}" + (f" ({', '.join(notes)})" if notes else "")


def _metric_row(label: str, s: dict) -> list[str]:
    return [label, _count(s)] + [_cell(s[k], f) for k, _, f in COLUMNS]


def reconstruction_tables(reco: dict) -> str:
    """The Markdown of the reconstruction part."""
    size = reco["size"]
    head = ["category", "cases"] + [h for _, h, _ in COLUMNS]
    seed = reco["seed_paper"]
    rows = [_metric_row(c, s) for c, s in reco["table1"].items()]
    rows.append(["**seed paper (average)**", "–"] + [format(seed[k], f) if k in seed else "–" for k, _, f in COLUMNS])
    protocol = (f"Protocol: {', '.join(size['categories'])}; instances {list(size['instances'])} × repetition seeds "
                f"{list(size['seeds'])}; {size['views']} static views × {size['frames']} time steps at "
                f"{size['width']}×{size['height']} px, D435-like noise (the seed paper: 8 views, 640×480).  "
                "Cells: mean ± std over instances and seeds (n = cases measured).  Axis error: angle between "
                "estimated and true axis, sign-agnostic; origin error: distance between the estimated and true "
                "joint lines (revolute only); inertia error: |M_kk / M_kk,true − 1| of each matched joint, what it "
                "moves at q = 0 (the inertia of its subtree about the axis, or its mass along a translation), "
                "mean over the object's joints; joints found: share of the true movable joints matched by a "
                "movable estimate; part IoU: per-pixel labels vs ground truth, parts matched by the "
                "Hungarian method, mean over the object's true parts (moving-part IoU: over the parts a joint "
                "moves, without the static body, whose IoU suffers from any background left unlabelled as "
                "environment); joints are matched through the part "
                "matching (then by geometry); a true joint with no movable estimate counts as wrong type and is "
                "left out of the axis/origin means; a failed reconstruction counts 0 in joints found, type and "
                "topology and is left out of the other columns.  Drift, energy residual: the Drake verification of "
                "`kinemaforge reconstruct` (reconstruction.json \"verification\"); past the recording's end the "
                "drift compares with the last measured pose held.")
    out = [f"## Table 1 — reconstruction per category ({size['name']} size)\n\n{protocol}\n\n{_table(head, rows)}\n"]
    truth_rows = [[c, _count(s)] + [_cell(s.get(k, {}), f) for k, _, f in TRUTH_COLUMNS] for c, s in reco["table1"].items()]
    if any(s.get(k, {}).get("n") for s in reco["table1"].values() for k, _, _ in TRUTH_COLUMNS):
        out.append("### The true model through the same verifier (the floor the protocol sets)\n\n"
                   "The ground truth's own URDF replayed exactly as a reconstruction is: q from the true link poses at "
                   "the rendered time steps, τ from wrenches.csv, initial velocity fitted to the first 0.25 s, the "
                   "last pose held past the recording.  A perfect reconstruction scores these, not 0.\n\n"
                   + _table(["category", "cases"] + [h for _, h, _ in TRUTH_COLUMNS], truth_rows) + "\n")

    if any(s.get(k, {}).get("n") for s in reco["table1"].values() for k, _, _ in CONTINUED_COLUMNS[1::2]):
        crows = [[c, _count(s)] + [_cell(s.get(k, {}), f) for k, _, f in CONTINUED_COLUMNS] for c, s in reco["table1"].items()]
        out.append("### Drift against the true model continued (benchmark only)\n\n"
                   "The same Drake replay of each reconstruction, compared with the ground-truth URDF simulated in Drake "
                   "from the true state at the recording's start under the true applied force (MuJoCo's 120 Hz record), "
                   "mapped into the reconstruction's joints.  The tool's definition (Table 1) compares with the "
                   "measured pose within the recording and with the last measured pose held after it, which scores "
                   "a still-moving object (a door bouncing off its stop) as drift even for the true model.\n\n"
                   + _table(["category", "cases"] + [h for _, h, _ in CONTINUED_COLUMNS], crows) + "\n")

    rows2 = []
    for v, s in reco["table2"].items():
        if not s["available"]:
            rows2.append([v, "–"] + [f"{NOT_AVAILABLE} ({s['reason']})"] + ["–"] * (len(COLUMNS) - 1))
        else:
            rows2.append(_metric_row(v, s))
    out.append("## Table 2 — ablations\n\nOn " + ", ".join(size["ablation_categories"])
               + f" (instances {list(size.get('ablation_instances', size['instances']))}, same size as Table 1).\n\n"
               + _table(["variant", "cases"] + [h for _, h, _ in COLUMNS], rows2) + "\n")

    seed_drift = {"1": seed.get("drift_1s_m"), "50": seed.get("drift_50s_m")}
    rows3 = [[h, _cell(d, ".3f"), "–" if seed_drift.get(h) is None else f"{seed_drift[h]:.3f}"]
             for h, d in reco["drift_vs_horizon"].items()]
    out.append("## Drift vs horizon (Table 1 cases)\n\n" + _table(["horizon [s]", "drift [m]", "seed paper [m]"], rows3) + "\n")

    e = reco["sensitivity"]["energy_weight"]
    if not e["available"]:
        etxt = f"{NOT_AVAILABLE}: {e['reason']}."
    else:
        etxt = _table(["energy weight", "cases"] + [h for _, h, _ in COLUMNS],
                      [_metric_row(f"{p['energy_weight']:g}", p) for p in e["points"]])
    vrows = [_metric_row(str(p["views"]), p) + [f"{p['mean_wall_s']:.1f}"] for p in reco["sensitivity"]["views"]]
    on = f" (instance 0 of {', '.join(e['categories'])})" if e.get("categories") else ""
    out.append(f"## Sensitivity to the energy weight{on}\n\n" + etxt + "\n\n"
               f"## Sensitivity to the number of views ({size['sweep_category']} instance 0)\n\n"
               + _table(["views", "cases"] + [h for _, h, _ in COLUMNS] + ["wall time [s]"], vrows) + "\n")

    sc = reco["scaling"]
    stages = list(dict.fromkeys(s for sweep in sc.values() for s in sweep))
    xs = {k: sc[k].get("total", {}).get("x", []) for k in sc}
    srows = [[s] + [("–" if sc[k].get(s, {}).get("exponent") is None else f"{sc[k][s]['exponent']:.2f}") for k in sc]
             for s in stages]
    prow = [[k, str(x), f"{t:.2f}", f"{c:.2f}"] for k in sc for x, t, c in
            zip(xs[k], sc[k].get("total", {}).get("time_s", []), sc[k].get("cpu", {}).get("time_s", []))]
    out.append("## Time per stage vs frames, views and joints (fitted log-log exponents: time ∝ x^p)\n\n"
               f"Frames and views swept on {size['sweep_category']} instance 0; joints: Table 1 cases grouped by their "
               "number of movable joints (so the category changes with it).  Only runs that found a movable joint "
               "(so every stage ran) count.  `cpu`: process CPU time.\n\n"
               + _table(["stage"] + [f"p ({k}: {', '.join(map(str, xs[k]))})" for k in sc], srows) + "\n\n"
               + _table(["sweep", "x", "total wall [s]", "CPU [s]"], prow) + "\n")

    fails = [r for r in reco["records"] if not r["ok"] or r.get("verification_error")]
    if fails:
        out.append("### Failures and skipped runs\n\n" + "\n".join(
            f"- {r['case']} {r['options'] or ''}: {r['error'] or 'verification: ' + r['verification_error']}"
            for r in fails) + "\n")
    out.append(f"Reconstruction part: {reco['total_s']:.0f} s wall (case generation {reco['generation_s']:.0f} s; "
               "cached cases are reused).\n")
    return "\n".join(out)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_drift(reco: dict, path: Path) -> Path | None:
    """Drift [m] vs horizon [s] (mean ± std over the Table 1 cases, and each case), with the
    seed paper's 1-s and 50-s points; None when no case has a verification."""
    d = reco["drift_vs_horizon"]
    hs = [h for h in d if d[h]["n"]]
    if not hs:
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5, 4))
    t1 = set(reco.get("table1_cases", []))
    recs = [r for r in reco["records"] if r["ok"] and r.get("drift_m") and r["options"] == {} and r["case"] in t1]
    for r in recs:
        x = [float(h) for h in r["drift_m"]]
        ax.plot(x, list(r["drift_m"].values()), "-", color="0.8", lw=0.8)
    ax.errorbar([float(h) for h in hs], [d[h]["mean"] for h in hs], yerr=[d[h]["std"] for h in hs], fmt="o-",
                capsize=3, label="kinemaforge_opt (mean ± std)")
    seed = reco["seed_paper"]
    ax.plot([1, 50], [seed["drift_1s_m"], seed["drift_50s_m"]], "s", color="C3", label="seed paper")
    ax.set_xscale("log")
    ax.set_xlabel("horizon [s]")
    ax.set_ylabel("drift [m]")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    return save_png(fig, path)


def plot_sensitivity(reco: dict, path: Path) -> Path | None:
    """Axis error, part IoU and 1-s drift vs the number of views (and vs the energy weight when
    that option exists)."""
    views = reco["sensitivity"]["views"]
    e = reco["sensitivity"]["energy_weight"]
    if not views:
        return None
    plt = _plt()
    ncol = 2 if e["available"] and e["points"] else 1
    fig, axes = plt.subplots(1, ncol, figsize=(5 * ncol, 4), squeeze=False)

    def draw(ax, xs, pts, xlabel, log=False):
        for k, label, c in (("axis_error_deg", "axis error [deg]", "C0"), ("part_iou", "part IoU", "C1"),
                            ("drift_1s_m", "1-s drift [m]", "C2"), ("type_accuracy", "joint type correct", "C3")):
            ys = [p[k]["mean"] if p[k]["n"] else float("nan") for p in pts]
            ax.plot(xs, ys, "o-", color=c, label=label)
        ax.set_xlabel(xlabel)
        ax.set_yscale("symlog", linthresh=0.01)
        if log:
            ax.set_xscale("symlog", linthresh=0.1)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)

    draw(axes[0, 0], [p["views"] for p in views], views, "views")
    if ncol == 2:
        draw(axes[0, 1], [p["energy_weight"] for p in e["points"]], e["points"], "energy weight", log=True)
    return save_png(fig, path)


def plot_stage_scaling(reco: dict, path: Path) -> Path | None:
    """Log-log time per stage vs frames, views and joints with the fitted exponent per stage."""
    sc = reco["scaling"]
    if not any(s.get("total", {}).get("x") for s in sc.values()):
        return None
    plt = _plt()
    import numpy as np

    fig, axes = plt.subplots(1, len(sc), figsize=(5 * len(sc), 4), squeeze=False)
    for ax, (key, sweep) in zip(axes[0], sc.items()):
        for i, (stage, s) in enumerate(sweep.items()):
            if len(s["x"]) < 1 or stage == "cpu":
                continue
            x, y = np.array(s["x"], float), np.array(s["time_s"], float)
            lab = stage + ("" if s["exponent"] is None else f" (p = {s['exponent']:.2f})")
            ax.loglog(x, y, "o-", color=f"C{i % 10}", label=lab, lw=2 if stage == "total" else 1)
        xs = sorted({x for s in sweep.values() for x in s["x"]})
        if xs:
            from matplotlib.ticker import NullFormatter

            ax.set_xticks(xs)
            ax.set_xticklabels([str(x) for x in xs])
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(key)
        ax.set_ylabel("time [s]")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "no complete run", ha="center", va="center", transform=ax.transAxes)
    return save_png(fig, path)
