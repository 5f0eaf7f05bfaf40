"""A CPU hog for running tests on a busy machine: ``N`` processes spin for a bounded time,
then end by themselves (and when the hog is interrupted, or its parent goes away).

Usage, beside a test run in another shell::

    .venv/bin/python -m tests.utils.hog --procs 16 --seconds 600 &
    .venv/bin/python -m pytest -q -p no:cacheprovider tests/...

The tests must pass with it: they never assume an idle machine (``docs/testing.md``).  ``--procs`` is bounded to 64 and ``--seconds`` to one hour, so
a forgotten hog stops on its own.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import signal
import sys
import time

__all__ = ["MAX_PROCS", "MAX_SECONDS", "hog", "spin"]

#: Most busy processes one hog starts.
MAX_PROCS = 64
#: Longest a hog runs, seconds.
MAX_SECONDS = 3600.0


def spin(until: float, parent: int) -> None:
    """Busy-loop until the monotonic time ``until`` or until ``parent`` is gone."""
    x = 0
    while time.monotonic() < until:
        for _ in range(200_000):  # about 10 ms of arithmetic between the clock reads
            x = (x * 1_103_515_245 + 12_345) & 0xFFFFFFFF
        if os.getppid() != parent:
            return


def hog(procs: int, seconds: float) -> int:
    """Run ``procs`` spinning processes for ``seconds``; returns how many were started."""
    if isinstance(procs, bool) or not isinstance(procs, int) or not 1 <= procs <= MAX_PROCS:
        raise ValueError(f"procs must be an integer in 1..{MAX_PROCS}, got {procs!r}")
    if not 0.0 < float(seconds) <= MAX_SECONDS:
        raise ValueError(f"seconds must be in (0, {MAX_SECONDS:g}], got {seconds!r}")
    until = time.monotonic() + float(seconds)
    ctx = mp.get_context("fork" if sys.platform != "win32" else "spawn")
    workers = [
        ctx.Process(target=spin, args=(until, os.getpid()), daemon=True) for _ in range(procs)
    ]
    for w in workers:
        w.start()
    try:
        for w in workers:
            w.join(max(0.0, until - time.monotonic()) + 5.0)
    finally:
        for w in workers:
            if w.is_alive():
                w.terminate()
        for w in workers:
            w.join(5.0)
    return len(workers)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--procs", type=int, default=2 * (os.cpu_count() or 2),
                   help=f"busy processes, 1..{MAX_PROCS} (default: twice the CPUs)")  # fmt: skip
    p.add_argument("--seconds", type=float, default=300.0,
                   help=f"how long, 0..{MAX_SECONDS:g} s (default 300)")  # fmt: skip
    args = p.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))  # workers are daemons: they go too
    try:
        n = hog(args.procs, args.seconds)
    except ValueError as exc:
        p.error(str(exc))
    except KeyboardInterrupt:
        return 0
    print(f"hog: {n} processes spun for {args.seconds:g} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
