"""Run the benchmark at a size: ``QUICK`` (< 10 min on 2 cores) or ``FULL``."""

from __future__ import annotations

import os
import platform
import time
from dataclasses import dataclass

import numpy as np

from .discovery import as_dicts, run_case, summarise
from .reconstruction import RECO_FULL, RECO_QUICK, RecoSize, run_reconstruction
from .stages import calibrate_scaling, demo_door, sturm_logs

PARTS = ("discovery", "sturm", "calibration", "scaling", "arm", "reconstruction")


@dataclass(frozen=True)
class Size:
    """What one benchmark size runs: discovery cases (with or without the effect pairs) ×
    encoder-noise seeds, demo-door seeds, the recording rates of the calibrate-scaling sweep, and
    the robot-arm side-by-side at its quick size (6 s excitation) or full size (20 s), and the
    RGB-D reconstruction benchmark at ``reco`` (Table 1, Table 2, drift, sensitivity, scaling)."""

    name: str
    pairs: bool
    noise_seeds: tuple[int, ...]
    demo_seeds: tuple[int, ...]
    rates_hz: tuple[int, ...]
    arm_quick: bool
    reco: RecoSize = RECO_FULL


QUICK = Size("quick", False, (0,), (0,), (30, 60, 120), True, RECO_QUICK)
FULL = Size("full", True, (0, 1, 2), (0, 1, 2), (30, 60, 120, 240, 400), False, RECO_FULL)


def discovery_cases(pairs: bool = True) -> list[str]:
    """The concealed-effects set: ``effect_*`` and ``null_*`` catalogue cases (the pairs
    ``effect_<kind>_<a>+<b>`` only with ``pairs``: each costs several single cases)."""
    from problems.catalogue import CASES

    return [n for n in CASES if n.startswith(("effect_", "null_")) and (pairs or "+" not in n)]


def machine() -> str:
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"


def revision() -> str | None:
    """The repository's commit (with "+dirty" when tracked files differ from it), or None outside
    a git checkout: a benchmark figure names the code it measured."""
    import subprocess

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    try:
        head = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", root, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("+dirty" if dirty else "")


def run_bench(size: Size, cases: list[str] | None = None, progress=None, out_dir=None,
              parts: tuple[str, ...] = PARTS, cache=None, resume: bool = False) -> dict:
    """Run the chosen ``parts`` of the benchmark (all by default); returns the result document
    (see :mod:`.report`).  ``out_dir``: where the reconstruction part keeps its reconstructions
    (a temporary folder when None); ``cache``: its generated cases (default
    :func:`.reconstruction.cache_root`); ``resume``: reuse the reconstruction runs an
    interrupted run left in ``out_dir`` (see :func:`.reconstruction.run_reconstruction`)."""
    import tempfile

    say = progress or (lambda s: None)
    t_start = time.perf_counter()
    result = {"size": size.name, "machine": machine(), "revision": revision(), "parts": list(parts),
              "load_average_start": list(os.getloadavg())}
    stage = {}
    if "discovery" in parts:
        scores = []
        for seed in size.noise_seeds:
            for case in cases or discovery_cases(size.pairs):
                say(f"discovery {case} (noise seed {seed})")
                scores += run_case(case, seed)
        result["discovery"] = {"summary": summarise(scores), "cases": as_dicts(scores)}
        stage.update({f"diagnose per case ({m})": float(np.mean([s.time_s for s in scores if s.method == m]))
                      for m in dict.fromkeys(s.method for s in scores)})
    if "sturm" in parts:
        say("real Sturm logs")
        sturm = result["sturm"] = sturm_logs()
        if sturm:
            stage["graph: joint type per Sturm log"] = float(np.mean([v["time_per_log_s"] for v in sturm.values()]))
    if "calibration" in parts:
        say("calibration on the demo door")
        cal = result["calibration"] = demo_door(size.demo_seeds)
        stage["calibrate demo door (IPOPT)"] = float(np.mean([r["solve_time_s"] for r in cal]))
        stage["demo door end to end (simulate + calibrate + write)"] = float(np.mean([r["wall_time_s"] for r in cal]))
    if "scaling" in parts:
        say("calibrate time vs samples")
        result["scaling"] = calibrate_scaling(size.rates_hz)
    if "arm" in parts:
        from ..arm.side_by_side import compare_arm_models  # MuJoCo and Pinocchio: load on use

        arm = result["arm"] = compare_arm_models(size.arm_quick, progress=say)
        for m in ("IDIM-LS", "kinemaforge_opt"):
            stage[f"robot arm: {m} fit per arm"] = float(np.mean([a["fit_time_s"][m] for a in arm["arms"].values()]))
        stage["robot arm side-by-side end to end"] = arm["total_s"]
    if "reconstruction" in parts:
        with tempfile.TemporaryDirectory() as tmp:
            reco = result["reconstruction"] = run_reconstruction(size.reco, out_dir or tmp, cache, say,
                                                                 resume=resume and out_dir is not None)
        t1 = [r for r in reco["records"] if r["ok"] and r["options"] == {}]
        for k in dict.fromkeys(k for r in t1 for k in r["timing_s"]):
            stage[f"reconstruct: {k} per case ({size.reco.views} views, {size.reco.frames} steps)"] = float(
                np.mean([r["timing_s"][k] for r in t1 if k in r["timing_s"]]))
    result["stage_time_s"] = stage
    result["total_s"] = time.perf_counter() - t_start
    result["load_average_end"] = list(os.getloadavg())
    return result
