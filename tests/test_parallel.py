"""kinemaforge_opt.parallel: the thread and process maps keep order, raise the first error and
fall back to one worker when asked; the process map really uses a second process."""

from __future__ import annotations

import os
import signal
import time

import pytest

from kinemaforge_opt.parallel import cpu_seconds, process_map, thread_map, workers


def test_thread_map_keeps_order_and_raises_the_first_error(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    assert workers() == 2
    assert thread_map(lambda x: x * x, range(50)) == [x * x for x in range(50)]

    def fail(x):
        if x == 7:
            raise ValueError("item 7 is bad")
        return x

    with pytest.raises(ValueError, match="item 7 is bad"):
        thread_map(fail, range(20))


def test_workers_read_openmp_settings(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "3,2")  # a nested OpenMP list: the first level counts
    assert workers() == 3
    monkeypatch.setenv("OMP_NUM_THREADS", "")  # unset in effect: the CPUs this process may use
    assert workers() >= 1
    monkeypatch.setenv("OMP_NUM_THREADS", "0")  # not a thread count: ignored the same way
    assert workers() >= 1


def test_one_thread_when_the_batch_runner_asks_for_it(monkeypatch):
    import threading

    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    main = threading.get_ident()
    assert set(thread_map(lambda _: threading.get_ident(), range(8))) == {main}


def test_thread_map_keeps_its_threads_and_runs_nested_maps_inline(monkeypatch):
    import threading

    monkeypatch.setenv("OMP_NUM_THREADS", "2")

    def slow_ident(_):  # slow enough that both threads take items
        time.sleep(0.02)
        return threading.get_ident()

    first, second = set(thread_map(slow_ident, range(6))), set(thread_map(slow_ident, range(6)))
    assert first == second and threading.get_ident() not in first  # the same two pool threads

    def outer(x):  # a map inside a map item runs in that item's thread (no wait on a full pool)
        me = threading.get_ident()
        assert set(thread_map(lambda _: threading.get_ident(), range(4))) == {me}
        return x

    done = []
    t = threading.Thread(target=lambda: done.append(thread_map(outer, range(4))))
    t.start()
    t.join(timeout=10)
    assert done == [[0, 1, 2, 3]]


def test_thread_map_in_a_forked_child(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    thread_map(lambda x: x, range(4))  # the parent's pool exists before the fork

    def in_child(x):  # the child's copy of the pool has no threads: it must make its own
        time.sleep(0.05)  # slow enough that the forked child takes some of the items
        signal.alarm(10)  # a child hung on a dead pool is killed; the parent then redoes its items
        out = sum(thread_map(lambda y: y * x, range(5)))
        signal.alarm(0)
        return out, os.getpid()

    out = process_map(in_child, range(6), n=2)
    assert [v for v, _ in out] == [10 * x for x in range(6)]
    assert len({pid for _, pid in out}) == 2


def test_process_map_keeps_order_and_uses_a_second_process(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")

    def slow_square(x):  # slow enough that the forked child takes some of the items
        time.sleep(0.05)
        return x * x, os.getpid()

    out = process_map(slow_square, range(12))
    assert [v for v, _ in out] == [x * x for x in range(12)]
    assert len({pid for _, pid in out}) == 2 and os.getpid() in {pid for _, pid in out}


def test_process_map_raises_the_error_of_an_item_done_in_a_child(monkeypatch):
    parent = os.getpid()

    def fail_in_child(x):
        time.sleep(0.05)
        if os.getpid() != parent:
            raise ValueError(f"item {x} is bad")
        return x

    with pytest.raises(ValueError, match=r"item \d+ is bad"):
        process_map(fail_in_child, range(8), n=2)


def test_process_map_redoes_the_items_of_a_child_that_died():
    parent = os.getpid()

    def die_in_child(x):
        time.sleep(0.05)
        if os.getpid() != parent:
            os._exit(3)  # a crash: nothing comes back from this child
        return -x

    assert process_map(die_in_child, range(6), n=2) == [-x for x in range(6)]


def test_process_map_on_one_worker_stays_in_this_process(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert set(process_map(lambda _: os.getpid(), range(5))) == {os.getpid()}


def test_cpu_seconds_count_the_forked_children():
    def busy(_):  # 0.15 s of CPU, wherever it runs
        end = time.process_time() + 0.15
        while time.process_time() < end:
            pass
        return os.getpid()

    c0 = cpu_seconds()
    pids = process_map(busy, range(6), n=2)
    assert len(set(pids)) == 2
    assert cpu_seconds() - c0 >= 0.85  # 6 x 0.15 s, the child's share included


def test_an_interrupt_in_this_process_leaves_no_child_behind():
    parent = os.getpid()

    def interrupted(x):
        time.sleep(0.02)
        if os.getpid() == parent and x >= 2:
            raise KeyboardInterrupt  # Ctrl-C while this process works on its share
        return x

    with pytest.raises(KeyboardInterrupt):
        process_map(interrupted, range(40), n=2)
    with pytest.raises(ChildProcessError):  # the child was stopped and reaped
        os.waitpid(-1, os.WNOHANG)
