"""Independent per-frame, per-step and per-camera work on a pool of threads.

The work mapped here is numpy on whole images and clouds, KD-tree queries and OpenCV's PNG
decoder, all of which release the GIL, so threads use both cores of the target machine without
the copies a process pool would make of the clouds."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

X = TypeVar("X")
Y = TypeVar("Y")


def workers() -> int:
    """Threads to use: OMP_NUM_THREADS when set (the batch runner sets 1 per job; of a nested
    OpenMP list such as "4,2" the first level), else the CPUs this process may run on."""
    first = os.environ.get("OMP_NUM_THREADS", "").split(",")[0].strip()
    if first.isdigit() and int(first) > 0:
        return int(first)
    if hasattr(os, "sched_getaffinity"):  # Linux: the CPUs this process is allowed, not the machine's
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def thread_map(fn: Callable[[X], Y], items: Sequence[X]) -> list[Y]:
    """``[fn(x) for x in items]``, in order, computed on up to :func:`workers` threads (in this
    thread when that is one or there is one item).  An exception in ``fn`` propagates."""
    n = min(workers(), len(items))
    if n <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(max_workers=n) as pool:
        return list(pool.map(fn, items))
