"""The CPU accounting of the load benchmark: threads land in their group, children count."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import pytest

from benchmarks import cpu_account


def _burn(seconds: float) -> None:
    end = time.thread_time() + seconds
    x = 0
    while time.thread_time() < end:
        x += 1


def test_a_busy_worker_thread_is_counted_in_its_group() -> None:
    burnt, release = threading.Event(), threading.Event()

    def work() -> None:
        _burn(0.3)
        burnt.set()
        release.wait(30)

    a = cpu_account.snapshot()
    t = threading.Thread(target=work, name="asyncio_99")
    t.start()
    try:
        assert burnt.wait(30)
        alive = cpu_account.snapshot()  # the thread is alive here: named, so grouped
    finally:
        release.set()
        t.join()
    # join() returns when the Python thread is done; the kernel's task can outlive it for a
    # moment (on a loaded machine, long enough to be read as alive): wait until it is gone.
    deadline = time.monotonic() + 10.0
    while os.path.exists(f"/proc/self/task/{t.native_id}") and time.monotonic() < deadline:
        time.sleep(0.01)
    u = cpu_account.usage(a, alive)
    assert u["cpu_s"]["server: to_thread workers"] >= 0.25
    # Once it has ended, its CPU is still the process's, counted as an ended thread.
    u = cpu_account.usage(a, cpu_account.snapshot())
    assert u["cpu_s"]["server: ended threads"] >= 0.25
    assert u["cpu_s"]["server: total"] >= 0.25


def test_the_main_thread_is_the_event_loop_and_a_child_is_counted() -> None:
    child = subprocess.Popen(
        [sys.executable, "-c", "import time\nt=time.process_time()\n"
         "while time.process_time()-t<0.4: pass\nimport sys; sys.stdin.read()"],
        stdin=subprocess.PIPE,
    )  # fmt: skip
    try:
        a = cpu_account.snapshot({"kid": child.pid})
        _burn(0.2)
        time.sleep(0.6)
        b = cpu_account.snapshot({"kid": child.pid})
    finally:
        assert child.stdin is not None
        child.stdin.close()
        child.wait(10)
    u = cpu_account.usage(a, b)
    assert u["cpu_s"]["server: event loop"] >= 0.18
    assert u["cpu_s"]["kid"] >= 0.2
    assert u["core_pct"]["kid"] == pytest.approx(100 * u["cpu_s"]["kid"] / u["wall_s"])
    assert u["cores"] == os.cpu_count()


def test_group_names() -> None:
    assert cpu_account.group_of("x", is_main=True) == "event loop"
    assert cpu_account.group_of("sim-physics", is_main=False) == "sim-physics"
    assert cpu_account.group_of("asyncio_3", is_main=False) == "to_thread workers"
    assert cpu_account.group_of("uvloop_1", is_main=False) == "to_thread workers"
    assert cpu_account.group_of("aiosqlite:f", is_main=False) == "aiosqlite"
    assert cpu_account.group_of(None, is_main=False, comm="llvmpipe-3\n") == "native llvmpipe"
    assert cpu_account.group_of(None, is_main=False) == "native ?"
    assert cpu_account.group_of("worker", is_main=False) == "other threads"


def test_bad_inputs_are_refused() -> None:
    with pytest.raises(ValueError, match="positive int"):
        cpu_account.snapshot({"kid": 0})
    with pytest.raises(ValueError, match="positive int"):
        cpu_account.snapshot({"kid": True})  # type: ignore[dict-item]
    a = cpu_account.snapshot()
    with pytest.raises(ValueError, match="later"):
        cpu_account.usage(a, a)
