"""Fault campaign during continuous inspection (issue 16, part 1), one process plus a server.

A simulated cell (MuJoCo arm and camera, SQLite or a throw-away PostgreSQL cluster) runs
continuous inspection (:func:`backend.inspection.service.start_run`, what
``POST /api/inspection/run`` starts).  A feeder puts one object at a time at the station
(index mode): a taught model or an untrained part, alternately; it takes the object away
when a complete (``recognized`` / ``unknown``) row names it, and leaves it when the row is
``failed``, so the cell must inspect it again.  Faults are injected while an inspection is
under way:

* ``camera``: the camera's ``grab()`` hangs for ``--fault-s`` seconds, then frames return;
* ``estop``: the emergency stop mid-inspection, reset after ``--fault-s``; the run is
  started again by the operator (the harness): resetting an e-stop never restarts motion
  by itself (ISO 13850);
* ``database``: SQLite: another connection holds ``BEGIN EXCLUSIVE`` on the file for
  ``--fault-s``; PostgreSQL (``--postgres``): the cell's own database on the shared server,
  reached through a TCP proxy that is cut (new connections refused, open ones dropped)
  while every backend of that database is terminated (``pg_terminate_backend``), then
  restored (``benchmarks/faultkit.py``; the server itself is never stopped);
* ``serial``: the arm is the serial driver talking over a real
  pseudo-terminal to the controller emulator in front of the simulated arm; the port
  vanishes for ``--fault-s``;
* ``kill``: ``visioncell serve`` (a child process) is killed with SIGKILL mid-inspection
  and started again on the same database; the run is started again through the API.

Measured per fault kind: faults injected, inspections lost (an object taken away or left at
the end without a complete row, a marker left behind), duplicated (two complete rows for one
object, or a marker with a row), partial rows, unsafe motions, motion commands issued while
the fault was active (the cell should hold), the failed rows' reasons, and the recovery
time: from the fault's end to the next complete inspection.  Motions are audited from the
cell's motion log (``VISIONCELL_MOTION_LOG``, :mod:`backend.cell.motionlog`), which every
cell of the campaign writes, the killed ``serve`` children included; after each part the
log is read and each motion judged against the faults injected
(:func:`benchmarks.faultkit.judge_motions`): unsafe is a motion commanded with the e-stop
latched, the link down, without the motion lock or outside the limits, or commanded during
an e-stop, link drop or kill and moving the arm.  Baseline: the same cell without faults (cycle time), in the
same run.  Run::

    nice -n 5 .venv/bin/python -m benchmarks.faults [--per-kind 3] [--kinds camera,estop,...]
        [--postgres [--postgres-url URL]] [--keep-logs DIR] [--json]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import os
import shutil
import signal
import socket
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from benchmarks.faultkit import FaultWindow, PgDatabase, judge_motions

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering, before MuJoCo loads

out = Console(width=170)
err = Console(stderr=True)

#: The taught model and the untrained part the feeder alternates.
TAUGHT = "wheel-steel"
UNTRAINED_FALLBACK = "oil-filter"
KINDS = ("camera", "estop", "database", "serial", "kill")


def free_port() -> int:
    """A TCP port free now on 127.0.0.1."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def settings_for(tmp: Path, url: str, *, time_scale: float, busy_s: float = 1.0, **kw: Any) -> Any:
    """Settings of the campaign's cell (sim, no 3D view, no demo objects, motion log)."""
    from backend.settings import Settings

    return Settings(
        database_url=url, var_dir=tmp / "var", driver=kw.pop("driver", "sim"), camera="sim",
        motion_log=kw.pop("motion_log", tmp / "motion.jsonl"),
        sim_demo=False, time_scale=time_scale, secret_key="faults-secret-0123456789abcdef",
        view3d_enabled=False, bootstrap_operator=False, database_busy_timeout_s=busy_s, **kw,
    )  # fmt: skip


# -- what is measured -------------------------------------------------------------------------
@dataclass
class MotionWatch:
    """When the cell commands motions (the harness waits on it); whether they were safe is
    judged from the motion log afterwards (:func:`apply_motion_audit`).

    It also places the faults: :meth:`arm` hands it a coroutine function that starts a
    fault, run as its own task on the first motion commanded *inside* an inspection (after
    the inspection's durable marker, before its row is stored: past the search for the
    part, which stores nothing when cut short) -- the move to the second view, or the
    pick's.  The fault then starts while that motion is under way, on any machine load."""

    rt: Any
    commands: int = 0
    times: list[float] = field(default_factory=list)
    inside: bool = False
    _inject: Any = None
    _originals: list[tuple[Any, str, Any]] = field(default_factory=list)

    def install(self) -> None:
        from backend.inspection import recovery, results

        driver = self.rt.cell.driver
        inner = driver.move
        begin, store = recovery.begin, results.store

        async def move(traj: Any) -> Any:
            self.commands += 1
            self.times.append(time.monotonic())
            if self.inside and self._inject is not None:
                inject, self._inject = self._inject, None
                task = asyncio.get_running_loop().create_task(inject())
                INJECTIONS.append(task)  # runs at the loop's next turn, the motion under way
            return await inner(traj)

        async def begin_(*a: Any, **kw: Any) -> int:
            mid = await begin(*a, **kw)
            self.inside = True
            return mid

        async def store_(*a: Any, **kw: Any) -> int:
            iid = await store(*a, **kw)
            self.inside = False
            return iid

        driver.move = move
        recovery.begin = begin_  # type: ignore[assignment]
        results.store = store_  # type: ignore[assignment]
        self._originals = [(recovery, "begin", begin), (results, "store", store)]

    def uninstall(self) -> None:
        for mod, name, fn in reversed(self._originals):
            setattr(mod, name, fn)
        self._originals = []

    def arm(self, inject: Any) -> None:
        """Run ``inject()`` (a coroutine function) on the next motion inside an inspection."""
        self._inject = inject


#: The fault-starting tasks :class:`MotionWatch` ran (awaited by the harness).
INJECTIONS: list[asyncio.Task[Any]] = []


def keep_log(args: argparse.Namespace, path: Path, part: str) -> None:
    """Copy a part's motion log to ``--keep-logs DIR`` (for reading it afterwards)."""
    if getattr(args, "keep_logs", None) and path.exists():
        Path(args.keep_logs).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, Path(args.keep_logs) / f"motion-{part}.jsonl")


def apply_motion_audit(res: dict[str, KindResult], log_path: Path,
                       windows: list[FaultWindow], spans: list[FaultWindow]) -> list[str]:  # fmt: skip
    """Judge every motion of ``log_path`` against the fault ``windows``; add each kind's
    audited, unsafe and during-fault counts.  A motion belongs to the kind whose ``span``
    (that kind's part of the run, in order) it was commanded in; one before the first span
    (the teach) to the first, one after the last to the last.  Returns the unsafe motions'
    descriptions."""
    from backend.cell.motionlog import read_motion_log

    detail: list[str] = []
    moves = read_motion_log(log_path)
    for i, span in enumerate(spans):
        lo = -math.inf if i == 0 else span.start
        hi = math.inf if i == len(spans) - 1 else span.end
        mine = [m for m in moves if lo <= float(m.get("t", 0.0)) < hi]
        k = res.setdefault(span.kind, KindResult(span.kind))
        for r in judge_motions(mine, windows).values():
            k.audited += r["audited"]
            k.unsafe += len(r["unsafe"])
            k.during_fault += r["during_fault"]
            detail += r["unsafe"]
    return detail


@dataclass
class Feeder:
    """One object at a time at the station; taken away once a complete row names it."""

    rt: Any
    names: tuple[str, ...]
    presented: list[int] = field(default_factory=list)
    complete: dict[int, list[int]] = field(default_factory=dict)
    failed: dict[int, list[str]] = field(default_factory=dict)
    done_times: list[tuple[float, str]] = field(default_factory=list)
    current: int | None = None
    _cleared: float = 0.0
    _seen: float = 0.0
    _next: asyncio.Event = field(default_factory=asyncio.Event)
    _k: int = 0
    _held: bool = False

    def hold(self) -> None:
        """Put no new object at the station (the end of a part of the campaign)."""
        self._held = True

    def settled(self) -> bool:
        """Holding, and the object last put at the station has a complete row."""
        return self._held and (self.current is None or self.current in self.complete)

    def start(self) -> None:
        from backend.cell.events import InspectionDone

        self.rt.bus.add_listener(self._on_done, InspectionDone)
        cell = self.rt.cell
        inner = cell.look
        self._seen = 0.0

        async def look(*a: Any, **kw: Any) -> Any:
            frame = await inner(*a, **kw)
            self._seen = max(self._seen, float(frame.stamp_s))
            return frame

        cell.look = look  # the feeder knows when the cell has seen the empty station
        self.spawn()

    def spawn(self) -> None:
        eng = self.rt.sim
        eng.clear_objects()
        name = self.names[self._k % len(self.names)]
        self._k += 1
        yaw = math.remainder(0.3 * self._k, 2 * math.pi)  # turned a little more each time
        o = eng.spawn(name, s_m=eng.config.layout.conveyor.station_s_m, yaw_rad=yaw)
        self.current = int(o.id)
        self.presented.append(self.current)

    def _on_done(self, ev: Any) -> None:
        truth = self._truth(ev.inspection_id)
        self.done_times.append((time.monotonic(), ev.decision))
        if ev.decision == "failed":
            self.failed.setdefault(truth if truth is not None else -1, []).append(ev.reason)
            return
        if truth is not None:
            self.complete.setdefault(truth, []).append(ev.inspection_id)
        if truth == self.current:
            # the object leaves at once (before the run looks again), the next one comes
            # once the cell has seen the empty station (:meth:`run`)
            self.rt.sim.clear_objects()
            self._cleared = time.monotonic()
            self._next.set()

    def _truth(self, iid: int) -> int | None:
        return self._truths.get(iid) if hasattr(self, "_truths") else None

    async def run(self) -> None:
        """Replace the object after each complete inspection of it."""
        while True:
            await self._next.wait()
            self._next.clear()
            t0 = time.monotonic()
            while self._seen <= self._cleared and time.monotonic() - t0 < 60.0:
                await asyncio.sleep(0.02)
            if not self._held:
                self.spawn()


def watch_truths(rt: Any, feeder: Feeder) -> Any:
    """Map inspection ids to the object they saw (the row's simulator truth), from the
    record the service stores.  Returns the function that puts the store back."""
    from backend.inspection import results

    feeder._truths = {}  # type: ignore[attr-defined]
    inner = results.store

    async def store(db: Any, cell_id: int, rec: Any, **kw: Any) -> int:
        iid = await inner(db, cell_id, rec, **kw)
        feeder._truths[iid] = None if rec.truth is None else int(rec.truth["id"])  # type: ignore[attr-defined]
        return iid

    results.store = store  # type: ignore[assignment]

    def undo() -> None:
        results.store = inner  # type: ignore[assignment]

    return undo


# -- the cell -----------------------------------------------------------------------------
async def teach_one(rt: Any, name: str) -> None:
    """Teach ``name`` through the teach service (as benchmarks/inspection.py does)."""
    from benchmarks.inspection import _teach_all

    await _teach_all(rt, [name])


def untrained_name() -> str:
    from robot.sim.catalogue import CATALOGUE

    return next((n for n, e in CATALOGUE.items() if not e.trainable), UNTRAINED_FALLBACK)


async def start_run(rt: Any) -> Any:
    from backend.inspection import service

    opts = service.InspectOptions(policy="two-views", max_views=2, wait_s=30.0)
    return service.start_run(rt, opts, None)


def _ended(run: Any) -> Any:
    """A predicate: the run's job has ended."""
    return lambda: run.job.task.done()


#: Helper tasks (the feeder) whose death must end the campaign, not stall it.
WATCHED: list[asyncio.Task[Any]] = []


async def wait_until(pred: Any, timeout_s: float, what: str) -> None:
    t0 = time.monotonic()
    while not pred():
        for t in WATCHED:
            if t.done() and not t.cancelled() and t.exception() is not None:
                raise RuntimeError(
                    f"a helper task died while waiting for {what}"
                ) from t.exception()
        if time.monotonic() - t0 > timeout_s:
            raise TimeoutError(f"{what} did not happen within {timeout_s:g} s")
        await asyncio.sleep(0.05)


@dataclass
class KindResult:
    kind: str
    injected: int = 0
    recovery_s: list[float] = field(default_factory=list)
    resume_s: list[float] = field(default_factory=list)
    failed: int = 0
    reasons: list[str] = field(default_factory=list)
    lost: int = 0
    duplicated: int = 0
    partial: int = 0
    unsafe: int = 0
    during_fault: int = 0
    audited: int = 0
    inspections: int = 0
    cycle_s: list[float] = field(default_factory=list)
    note: str = ""

    def summary(self) -> dict[str, Any]:
        r = self.recovery_s
        return {
            "kind": self.kind, "injected": self.injected, "inspections": self.inspections,
            "lost": self.lost, "duplicated": self.duplicated, "partial": self.partial,
            "motions_audited": self.audited, "unsafe_motions": self.unsafe,
            "moves_during_fault": self.during_fault,
            "failed_rows": self.failed,
            "resume_median_s": _med(self.resume_s), "resume_max_s": _max(self.resume_s),
            "recovery_median_s": round(statistics.median(r), 2) if r else None,
            "recovery_max_s": round(max(r), 2) if r else None,
            "cycle_median_s": round(statistics.median(self.cycle_s), 2) if self.cycle_s else None,
            "reasons": sorted(set(self.reasons))[:6], "note": self.note,
        }  # fmt: skip


def _med(v: list[float]) -> float | None:
    return round(statistics.median(v), 2) if v else None


def _max(v: list[float]) -> float | None:
    return round(max(v), 2) if v else None


async def audit_rows(db: Any, cell_id: int, since_id: int) -> tuple[int, int, list[dict[str, Any]]]:
    """(partial rows, markers left, rows) of the cell after ``since_id``."""
    from sqlalchemy import func, select
    from sqlalchemy.orm import selectinload

    from backend.db.models import Inspection, InspectionInProgress

    async with db.session() as session:
        rows = (
            await session.scalars(
                select(Inspection)
                .where(Inspection.cell_id == cell_id, Inspection.id > since_id)
                .options(selectinload(Inspection.images))
                .order_by(Inspection.id)
            )
        ).all()
        markers = int(
            await session.scalar(
                select(func.count(InspectionInProgress.id)).where(
                    InspectionInProgress.cell_id == cell_id
                )
            )
            or 0
        )
    partial = 0
    out = []
    for r in rows:
        ok = r.finished_at is not None and r.reason != "" and r.decision is not None
        if r.decision.value != "failed":
            ok = ok and len(r.images) == len(r.viewpoints_visited or []) > 0
        partial += 0 if ok else 1
        out.append({"id": r.id, "decision": r.decision.value, "reason": r.reason,
                    "truth": None if r.truth is None else r.truth.get("id"),
                    "cycle_s": sum(v for k, v in (r.durations or {}).items() if k != "wait")})  # fmt: skip
    return partial, markers, out


# -- in-process faults -------------------------------------------------------------------------
class DbFault:
    """Make the database unavailable and bring it back (SQLite lock, or the PostgreSQL
    proxy cut with the database's backends terminated)."""

    def __init__(self, url: str, pg: PgDatabase | None) -> None:
        self.url, self.pg = url, pg
        self._release: threading.Event | None = None
        self._thread: threading.Thread | None = None

    async def down(self) -> None:
        if self.pg is not None:
            await self.pg.down()
            return
        path = self.url.split(":///", 1)[1]
        self._release = threading.Event()
        locked = threading.Event()
        release = self._release

        def hold() -> None:
            con = sqlite3.connect(path, timeout=30, isolation_level=None)
            try:
                con.execute("BEGIN EXCLUSIVE")
                locked.set()
                release.wait(120)
                con.execute("ROLLBACK")
            finally:
                con.close()

        self._thread = threading.Thread(target=hold, daemon=True)
        self._thread.start()
        await asyncio.to_thread(locked.wait, 30)

    async def up(self) -> None:
        if self.pg is not None:
            await self.pg.up()
            return
        assert self._release is not None and self._thread is not None
        self._release.set()
        await asyncio.to_thread(self._thread.join, 30)


async def in_process(args: argparse.Namespace, url: str, pg: PgDatabase | None,
                     progress: Any) -> tuple[dict[str, KindResult], dict[str, Any]]:  # fmt: skip
    """Baseline, then camera, e-stop, database (and serial) faults on one cell."""
    from backend.db.migrate import upgrade
    from backend.runtime import CellRuntime

    tmp = Path(tempfile.mkdtemp(prefix="vc-faults-"))
    settings = settings_for(tmp, url, time_scale=args.time_scale)
    await asyncio.to_thread(upgrade, url)
    kinds = list(args.kinds)
    results_: dict[str, KindResult] = {}
    info: dict[str, Any] = {}
    async with CellRuntime(settings, view3d=False) as rt:
        await teach_one(rt, TAUGHT)
    # The serial cell (if asked) is built on the same database, taught above.
    hw_factory = serial_hardware if "serial" in kinds else None
    for group in (("baseline", "camera", "estop", "database"), ("serial",)):
        todo = [k for k in group if k == "baseline" or k in kinds]
        if not todo:
            continue
        stack = contextlib.AsyncExitStack()
        async with stack:
            hardware, emu = None, None
            if group == ("serial",) and hw_factory is not None:
                hardware, emu = await hw_factory(settings, stack)
            rt = await stack.enter_async_context(
                CellRuntime(settings, view3d=False, hardware=hardware)
            )
            # object ids start again with each engine: audit only this cell's new rows
            _, _, before = await audit_rows(rt.database, rt.cell_id, 0)
            first_id = max((r["id"] for r in before), default=0)
            windows: list[FaultWindow] = []
            audit = MotionWatch(rt)
            audit.install()
            feeder = Feeder(rt, (TAUGHT, untrained_name()))
            unwatch = watch_truths(rt, feeder)
            feeder.start()
            feed_task = asyncio.create_task(feeder.run())
            WATCHED[:] = [feed_task]
            stack.callback(feed_task.cancel)
            run = await start_run(rt)
            dbf = DbFault(url, pg)
            spans: list[FaultWindow] = []  # each kind's part of the run, for the audit
            for kind in todo:
                res = results_.setdefault(kind, KindResult(kind))
                spans.append(FaultWindow(kind, time.time(), math.inf))
                if len(spans) > 1:
                    spans[-2] = FaultWindow(spans[-2].kind, spans[-2].start, spans[-1].start)
                since = len(feeder.done_times)
                n = args.baseline if kind == "baseline" else args.per_kind
                for k in range(n):
                    # wait for a fresh object and for its inspection to be moving the arm
                    c0 = sum(1 for _, d in feeder.done_times if d != "failed")
                    await wait_until(lambda c0=c0: sum(1 for _, d in feeder.done_times if d != "failed") > c0,  # noqa: B023 (awaited in this iteration)
                                     300, f"{kind}: a complete inspection before fault {k + 1}")  # fmt: skip
                    if kind == "baseline":
                        progress(f"baseline {k + 1}/{n}")
                        continue
                    # The fault starts while the arm moves inside an inspection (past its
                    # search for the part, which stores nothing when cut short): on the
                    # first motion after its durable marker (:meth:`MotionWatch.arm`).
                    began: list[float] = []
                    ending: list[Any] = []
                    inject = _injector(kind, rt, dbf, emu, args.fault_s, began, ending)
                    audit.arm(inject)
                    await wait_until(lambda: bool(INJECTIONS) and INJECTIONS[-1].done(), 300,
                                     f"{kind}: the next inspection to move the arm")  # fmt: skip
                    INJECTIONS.pop().result()  # a fault that could not start ends the campaign
                    w_start = began[0]
                    res.injected += 1
                    progress(f"{kind} fault {k + 1}/{n}")
                    if kind == "camera":
                        await asyncio.sleep(args.fault_s)
                        ending[0]()
                    elif kind == "estop":
                        await asyncio.sleep(args.fault_s)
                        await rt.cell.reset()
                        await wait_until(_ended(run), 30, "the run to end on e-stop")
                        run = await start_run(rt)  # the operator starts it again
                    elif kind == "database":
                        await asyncio.sleep(args.fault_s)
                        await dbf.up()
                    elif kind == "serial":
                        await ending[0]
                    windows.append(FaultWindow(kind, w_start, time.time()))
                    t_clear = time.monotonic()
                    c1 = sum(1 for t, d in feeder.done_times if d != "failed" and t > t_clear)
                    await wait_until(
                        lambda: any(d != "failed" and t > t_clear for t, d in feeder.done_times),  # noqa: B023 (awaited in this iteration)
                        300, f"{kind}: a complete inspection after the fault")  # fmt: skip
                    del c1
                    t_ok = next(t for t, d in feeder.done_times if d != "failed" and t > t_clear)
                    res.recovery_s.append(t_ok - t_clear)
                    # the cell moving again by itself: the first motion command after the end
                    moved = [t for t in audit.times if t > t_clear]
                    if moved:
                        res.resume_s.append(moved[0] - t_clear)
                res.inspections = len(feeder.done_times) - since
                res.failed = sum(1 for _, d in feeder.done_times[since:] if d == "failed")
            from backend.inspection import service

            # A clean end: no new object, and the one at the station finished (a complete
            # row names it) before the run is stopped, so the stop cuts no inspection short.
            feeder.hold()
            await wait_until(feeder.settled, 300, "the last object's complete inspection")
            with contextlib.suppress(Exception):
                service.stop_run(rt)
            await wait_until(_ended(run), 300, "the run to stop")
            unwatch()
            audit.uninstall()
            partial, markers, rows = await audit_rows(rt.database, rt.cell_id, first_id)
            assert settings.motion_log is not None
            info.setdefault("unsafe", []).extend(
                apply_motion_audit(results_, Path(settings.motion_log), windows, spans)
            )
            keep_log(args, Path(settings.motion_log), todo[-1])
            Path(settings.motion_log).unlink(missing_ok=True)  # the next part's own log
            tally(results_, todo, feeder, partial, markers, rows)
            feed_task.cancel()
    shutil.rmtree(tmp, ignore_errors=True)
    return results_, info


def tally(res: dict[str, KindResult], todo: list[str], feeder: Feeder, partial: int,
          markers: int, rows: list[dict[str, Any]]) -> None:  # fmt: skip
    """Lost / duplicated / partial over the whole cell's rows, charged to the last kind run
    (each kind's own numbers come from its span of the rows)."""
    complete: dict[int, int] = {}
    for r in rows:
        if r["decision"] != "failed" and r["truth"] is not None:
            complete[r["truth"]] = complete.get(r["truth"], 0) + 1
    # an object is lost when it was presented and taken away (not the one left at the end)
    # without a complete row, or is left at the end with only failed rows
    lost = sum(1 for o in feeder.presented[:-1] if complete.get(o, 0) == 0)
    last = feeder.presented[-1] if feeder.presented else None
    if last is not None and complete.get(last, 0) == 0 and any(r["truth"] == last for r in rows):
        lost += 1
    lost += markers
    dup = sum(c - 1 for c in complete.values() if c > 1)
    # charge each to the kind during whose span the object was presented: spans are in order
    for kind in todo:
        r = res[kind]
        r.cycle_s = (
            [x["cycle_s"] for x in rows if x["decision"] != "failed"]
            if kind == "baseline"
            else r.cycle_s
        )
        r.reasons += [x["reason"].split(";")[0][:90] for x in rows if x["decision"] == "failed"
                      and kind != "baseline" and _reason_kind(x["reason"]) == kind]  # fmt: skip
    res[todo[-1]].lost += lost
    res[todo[-1]].duplicated += dup
    res[todo[-1]].partial += partial


def _injector(kind: str, rt: Any, dbf: DbFault, emu: Any, fault_s: float,
              began: list[float], ending: list[Any]) -> Any:  # fmt: skip
    """The coroutine function that starts a ``kind`` fault, noting when it began in
    ``began`` and what ends it (the camera's release, the serial link's return) in
    ``ending``."""

    async def inject() -> None:
        began.append(time.time())
        if kind == "camera":
            ending.append(stall_camera(rt))
        elif kind == "estop":
            await rt.cell.estop()
        elif kind == "database":
            await dbf.down()
        elif kind == "serial":
            ending.append(asyncio.ensure_future(emu.vanish(fault_s)))

    return inject


def _reason_kind(reason: str) -> str:
    r = reason.lower()
    if "camera" in r:
        return "camera"
    if "emergency" in r or "e-stop" in r:
        return "estop"
    if "database" in r or "locked" in r:
        return "database"
    if "interrupted" in r:
        return "kill"
    return "serial"


def stall_camera(rt: Any) -> Any:
    """Make the camera's ``grab()`` hang until the returned function is called."""
    cam = rt.cell.feed.camera
    inner = cam.grab
    gate = asyncio.Event()

    async def grab() -> Any:
        if not gate.is_set():
            await gate.wait()
        return await inner()

    cam.grab = grab

    def release() -> None:
        gate.set()
        cam.grab = inner

    return release


async def serial_hardware(settings: Any, stack: contextlib.AsyncExitStack) -> tuple[Any, Any]:
    """The serial driver over a PTY to the emulator in front of a simulated arm; the sim
    camera on the same engine sees that arm."""
    from backend.hardware import Hardware, make_sim_engine
    from robot.drivers.serial import SerialDriver
    from robot.drivers.serial.emulator import Emulator
    from robot.sim import SimCamera, SimDriver

    engine = await asyncio.to_thread(make_sim_engine, settings)
    arm = SimDriver(engine)
    await arm.connect()
    tmp = tempfile.mkdtemp(prefix="vc-faults-tty-")
    emu = Emulator(arm, link=f"{tmp}/tty", seed=3, start_tolerance_rad=0.05)
    await emu.start()
    stack.callback(shutil.rmtree, tmp, True)  # the PTY's folder, after the emulator closed
    stack.push_async_callback(arm.close)
    stack.push_async_callback(emu.close)
    driver = SerialDriver(emu.path, state_rate_hz=settings.state_rate_hz)
    return Hardware(driver, SimCamera(engine), engine), emu


# -- SIGKILL of the server -------------------------------------------------------------------
async def kill_campaign(args: argparse.Namespace, progress: Any, taught_url: str | None = None,
                        info: dict[str, Any] | None = None) -> KindResult:  # fmt: skip
    """``visioncell serve`` killed with SIGKILL mid-inspection, then started again, on
    ``taught_url`` (a SQLite file with the model taught; None: a new one, taught here).
    Every motion of the children is audited from their motion log after the last restart."""
    import httpx

    from backend.db.migrate import upgrade
    from backend.db.session import Database
    from backend.runtime import CellRuntime

    res = KindResult("kill")
    tmp = Path(tempfile.mkdtemp(prefix="vc-faults-kill-"))
    motion_log = tmp / "motion.jsonl"
    if taught_url is None:
        url = f"sqlite+aiosqlite:///{tmp / 'cell.db'}"
        await asyncio.to_thread(upgrade, url)
        settings = settings_for(tmp, url, time_scale=args.time_scale, motion_log=motion_log)
        async with CellRuntime(settings, view3d=False) as rt:
            await teach_one(rt, TAUGHT)
    else:
        url = taught_url
    port = free_port()
    env = {**os.environ, "VISIONCELL_DATABASE_URL": url, "VISIONCELL_HTTP_PORT": str(port),
           "VISIONCELL_HTTP_HOST": "127.0.0.1", "VISIONCELL_VIEW3D_ENABLED": "false",
           "VISIONCELL_SIM_DEMO": "true", "VISIONCELL_TIME_SCALE": str(args.time_scale),
           "VISIONCELL_AUTH_ENABLED": "false", "VISIONCELL_VAR_DIR": str(tmp / "var"),
           "VISIONCELL_SECRET_KEY": "faults-secret-0123456789abcdef",
           "VISIONCELL_BOOTSTRAP_OPERATOR": "false", "MUJOCO_GL": "egl",
           "VISIONCELL_MOTION_LOG": str(motion_log)}  # fmt: skip
    exe = Path(sys.executable).with_name("visioncell")
    db = Database(url)
    base = f"http://127.0.0.1:{port}/api"
    log = open(tmp / "serve.log", "ab")  # noqa: SIM115 - closed below

    async def launch() -> subprocess.Popen[bytes]:
        p = subprocess.Popen([str(exe), "serve"], env=env, stdout=log, stderr=log)
        async with httpx.AsyncClient(timeout=2.0) as c:
            for _ in range(2400):  # a loaded machine takes a while to start MuJoCo
                with contextlib.suppress(httpx.HTTPError):
                    if (await c.get(f"{base}/health")).status_code == 200:
                        return p
                if p.poll() is not None:
                    raise RuntimeError(f"serve ended with {p.returncode}: see {tmp / 'serve.log'}")
                await asyncio.sleep(0.1)
        p.kill()  # never leave a server behind
        p.wait(30)
        raise RuntimeError("serve did not answer /api/health within 240 s")

    async def markers() -> list[Any]:
        from sqlalchemy import select

        from backend.db.models import InspectionInProgress

        async with db.session() as s:
            return [m.started_at for m in (await s.scalars(select(InspectionInProgress))).all()]

    killed: list[Any] = []
    windows: list[FaultWindow] = []
    _, _, before = await audit_rows(db, 1, 0)
    first_id = max((r["id"] for r in before), default=0)

    async def complete_after(iid: int) -> int:
        _, _, rows = await audit_rows(db, 1, iid)
        return sum(1 for r in rows if r["decision"] != "failed")

    proc = await launch()
    try:
        async with httpx.AsyncClient(timeout=10.0) as c:
            body = {"policy": "two-views", "max_views": 2, "wait_s": 30.0}
            r = await c.post(f"{base}/inspection/run", json=body)
            r.raise_for_status()
            for k in range(args.per_kind):
                # a complete inspection first, then kill while the next one is in progress
                _, _, rows = await audit_rows(db, 1, first_id)
                last = max((x["id"] for x in rows), default=first_id)
                t0 = time.monotonic()
                while await complete_after(last) == 0 or not await markers():
                    if time.monotonic() - t0 > 300:
                        raise TimeoutError("no inspection in progress within 300 s")
                    await asyncio.sleep(0.05)
                await asyncio.sleep(float(np.random.default_rng(k).uniform(0.1, 0.8)))
                while not (held := await markers()):
                    await asyncio.sleep(0.02)
                progress(f"kill {k + 1}/{args.per_kind}")
                w_start = time.time()
                proc.send_signal(signal.SIGKILL)
                proc.wait(30)
                killed.extend(held)
                res.injected += 1
                t_clear = time.monotonic()
                proc = await launch()
                # from the kill until the new process serves: nobody may move the arm
                windows.append(FaultWindow("kill", w_start, time.time()))
                res.resume_s.append(time.monotonic() - t_clear)  # serving again
                r = await c.post(f"{base}/inspection/run", json=body)
                r.raise_for_status()
                _, _, rows = await audit_rows(db, 1, first_id)
                last = max(x["id"] for x in rows)
                while await complete_after(last) == 0:
                    if time.monotonic() - t0 > 600:
                        raise TimeoutError("no complete inspection after the restart")
                    await asyncio.sleep(0.1)
                res.recovery_s.append(time.monotonic() - t_clear)
            with contextlib.suppress(httpx.HTTPError):
                await c.post(f"{base}/inspection/stop")
                await asyncio.sleep(0.5)
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
        log.close()
    partial, left, rows = await audit_rows(db, 1, first_id)
    from sqlalchemy import select

    from backend.db.models import Inspection

    async with db.session() as s:
        started = [
            r.started_at
            for r in (await s.scalars(select(Inspection).where(Inspection.id > first_id))).all()
        ]
    await db.dispose()
    res.inspections = len(rows)
    res.partial = partial
    res.reasons = [r["reason"].split(";")[0][:90] for r in rows if r["decision"] == "failed"]
    res.failed = sum(1 for r in rows if r["decision"] == "failed")
    interrupted = sum(1 for r in rows if r["reason"].startswith("interrupted"))
    # every inspection in progress at a kill (its marker read just before) must have
    # exactly one row afterwards: the interrupted row written at start-up, or its own
    # result if it finished in the instant between the read and the kill
    res.lost = sum(1 for t in killed if started.count(t) == 0) + left
    res.duplicated = sum(started.count(t) - 1 for t in killed if started.count(t) > 1)
    from backend.cell.motionlog import read_motion_log

    judged: dict[str, KindResult] = {"kill": res}
    unsafe = apply_motion_audit(judged, motion_log, windows, [FaultWindow("kill", 0, math.inf)])
    keep_log(args, motion_log, "kill")
    if info is not None:
        info.setdefault("unsafe", []).extend(unsafe)
    children = len({m["pid"] for m in read_motion_log(motion_log)})
    res.note = (f"{interrupted} interrupted row(s) written at start-up; {res.audited} motions "
                f"of {children} processes (the serve children, and the teach when it ran "
                "here) audited from their motion log")  # fmt: skip
    shutil.rmtree(tmp, ignore_errors=True)
    return res


# -- report ------------------------------------------------------------------------------------
def table(rows: list[dict[str, Any]]) -> Table:
    t = Table(title="Fault campaign during continuous inspection (issue 16, part 1)")
    for col in ("fault", "injected", "inspections", "failed rows", "lost", "duplicated",
                "partial", "motions audited", "unsafe", "moves in fault", "resume med/max s",
                "next complete med/max s", "cycle s"):  # fmt: skip
        t.add_column(col, justify="right" if col != "fault" else "left")
    for r in rows:
        t.add_row(r["kind"], str(r["injected"]), str(r["inspections"]), str(r["failed_rows"]),
                  str(r["lost"]), str(r["duplicated"]), str(r["partial"]),
                  str(r["motions_audited"]), str(r["unsafe_motions"]),
                  str(r["moves_during_fault"]),
                  f"{_f(r['resume_median_s'])} / {_f(r['resume_max_s'])}",
                  f"{_f(r['recovery_median_s'])} / {_f(r['recovery_max_s'])}",
                  _f(r["cycle_median_s"]))  # fmt: skip
    return t


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


async def campaign(args: argparse.Namespace, progress: Any) -> dict[str, Any]:
    """The whole campaign; returns the JSON summary."""
    pg = None
    url = ""
    tmp = Path(tempfile.mkdtemp(prefix="vc-faults-db-"))
    if args.postgres:
        pg = PgDatabase(args.postgres_url)
        url = await pg.create()
        progress(f"PostgreSQL: database {pg.name} behind a proxy on port {pg.proxy.port}")
    else:
        url = f"sqlite+aiosqlite:///{tmp / 'cell.db'}"
    try:
        res, info = await in_process(args, url, pg, progress)
    finally:
        if pg is not None:
            await pg.drop()
    if "kill" in args.kinds:
        try:
            # on SQLite the child serves the database taught above (no second teach)
            res["kill"] = await kill_campaign(args, progress, None if pg else url, info)
        except Exception as exc:  # report what was measured before, and why this part ended
            res["kill"] = KindResult(
                "kill", note=f"the kill part ended: {type(exc).__name__}: {exc}"
            )
    shutil.rmtree(tmp, ignore_errors=True)
    rows = [r.summary() for r in res.values()]
    base = res.get("baseline")
    return {
        "benchmark": "faults", "database": "postgresql" if pg else "sqlite",
        "time_scale": args.time_scale, "fault_s": args.fault_s, "kinds": rows,
        "baseline_cycle_median_s": base.summary()["cycle_median_s"] if base else None,
        "totals": {k: sum(int(r[k]) for r in rows) for k in ("injected", "lost", "duplicated",
                                                             "partial", "unsafe_motions")},
        "unsafe_detail": info.get("unsafe", [])[:10],
    }  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--per-kind", type=int, default=3, help="faults of each kind (1..50)")
    p.add_argument("--baseline", type=int, default=4, help="inspections without faults (1..100)")
    p.add_argument(
        "--fault-s", type=float, default=12.0, help="how long each fault lasts, s (0.5..60)"
    )
    p.add_argument("--time-scale", type=float, default=4.0, help="simulated s per wall s (1..20)")
    p.add_argument(
        "--kinds",
        default=",".join(KINDS),
        help=f"comma-separated fault kinds among {', '.join(KINDS)} (default: all)",
    )
    p.add_argument(
        "--postgres",
        action="store_true",
        help="the cell on a database of its own on the PostgreSQL server of --postgres-url",
    )
    p.add_argument(
        "--postgres-url",
        default=os.environ.get(
            "VISIONCELL_TEST_POSTGRES_URL", "postgresql+asyncpg://postgres@127.0.0.1:5432/test"
        ),
        help="the server (any database on it; default: $VISIONCELL_TEST_POSTGRES_URL)",
    )
    p.add_argument("--keep-logs", default=None, help="copy each part's motion log to this folder")
    p.add_argument("--json", action="store_true", help="one JSON line on the last line")
    args = p.parse_args(argv)
    for name, v, lo, hi in (("--per-kind", args.per_kind, 1, 50), ("--baseline", args.baseline, 1, 100),
                            ("--fault-s", args.fault_s, 0.5, 60), ("--time-scale", args.time_scale, 1, 20)):  # fmt: skip
        if not lo <= v <= hi:
            p.error(f"{name} must be in [{lo}, {hi}], got {v!r}")
    kinds = tuple(k.strip() for k in args.kinds.split(",") if k.strip())
    bad = [k for k in kinds if k not in KINDS]
    if bad or not kinds:
        p.error(f"--kinds must name some of {', '.join(KINDS)}, got {args.kinds!r}")
    args.kinds = kinds
    t0 = time.monotonic()

    def progress(msg: str) -> None:
        err.print(f"[{time.monotonic() - t0:6.1f} s] {msg}")

    summary = asyncio.run(campaign(args, progress))
    out.print(table(summary["kinds"]))
    for r in summary["kinds"]:
        if r["reasons"]:
            out.print(f"{r['kind']}: failed rows' reasons: " + " | ".join(r["reasons"]))
        if r["note"]:
            out.print(f"{r['kind']}: {r['note']}")
    if args.json:
        print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
