"""Independent work on both cores of the target machine: a pool of threads or of forked processes.

:func:`thread_map` is for work that releases the GIL — perception's numpy on whole images and
clouds, KD-tree queries and OpenCV's PNG decoder — and makes no copies of the clouds.
:func:`process_map` is for work that holds it: CasADi keeps the GIL through an ``nlpsol`` call,
so the diagnosis's independent hypothesis fits gain nothing from threads (measured), but run
side by side in forked processes that inherit the problems already built."""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

X = TypeVar("X")
Y = TypeVar("Y")


def workers() -> int:
    """Threads or processes to use: OMP_NUM_THREADS when set (the batch runner sets 1 per job; of a nested
    OpenMP list such as "4,2" the first level), else the CPUs this process may run on."""
    first = os.environ.get("OMP_NUM_THREADS", "").split(",")[0].strip()
    if first.isdigit() and int(first) > 0:
        return int(first)
    if hasattr(os, "sched_getaffinity"):  # Linux: the CPUs this process is allowed, not the machine's
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def cpu_seconds() -> float:
    """CPU seconds [s] used so far by this process (all its threads) and by its children that have
    finished (e.g. :func:`process_map`'s), user and system time."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


class _ThreadPool:
    """One pool of worker threads for the process, made on first use and kept: perception calls
    :func:`thread_map` hundreds of times per sequence on small batches (a region's growth
    tests ten steps per round), and a pool made per call started and joined ~1500 threads on
    eval_drawer_2.  A child forked by :func:`process_map` gets a new pool (the parent's threads
    do not exist there)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pool: ThreadPoolExecutor | None = None
        self._size = 0
        self._local = threading.local()  # .worker: True on the pool's own threads

    def _mark_worker(self) -> None:
        self._local.worker = True

    def in_worker(self) -> bool:
        """True on one of the pool's threads."""
        return getattr(self._local, "worker", False)

    def get(self, n: int) -> ThreadPoolExecutor:
        """The pool, of ``n`` threads (made again when ``n`` changes, which :func:`workers` does
        only when OMP_NUM_THREADS is set anew)."""
        with self._lock:
            if self._pool is None or self._size != n:
                if self._pool is not None:
                    self._pool.shutdown(wait=False)
                self._pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="kinemaforge",
                                                initializer=self._mark_worker)
                self._size = n
            return self._pool

    def forget(self) -> None:
        """Drop the pool without joining it (in a forked child, whose copy has no threads)."""
        self._lock = threading.Lock()
        self._pool, self._size = None, 0


_THREADS = _ThreadPool()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_THREADS.forget)


def thread_map(fn: Callable[[X], Y], items: Sequence[X]) -> list[Y]:
    """``[fn(x) for x in items]``, in order, computed on up to :func:`workers` threads (in this
    thread when that is one or there is one item).  An exception in ``fn`` propagates.  Called
    from within a ``thread_map`` item, it runs in that thread: the pool's threads are all
    taken by the outer map already, and waiting on the pool from inside it could deadlock."""
    n = workers()
    if min(n, len(items)) <= 1 or _THREADS.in_worker():
        return [fn(x) for x in items]
    return list(_THREADS.get(n).map(fn, items))


def process_map(fn: Callable[[X], Y], items: Sequence[X], n: int | None = None) -> list[Y]:
    """``[fn(x) for x in items]``, in order, computed by this process and up to ``n - 1`` (default
    :func:`workers`) forked children, which take the next item as each finishes one (items may
    differ widely in cost).  The children are forked when called, so ``fn`` sees the caller's
    state as it is then, and whatever ``fn`` changes in that state in a child stays there: only
    the results (which must pickle) come back.  Runs in this process alone when there is one
    worker or one item, or where fork is unavailable.  An exception in ``fn`` propagates."""
    items = list(items)
    n = min(workers() if n is None else n, len(items))
    if n <= 1 or not hasattr(os, "fork"):
        return [fn(x) for x in items]
    ctx = multiprocessing.get_context("fork")
    counter = ctx.Value("i", 0)  # the next item to take, shared by every process

    def take() -> int:
        with counter.get_lock():
            k = counter.value
            counter.value += 1
        return k

    def work() -> dict[int, tuple[bool, object]]:
        done = {}
        while (k := take()) < len(items):
            try:
                done[k] = (True, fn(items[k]))
            except Exception as e:  # handed to the caller, who raises it in item order
                done[k] = (False, e)
        return done

    sys.stdout.flush()  # else a child would print the caller's pending output again
    sys.stderr.flush()
    children = []
    for _ in range(n - 1):
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # child: work, send what it did, leave without running the caller's cleanup
            os.close(r)
            code = 0
            try:
                with os.fdopen(w, "wb") as f:
                    pickle.dump(work(), f)
            except BaseException:  # noqa: BLE001 - the caller redoes the items it does not get back
                code = 1
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
        os.close(w)
        children.append((pid, r))
    try:
        done = work()
    except BaseException:  # e.g. KeyboardInterrupt: no child outlives the call
        for pid, r in children:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            os.close(r)
        raise
    for pid, r in children:
        with os.fdopen(r, "rb") as f:
            try:
                done.update(pickle.load(f))
            except (EOFError, pickle.UnpicklingError):
                pass  # the child died or could not pickle what it did: redone below
        os.waitpid(pid, 0)
    out = []
    for k in range(len(items)):
        ok, value = done[k] if k in done else (True, fn(items[k]))
        if not ok:
            raise value
        out.append(value)
    return out
