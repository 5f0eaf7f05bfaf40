"""Where the CPU goes during a benchmark: per thread of this process, grouped by role, and
per child process, from Linux ``/proc`` (no sampling thread, two reads per phase).

:func:`snapshot` reads the user + system CPU seconds of every thread of this process
(``/proc/self/task/*/stat``) and of the given child processes; :func:`usage` turns two
snapshots into CPU seconds and % of one core per group over the wall time between them.
Groups come from the Python names of the threads (``threading.enumerate()``, matched on
the native thread id):

* ``event loop``: the main thread, where uvicorn, the FastAPI handlers, the cell's async
  loop and the SQLAlchemy/aiosqlite callbacks run;
* ``sim-physics``: the MuJoCo thread (physics steps and the camera renders);
* ``to_thread workers``: the loop's default executor (``asyncio_N`` under asyncio,
  ``uvloop_N`` under uvloop), where the inspection's
  vision (segmentation, matching, pose) and the JPEG encoding of frames run;
* ``aiosqlite``: the database's connection threads;
* ``native NAME``: threads without a Python name (OpenCV, Mesa's ``llvmpipe`` renderer
  under EGL, BLAS), by their kernel name;
* ``other threads``: Python threads not named above; CPU of threads that ended between the snapshots is counted in
  ``ended threads`` (the process total minus the threads alive at the end).
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["CpuSnapshot", "group_of", "snapshot", "usage"]

_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def _stat_cpu_s(path: Path) -> float | None:
    """User + system CPU seconds from a ``/proc/.../stat`` file, None if it is gone."""
    try:
        text = path.read_text()
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        return None
    fields = text.rsplit(")", 1)[1].split()  # the command name may hold spaces
    return (int(fields[11]) + int(fields[12])) * _TICK_S


def group_of(name: str | None, *, is_main: bool, comm: str = "") -> str:
    """The role of a thread from its Python name (None for a native thread, then named by
    its kernel name ``comm`` without digits: ``native llvmpipe-`` for Mesa's software
    renderer under EGL, for instance)."""
    if is_main:
        return "event loop"
    if name is None:
        base = comm.strip().rstrip("0123456789:_-") or "?"
        return f"native {base}"
    if name == "sim-physics":
        return "sim-physics"
    if name.startswith(("asyncio_", "uvloop_")):  # the default executor of each loop
        return "to_thread workers"
    if name.startswith("aiosqlite:") or "_connection_worker" in name:
        return "aiosqlite"
    return "other threads"


@dataclass(frozen=True)
class CpuSnapshot:
    """CPU seconds at one instant."""

    at_s: float
    """``time.monotonic()`` of the snapshot."""
    process_s: float
    """This process, all threads (alive or ended)."""
    threads_s: dict[int, tuple[str, float]]
    """Native thread id -> (group, CPU seconds) for the threads alive now."""
    children_s: dict[str, float]
    """Label -> CPU seconds of each child process given (0 when it is gone)."""


def snapshot(children: dict[str, int] | None = None) -> CpuSnapshot:
    """CPU seconds of every thread of this process and of ``children`` (label -> pid)."""
    children = children or {}
    for label, pid in children.items():
        if not isinstance(pid, int) or isinstance(pid, bool) or pid <= 0:
            raise ValueError(f"pid of {label!r} must be a positive int, got {pid!r}")
    names: dict[int, str] = {}
    for t in threading.enumerate():
        if t.native_id is not None:
            names[t.native_id] = _thread_label(t)
    main_id = threading.main_thread().native_id
    threads: dict[int, tuple[str, float]] = {}
    task_dir = Path("/proc/self/task")
    for entry in task_dir.iterdir():
        tid = int(entry.name)
        cpu = _stat_cpu_s(entry / "stat")
        if cpu is not None:
            name = names.get(tid)
            comm = ""
            if name is None:
                try:
                    comm = (entry / "comm").read_text()
                except (FileNotFoundError, ProcessLookupError):
                    comm = ""
            threads[tid] = (group_of(name, is_main=tid == main_id, comm=comm), cpu)
    process = _stat_cpu_s(Path("/proc/self/stat")) or 0.0
    kids = {label: _stat_cpu_s(Path(f"/proc/{pid}/stat")) or 0.0 for label, pid in children.items()}
    return CpuSnapshot(time.monotonic(), process, threads, kids)


def _thread_label(t: threading.Thread) -> str:
    """The thread's name, with the target's name for aiosqlite's unnamed threads."""
    target = getattr(t, "_target", None)
    qual = getattr(target, "__qualname__", "") or ""
    mod = getattr(target, "__module__", "") or ""
    if "aiosqlite" in mod:
        return f"aiosqlite:{qual}"
    return t.name


def usage(a: CpuSnapshot, b: CpuSnapshot) -> dict[str, object]:
    """CPU between snapshots ``a`` and ``b``: per group and child, seconds and % of a core.

    A thread alive only at ``b`` counts from zero (it started in between, its whole CPU
    time is within the interval)."""
    wall = b.at_s - a.at_s
    if not wall > 0:
        raise ValueError(f"snapshot b must be later than a (wall {wall!r} s)")
    groups: dict[str, float] = {}
    alive = 0.0
    for tid, (group, cpu) in b.threads_s.items():
        before = a.threads_s.get(tid)
        d = cpu - (before[1] if before is not None else 0.0)
        groups[group] = groups.get(group, 0.0) + max(0.0, d)
        alive += max(0.0, d)
    process = max(0.0, b.process_s - a.process_s)
    groups["ended threads"] = max(0.0, process - alive)
    kids = {k: max(0.0, b.children_s.get(k, 0.0) - a.children_s.get(k, 0.0)) for k in b.children_s}
    rows = {f"server: {g}": s for g, s in sorted(groups.items())}
    rows["server: total"] = process
    rows.update({f"{k}": s for k, s in kids.items()})
    return {
        "wall_s": wall,
        "cpu_s": rows,
        "core_pct": {k: 100.0 * s / wall for k, s in rows.items()},
        "cores": os.cpu_count(),
    }
