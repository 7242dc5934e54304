"""Run the benchmark at a size: ``QUICK`` (< 10 min on 2 cores) or ``FULL``."""

from __future__ import annotations

import os
import platform
import time
from dataclasses import dataclass

import numpy as np

from .discovery import as_dicts, run_case, summarise
from .stages import calibrate_scaling, demo_door, sturm_logs


@dataclass(frozen=True)
class Size:
    """What one benchmark size runs: discovery cases (with or without the effect pairs) ×
    encoder-noise seeds, demo-door seeds, the recording rates of the calibrate-scaling sweep, and
    the robot-arm side-by-side at its quick size (6 s excitation) or full size (20 s)."""

    name: str
    pairs: bool
    noise_seeds: tuple[int, ...]
    demo_seeds: tuple[int, ...]
    rates_hz: tuple[int, ...]
    arm_quick: bool


QUICK = Size("quick", False, (0,), (0,), (30, 60, 120), True)
FULL = Size("full", True, (0, 1, 2), (0, 1, 2), (30, 60, 120, 240, 400), False)


def discovery_cases(pairs: bool = True) -> list[str]:
    """The concealed-effects set: ``effect_*`` and ``null_*`` catalogue cases (the pairs
    ``effect_<kind>_<a>+<b>`` only with ``pairs``: each costs several single cases)."""
    from problems.catalogue import CASES

    return [n for n in CASES if n.startswith(("effect_", "null_")) and (pairs or "+" not in n)]


def machine() -> str:
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"


def run_bench(size: Size, cases: list[str] | None = None, progress=None) -> dict:
    """Run every part of the benchmark; returns the result document (see :mod:`.report`)."""
    from ..arm.side_by_side import compare_arm_models  # MuJoCo and Pinocchio: load on use

    say = progress or (lambda s: None)
    t_start = time.perf_counter()
    scores = []
    for seed in size.noise_seeds:
        for case in cases or discovery_cases(size.pairs):
            say(f"discovery {case} (noise seed {seed})")
            scores += run_case(case, seed)
    say("real Sturm logs")
    sturm = sturm_logs()
    say("calibration on the demo door")
    cal = demo_door(size.demo_seeds)
    say("calibrate time vs samples")
    scaling = calibrate_scaling(size.rates_hz)
    arm = compare_arm_models(size.arm_quick, progress=say)
    stage = {f"diagnose per case ({m})": float(np.mean([s.time_s for s in scores if s.method == m]))
             for m in dict.fromkeys(s.method for s in scores)}
    if sturm:
        stage["graph: joint type per Sturm log"] = float(np.mean([v["time_per_log_s"] for v in sturm.values()]))
    stage["calibrate demo door (IPOPT)"] = float(np.mean([r["solve_time_s"] for r in cal]))
    stage["demo door end to end (simulate + calibrate + write)"] = float(np.mean([r["wall_time_s"] for r in cal]))
    for m in ("IDIM-LS", "kinemaforge_opt"):
        stage[f"robot arm: {m} fit per arm"] = float(np.mean([a["fit_time_s"][m] for a in arm["arms"].values()]))
    stage["robot arm side-by-side end to end"] = arm["total_s"]
    return {
        "size": size.name, "machine": machine(), "total_s": time.perf_counter() - t_start,
        "discovery": {"summary": summarise(scores), "cases": as_dicts(scores)},
        "sturm": sturm, "calibration": cal, "scaling": scaling, "arm": arm, "stage_time_s": stage,
    }
