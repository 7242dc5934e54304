"""What a timing was measured on: one line to print above (and below) timing figures.

This 2-core VM's single-core speed toggles by about 2x, in bursts of a second or so, with the
load average and the CPU steal counter unchanged: a fixed 0.02-s workload timed back to back for
8 s took 20.5 ms or 39 ms, rarely in between (2026-12-01), and ``problems.time_diagnose
--lengths 10`` gave 4.15 s best of three one hour and 2.74 s the next.  So the line gives a speed
probe, that workload timed repeatedly: its fastest time (the machine's speed when nothing
competes) and the share of timings more than 1.5x slower (how much of the time it was slowed).
"""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import numpy as np


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (or the platform's processor string)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def _workload_s() -> float:
    """Wall time [s] of a fixed single-core workload: an interpreted loop and small dense solves,
    the two kinds of work the timed commands mix."""
    rng = np.random.default_rng(0)
    A = rng.standard_normal((60, 60)) + 60 * np.eye(60)
    b = rng.standard_normal(60)
    t0 = time.perf_counter()
    s = 0.0
    for k in range(200_000):
        s += k * 0.5
    for _ in range(300):
        b = np.linalg.solve(A, b) * 60.0
    return time.perf_counter() - t0


def speed_probe(samples: int = 40) -> tuple[float, float]:
    """(fastest workload time [ms], share of the ``samples`` timings slower than 1.5x that) over
    about one second."""
    t = np.array([_workload_s() for _ in range(samples)])
    return 1e3 * float(t.min()), float(np.mean(t > 1.5 * t.min()))


def machine_line(label: str = "machine") -> str:
    """"<label>: CPU, N cores, load L, speed probe P ms, S % slowed" (see the module docs)."""
    fastest, slowed = speed_probe()
    return (f"{label}: {cpu_model()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}, speed probe "
            f"{fastest:.1f} ms, {100 * slowed:.0f} % of its timings slowed by more than 1.5x")
