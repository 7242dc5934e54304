"""Write the benchmark: ``bench.json`` (everything measured), ``bench.md`` (the tables) and PNG
plots.  The reconstruction tables (Table 1, Table 2, drift, sensitivity, stage scaling) come from
:mod:`.reco_report`; without a reconstruction part they print "not yet measured"."""

from __future__ import annotations

import json
from pathlib import Path

from ..io.atomic import atomic_path, write_text_atomic

NOT_MEASURED = "not yet measured"
TABLE1_CATEGORIES = ("cabinet", "drawer", "laptop", "refrigerator", "microwave", "average")
TABLE1_METRICS = ("axis error [deg]", "origin error [cm]", "part IoU", "1-s drift [m]", "energy residual")
TABLE2_VARIANTS = ("full", "w/o coarse-to-fine", "w/o energy", "w/o NLP", "w/o graph")


def _fmt(x, spec: str = ".3g") -> str:
    return "–" if x is None else format(x, spec)


def _table(head: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def placeholder_tables() -> str:
    """The seed's Table 1 and Table 2 and the drift-vs-horizon table, every cell "not yet
    measured": they need RGB-D reconstruction (perception), which is not built yet."""
    t1 = _table(["category"] + list(TABLE1_METRICS), [[c] + [NOT_MEASURED] * len(TABLE1_METRICS) for c in TABLE1_CATEGORIES])
    t2 = _table(["variant"] + list(TABLE1_METRICS), [[v] + [NOT_MEASURED] * len(TABLE1_METRICS) for v in TABLE2_VARIANTS])
    t3 = _table(["horizon [s]", "drift [m]"], [[h, NOT_MEASURED] for h in ("1", "5", "10", "20", "50")])
    return (f"## Table 1 — reconstruction per category (seed protocol)\n\n{t1}\n\n"
            f"## Table 2 — ablations\n\n{t2}\n\n## Drift vs horizon\n\n{t3}\n")


def discovery_tables(summary: dict, cases: list[dict]) -> str:
    head = ["method", "cases", "precision", "recall", "F1", "F1 (equivalent explanations credited)",
            "F1 on supported cases (credited)", "FP on null cases", "median value error",
            "median held-out RMS gain (last quarter)", "median held-out RMS gain (second recording)",
            "effect cases ≥ 5× on the second recording (supported)", "mean time [s]"]
    rows = [[m, str(s["cases"]), _fmt(s["precision"], ".2f"), _fmt(s["recall"], ".2f"), _fmt(s["f1"], ".2f"),
             _fmt(s.get("f1_equivalence_classes"), ".2f"),
             f"{_fmt(s.get('f1_supported'), '.2f')} ({_fmt(s.get('f1_supported_equivalence_classes'), '.2f')}) "
             f"on {s.get('supported_cases', '–')}",
             str(s["null_false_positives"]), _fmt(s["median_value_error"], ".1%"),
             _fmt(s["median_heldout_gain"], ".2f") + "×", _fmt(s.get("median_other_gain"), ".1f") + "×",
             f"{_fmt(s.get('other_gain_at_bar'), '.0%')} ({_fmt(s.get('other_gain_at_bar_supported'), '.0%')})",
             _fmt(s["mean_time_s"], ".2f")] for m, s in summary.items()]
    per = [[c["case"], c["method"], ", ".join(c["truth"]) or "(none)", ", ".join(c["found"]) or "(none)",
            str(c["false_positives"]), ", ".join(f"{k} {v:.1%}" for k, v in c["value_error"].items()) or "–",
            _fmt(c["rms_before"], ".4f"), _fmt(c["rms_after"], ".4f"), _fmt(c.get("other_rms_before"), ".4f"),
            _fmt(c.get("other_rms_after"), ".4f"), _fmt(c.get("oracle_delta_bic"), ".0f")] for c in cases]
    per_head = ["case", "method", "truth", "found", "FP", "value error", "held-out RMS before", "after",
                "second recording RMS before", "after", "oracle ΔBIC"]
    return (f"## Mismatch discovery on the concealed-effects set\n\n{_table(head, rows)}\n\n"
            "Supported cases: the null cases and the effect cases whose true effects, fitted from their "
            "true values, gain ΔBIC < −10 on the recording (the oracle ΔBIC, `bench.detectability`); "
            "at or above it even the truth does not fit the recording better than the nominal model by "
            "diagnose's selection margin.  Held-out RMS [rad or m]: the last quarter of the recording "
            "(mostly a free coast), and a second recording of the same system under another hand plan "
            "(`bench.recordings.heldout_plan`, never shown to a method), its stretches clear of the nominal stops, "
            "predicted in 2-s pieces each from its own least-squares state.\n\n"
            f"### Per case\n\n{_table(per_head, per)}\n")


def sturm_table(sturm: dict) -> str:
    if not sturm:
        return f"## Real Sturm logs\n\n{NOT_MEASURED} (shared data not found)\n"
    rows = [[k, v["true_type"], f"{v['correct']}/{v['logs']}",
             "–" if v["radius_mean_m"] is None else f"{v['radius_mean_m']:.3f} ± {v['radius_std_m']:.3f}",
             f"{v['time_per_log_s']:.2f}"] for k, v in sturm.items()]
    return "## Real Sturm logs (graph stage)\n\n" + _table(["mechanism", "true type", "type correct", "radius [m]", "time/log [s]"], rows) + "\n"


def calibration_table(rows: list[dict]) -> str:
    out = [[str(r["seed"]), str(r["converged"]), f"{r['axis_error_deg']:.3f}",
            f"{r['damping']:.3f} ({r['damping_rel_error']:.1%})", f"{r['coulomb']:.3f} ({r['coulomb_rel_error']:.1%})",
            str(r["samples"]), f"{r['solve_time_s']:.2f}"] for r in rows]
    head = ["seed", "converged", "axis error [deg]", "damping (true 0.2) [N·m·s/rad]", "Coulomb (true 0.3) [N·m]",
            "samples", "calibrate time [s]"]
    return "## Calibration on the demo door\n\n" + _table(head, out) + "\n"


def arm_table(arm: dict) -> str:
    """The robot-arm side-by-side (:func:`kinemaforge_opt.arm.side_by_side.compare_arm_models`
    result): per real arm and model the mean over joints of the held-out torque RMS [N·m] and of
    the computed-torque tracking RMS [mrad], the fit time, then the same per joint."""
    exc = arm["excitation"]
    held = list(next(iter(arm["arms"].values()))["heldout_torque_rms_nm"])
    head = ["real arm", "model"] + [f"torque RMS, {h} [N·m]" for h in held] + ["tracking RMS [mrad]", "fit time [s]"]
    rows, per, notes = [], [], []
    for name, a in arm["arms"].items():
        for m in arm["models"]:
            rows.append([name, m] + [f"{a['heldout_torque_rms_nm'][h][m]['mean']:.3f}" for h in held]
                        + [f"{a['tracking_rms_mrad'][m]['mean']:.2f}", _fmt(a["fit_time_s"][m], ".2f")])
            per += [[name, m, f"torque RMS, {h} [N·m]"] + [f"{x:.3f}" for x in a["heldout_torque_rms_nm"][h][m]["per_joint"]]
                    for h in held]
            per.append([name, m, "tracking RMS [mrad]"] + [f"{x:.2f}" for x in a["tracking_rms_mrad"][m]["per_joint"]])
        notes.append(f"- {name}: fit on {a['fit_duration_s']:.1f} s at {a['rate_hz']:.0f} Hz; IDIM-LS "
                     f"{a['idim_base_parameters']} base parameters; kinemaforge_opt {a['ipopt_status']} "
                     f"({a['ipopt_iterations']} IPOPT iterations), identified inertias physically consistent: "
                     f"{a['physically_consistent']}")
    joints = [j[-6:] for j in arm["joints"]]
    return ("## robot arm: held-out torque RMS and tracking RMS, nominal vs IDIM-LS vs kinemaforge_opt\n\n"
            f"Excitation {exc['duration_s']:g} s (fits on the first 75 %), second trajectory {exc['test_duration_s']:g} s; "
            f"cond(W_base) {exc['initial_condition']:.1f} (random start) -> {exc['condition']:.1f} "
            f"({exc['iterations']} SLSQP iterations, {exc['design_time_s']:.1f} s); tracking: computed torque on "
            "the second trajectory.\n\n"
            + _table(head, rows) + "\n\n" + "\n".join(notes) + "\n\n### Per joint\n\n"
            + _table(["real arm", "model", "quantity"] + joints, per) + "\n")


def timing_tables(stages: dict, scaling: dict | None) -> str:
    rows = [[k, f"{v:.3f}"] for k, v in stages.items()]
    if scaling is None:
        return "## Time per stage\n\n" + _table(["stage", "mean time [s]"], rows) + "\n"
    pts = [[str(p["rate_hz"]), str(p["samples"]), f"{p['time_s']:.2f}", str(p["iterations"]), str(p["converged"])]
           for p in scaling["points"]]
    exp = _fmt(scaling["exponent"], ".2f")
    return ("## Time per stage\n\n" + _table(["stage", "mean time [s]"], rows) + "\n\n"
            f"## calibrate time vs samples (fitted exponent {exp}: time ∝ samples^{exp})\n\n"
            + _table(["rate [Hz]", "samples", "time [s]", "IPOPT iterations", "converged"], pts) + "\n")


def save_png(fig, path: Path) -> Path:
    """Lay out ``fig``, write it to ``path`` atomically (PNG, 120 dpi) and close it."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return path


def plot_scaling(scaling: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    n = np.array([p["samples"] for p in scaling["points"]], float)
    t = np.array([p["time_s"] for p in scaling["points"]], float)
    fig, ax = plt.subplots(figsize=(5, 4))
    ax.loglog(n, t, "o-", label="calibrate (door: axis, damping, Coulomb)")
    if scaling["exponent"] is not None:
        c = np.polyfit(np.log(n), np.log(t), 1)
        ax.loglog(n, np.exp(np.polyval(c, np.log(n))), "--", label=f"fit: exponent {c[0]:.2f}")
    ax.set_xlabel("samples")
    ax.set_ylabel("solve time [s]")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    return save_png(fig, path)


def plot_discovery(cases: list[dict], path: Path) -> Path:
    """Held-out RMS after / before per case and method (below 1: the fix helped)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    names = list(dict.fromkeys(c["case"] for c in cases))
    methods = list(dict.fromkeys(c["method"] for c in cases))
    fig, ax = plt.subplots(figsize=(10, 4 + 0.15 * len(names)))
    w = 0.8 / len(methods)
    for i, m in enumerate(methods):
        ratio = [next((c["rms_after"] / c["rms_before"] for c in cases if c["case"] == n and c["method"] == m
                       and c["rms_before"] and c["rms_after"] is not None), np.nan) for n in names]
        ax.barh(np.arange(len(names)) + i * w, ratio, height=w, label=m)
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ax.set_yticks(np.arange(len(names)) + 0.4 - w / 2)
    ax.set_yticklabels(names, fontsize=7)
    ax.set_xlabel("held-out RMS after / before")
    ax.legend()
    return save_png(fig, path)


def write_report(result: dict, out_dir: str | Path) -> dict[str, Path]:
    """Write bench.json, bench.md and the PNG plots (scaling, discovery, and with the
    reconstruction part drift_horizon, sensitivity, stage_scaling) into ``out_dir``.  Parts
    missing from ``result`` (``kinemaforge bench --parts``) are left out of the Markdown."""
    from .reco_report import plot_drift, plot_sensitivity, plot_stage_scaling, reconstruction_tables

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    load = result.get("load_average_start")
    notes = "".join([f"; code {result['revision']}" if result.get("revision") else "",
                     f"; load average (1 min) {load[0]:.1f} at start, {result['load_average_end'][0]:.1f} at end"
                     if load and result.get("load_average_end") else ""])
    sections = [f"# kinemaforge bench ({result['size']})\n\n{result['machine']}; total {result['total_s']:.0f} s{notes}\n"]
    if "discovery" in result:
        sections.append(discovery_tables(result["discovery"]["summary"], result["discovery"]["cases"]))
    if "sturm" in result:
        sections.append(sturm_table(result["sturm"]))
    if "calibration" in result:
        sections.append(calibration_table(result["calibration"]))
    if "arm" in result:
        sections.append(arm_table(result["arm"]))
    if "scaling" in result or result.get("stage_time_s"):
        sections.append(timing_tables(result.get("stage_time_s", {}), result.get("scaling")))
    reco = result.get("reconstruction")
    sections.append(reconstruction_tables(reco) if reco else placeholder_tables())
    paths = {"json": out / "bench.json", "markdown": out / "bench.md"}
    write_text_atomic(paths["json"], json.dumps(result, indent=2))
    write_text_atomic(paths["markdown"], "\n".join(sections))
    if "scaling" in result:
        paths["scaling"] = plot_scaling(result["scaling"], out / "scaling.png")
    if "discovery" in result:
        paths["discovery"] = plot_discovery(result["discovery"]["cases"], out / "discovery.png")
    if reco:
        for name, fn in (("drift_horizon", plot_drift), ("sensitivity", plot_sensitivity),
                         ("stage_scaling", plot_stage_scaling)):
            path = fn(reco, out / f"{name}.png")
            if path is not None:
                paths[name] = path
    return paths
