"""Serial link benchmark: latency, state stream, recovery, emergency stop, fault campaign.

Run ``python -m benchmarks.serial [--json] [--faults 1000]``.  Everything runs in one process
over real pseudo-terminals: ``SerialDriver`` on one end, the controller ``Emulator`` (backed by
an ``IdealDriver``) on the other.  A pseudo-terminal ignores the baud rate the host sets, so
the figures "PTY" are memory speed; the rows marked "115200 model" pace every byte in the
emulator at 10 bit times (8N1), which is what a real 115,200 baud line costs.

Baselines measured in the same run:

* round trip: a raw echo over the same kind of pseudo-terminal (the floor: kernel plus
  asyncio, no protocol), and a direct in-process call to the ideal driver (no link at all);
* reconnection: a cold ``connect()`` of a fresh driver to a live port;
* emergency stop: a ``PING`` issued at the same moment, which waits behind queued commands;
* fault campaign: a naive stop-and-wait host that re-sends an unanswered motion command under
  a new sequence number (no duplicate protection), on the same faulty line.

Output: a table on stdout, progress on stderr, ``benchmarks/out/serial.png``, and with
``--json`` one JSON object on the last line.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import platform
import secrets
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from robot.drivers import IdealDriver
from robot.drivers.serial import FaultConfig, SerialDriver, SerialLink
from robot.drivers.serial import frames as fr
from robot.drivers.serial.emulator import Emulator
from robot.drivers.serial.ptyport import PtyPort
from robot.errors import CommandRejected, CommandTimeout, DriverError, RobotError
from robot.model import ASEA
from robot.trajectory import plan_joint_move

OUT_DIR = Path(__file__).parent / "out"
TARGETS = {
    "rtt_median_ms": 5.0,
    "stream_hz": 50.0,
    "recover_s": 1.0,
    "estop_ms": 20.0,
    "lost": 0,
    "duplicated": 0,
}
CAMPAIGN_FAULTS = FaultConfig(
    drop_p=0.04, corrupt_p=0.04, truncate_p=0.02, garbage_p=0.03, delay_p=0.02, delay_s=0.04,
    vanish_p=0.002, vanish_s=0.3,
)  # fmt: skip
BENCH_DRIVER = {
    "resend_after_s": 0.05,
    "command_timeout_s": 1.0,
    "heartbeat_s": 0.1,
    "silence_timeout_s": 0.8,
}
Q_A = ASEA.q_home
Q_B = np.array([0.3, 1.45, -1.65, -0.2, 0.4])

Progress = Callable[[float, str], None]


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q)) if values else float("nan")


def _summary_ms(values_s: list[float]) -> dict[str, float]:
    ms = [v * 1e3 for v in values_s]
    return {"median_ms": _pct(ms, 50), "p95_ms": _pct(ms, 95), "max_ms": max(ms), "n": len(ms)}


class _Cell:
    """An ideal arm, an emulator on a PTY in a temporary directory, and optionally a driver."""

    def __init__(self, *, time_scale: float = 50.0, **emu_kw: object) -> None:
        self.tmp = tempfile.TemporaryDirectory(prefix="vc-bench-")
        self.arm = IdealDriver(time_scale=time_scale, rate_hz=200.0)
        self.emu_kw = emu_kw
        self.emu: Emulator
        self.driver: SerialDriver | None = None

    async def __aenter__(self) -> _Cell:
        await self.arm.connect()
        self.emu = Emulator(self.arm, link=f"{self.tmp.name}/tty", seed=11, **self.emu_kw)  # type: ignore[arg-type]
        await self.emu.start()
        return self

    async def attach(self, **kw: object) -> SerialDriver:
        self.driver = SerialDriver(self.emu.path, seed=5, **{**BENCH_DRIVER, **kw})  # type: ignore[arg-type]
        await self.driver.connect()
        if not self.driver.state.connected:
            raise RuntimeError("driver did not connect to the emulator")
        return self.driver

    async def __aexit__(self, *exc: object) -> None:
        if self.driver is not None:
            await self.driver.close()
        await self.emu.close()
        await self.arm.close()
        self.tmp.cleanup()


# -- 1. round trip ---------------------------------------------------------------------------
async def bench_round_trip(n: int, progress: Progress) -> dict[str, object]:
    """PING round trips over a PTY, paced at 115200, and the two baselines."""
    out: dict[str, object] = {}
    # Baseline 1: raw echo of a line of the same length as PING + its ACK, over a PTY.
    tmp = tempfile.TemporaryDirectory(prefix="vc-echo-")
    echo: PtyPort | None = None

    def bounce(data: bytes) -> None:
        assert echo is not None
        echo.write(data)

    echo = PtyPort(bounce, link=f"{tmp.name}/tty")
    echo.reopen()
    got = asyncio.Event()
    link = await SerialLink.open(
        echo.path, baud=115200, on_bytes=lambda b: got.set() if b"\n" in b else None
    )
    line = b"C 12345 PING*ABCD\n"
    times = []
    for _ in range(n):
        got.clear()
        t0 = time.perf_counter()
        link.write(line)
        await got.wait()
        times.append(time.perf_counter() - t0)
    link.close()
    await asyncio.sleep(0.01)
    echo.close()
    tmp.cleanup()
    out["raw_echo"] = _summary_ms(times)
    progress(0.2, "round trip: raw echo done")

    # Baseline 2: the same command without any link (in-process call to the ideal driver).
    arm = IdealDriver()
    await arm.connect()
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        await arm.stop()
        times.append(time.perf_counter() - t0)
    await arm.close()
    out["direct_call"] = _summary_ms(times)

    async with _Cell(time_scale=1000.0) as cell:
        d = await cell.attach()
        times = [await d.ping() for _ in range(n)]
        out["serial_pty"] = _summary_ms(times)
        out["move_95_points_pty"] = _summary_ms(await _timed_moves(d, 6))
        progress(0.6, "round trip: PTY done")
    async with _Cell(time_scale=1000.0, baud=115200) as cell:
        d = await cell.attach()
        times = [await d.ping() for _ in range(max(50, n // 4))]
        out["serial_115200_model"] = _summary_ms(times)
        out["move_95_points_115200_model"] = _summary_ms(await _timed_moves(d, 4))
        ping = fr.encode(fr.Ping(123456))
        ack = fr.encode(fr.Ack(123456, "PING", ("1234567",)))
        out["wire_time_115200_ms"] = (len(ping) + len(ack)) * 10 / 115200 * 1e3
    progress(1.0, "round trip done")
    return out


async def _timed_moves(d: SerialDriver, n: int) -> list[float]:
    """Wall time of ``move()`` for the q_home <-> q_ready plan (95 points at 100 Hz).

    The arm runs 1000 times faster than real time (about 1 ms of motion), so this is the
    cost of the link: upload, RUN, completion report, final state.
    """
    times = []
    for i in range(n):
        goal = ASEA.q_ready if i % 2 == 0 else ASEA.q_home
        traj = plan_joint_move(d.state.q, goal, rate_hz=100.0)
        t0 = time.perf_counter()
        report = await d.move(traj)
        times.append(time.perf_counter() - t0)
        if not report.completed:
            raise RuntimeError(f"benchmark move failed: {report.reason}")
    return times


# -- 2. state stream -------------------------------------------------------------------------
async def bench_stream(seconds: float, progress: Progress) -> dict[str, object]:
    """Achieved state-event rate for several requested rates, PTY and paced at 115200."""
    out: dict[str, object] = {}
    cases = [
        ("pty", None, 50.0),
        ("pty", None, 100.0),
        ("pty", None, 200.0),
        ("115200_model", 115200, 50.0),
        ("115200_model", 115200, 100.0),
    ]
    for i, (label, baud, rate) in enumerate(cases):
        async with _Cell(baud=baud) as cell:
            d = await cell.attach(state_rate_hz=rate)
            await asyncio.sleep(0.2)
            count = 0

            async def watch(driver: SerialDriver = d) -> None:
                nonlocal count
                async for _ in driver.states():
                    count += 1

            e0 = d.stats["events"]
            w = asyncio.create_task(watch())
            t0 = time.perf_counter()
            await asyncio.sleep(seconds)
            dt = time.perf_counter() - t0
            w.cancel()
            events = d.stats["events"] - e0
            out[f"{label}_{int(rate)}hz"] = {
                "requested_hz": rate,
                "received_hz": events / dt,
                "published_hz": count / dt,
                "missed_events": d.stats["events_missed"],
            }
        progress((i + 1) / len(cases), f"stream {label} {rate:g} Hz")
    return out


# -- 3. recovery after the port returns ------------------------------------------------------
async def bench_recovery(cycles: int, progress: Progress) -> dict[str, object]:
    """Time from the port re-appearing to the driver's session being back."""
    out: dict[str, object] = {}
    async with _Cell() as cell:
        cold = []
        for _ in range(10):
            d = SerialDriver(cell.emu.path, **BENCH_DRIVER)  # type: ignore[arg-type]
            t0 = time.monotonic()
            await d.connect()
            cold.append(d.connected_at - t0)
            await d.close()
        out["cold_connect"] = _summary_ms(cold)
        d = await cell.attach()
        for label, outage_s, n in (
            ("outage_0.3s", 0.3, cycles),
            ("outage_2s", 2.0, max(2, cycles // 4)),
        ):
            rec = []
            for i in range(n):
                await cell.emu.vanish(outage_s)
                back = time.monotonic()
                async with asyncio.timeout(10.0):
                    while d.connected_at < back:
                        await asyncio.sleep(0.001)
                rec.append(d.connected_at - back)
                progress(0.0, f"recovery {label} {i + 1}/{n}")
            out[label] = _summary_ms(rec) | {"outages_logged": d.outages}
        report = await d.move_joints(Q_B, speed=1.0)
        out["move_after_recovery_completed"] = report.completed
    progress(1.0, "recovery done")
    return out


# -- 4. emergency stop -----------------------------------------------------------------------
async def bench_estop(trials: int, progress: Progress) -> dict[str, object]:
    """Emergency-stop acknowledgement while an upload is queued and while the arm moves."""
    out: dict[str, object] = {}
    async with _Cell(time_scale=1.0) as cell:
        d = await cell.attach()
        cell.emu.fault = FaultConfig(process_delay_s=0.002)  # 2 ms per command: uploads queue
        during_upload, ping_upload, during_motion = [], [], []
        ping_timeouts = 0
        for i in range(trials):
            goal = Q_B if i % 2 == 0 else Q_A
            # (a) a PING issued during an upload: the baseline, it waits behind the points.
            task = asyncio.create_task(d.move(plan_joint_move(d.state.q, goal, rate_hz=100.0)))
            await asyncio.sleep(0.02)
            try:
                ping_upload.append(await d.ping())
            except CommandTimeout:  # a starved machine: the queue took longer than the timeout
                ping_timeouts += 1
            await _settle(task)
            # (b) the emergency stop in the same situation.
            goal = Q_A if np.allclose(d.state.q, Q_B, atol=1e-3) else Q_B
            task = asyncio.create_task(d.move(plan_joint_move(d.state.q, goal, rate_hz=100.0)))
            await asyncio.sleep(0.02)
            t0 = time.perf_counter()
            await d.estop()
            during_upload.append(time.perf_counter() - t0)
            await _settle(task)
            await _reset(d)
            # (c) during motion (upload finished, arm moving).
            task = asyncio.create_task(d.move_joints(goal, speed=0.5))
            async with asyncio.timeout(5.0):
                while not d.state.moving:
                    await asyncio.sleep(0.001)
            t0 = time.perf_counter()
            await d.estop()
            during_motion.append(time.perf_counter() - t0)
            await _settle(task)
            await _reset(d)
            progress((i + 1) / trials, f"estop trial {i + 1}/{trials}")
        out["estop_during_upload"] = _summary_ms(during_upload)
        out["estop_during_motion"] = _summary_ms(during_motion)
        out["ping_during_upload"] = _summary_ms(ping_upload) | {"timeouts": ping_timeouts}
    return out


async def _reset(d: SerialDriver, attempts: int = 5) -> None:
    """Reset after an emergency stop; on a starved machine, wait out a full controller queue.

    When the host's command timeout expires before a slow controller answered, the host
    forgets the command while the controller still holds it: it may then refuse a new one
    with ``NAK FULL`` until its queue drains.  That is the protocol working, not a failure.
    """
    for attempt in range(attempts):
        try:
            await d.reset()
            return
        except CommandRejected as exc:
            if exc.nak_code != "FULL" or attempt == attempts - 1:
                raise
            await asyncio.sleep(0.2)


async def _settle(task: asyncio.Task[object]) -> None:
    with contextlib.suppress(RobotError):
        await task


# -- 5. fault campaign -----------------------------------------------------------------------
async def bench_campaign(
    faults: int,
    progress: Progress,
    *,
    config: FaultConfig = CAMPAIGN_FAULTS,
    stall_s: float = 60.0,
) -> dict[str, object]:
    """Moves on a faulty line until ``faults`` faults hit command traffic; count losses and duplicates.

    ``config`` is the line's faults (the tests raise the port-vanish rate so that faults
    during the reconnection handshake happen within a short run); the campaign fails if no
    fault is injected for ``stall_s`` seconds (the link went dead).
    """
    async with _Cell(time_scale=50.0, watchdog_s=1.0) as cell:
        d = await cell.attach()
        cell.emu.fault = config
        issued: list[tuple[int, str]] = []  # (mid, outcome) per motion command
        t0 = time.perf_counter()
        i = 0
        stall = _StallGuard(lambda: cell.emu.stats.faults.on_commands, stall_s)
        outages_s: list[float] = []  # each outage, from the state's fall to its rise
        watcher = asyncio.create_task(_watch_outages(d, outages_s))
        while cell.emu.stats.faults.on_commands < faults:
            stall.check()
            i += 1
            goal = Q_B if i % 2 else Q_A
            mid = d.last_move_id + 1  # the id the driver gives this move if it gets that far
            try:
                if i % 3 == 0:
                    report = await d.move_joints(goal, speed=1.0)
                else:
                    report = await d.move(plan_joint_move(d.state.q, goal, rate_hz=20.0))
                outcome = "done" if report.completed else "interrupted"
            except RobotError:
                outcome = "refused" if d.last_move_id == mid else "not_sent"
                # Pause before the next try, as an operator's client would: a refusal can
                # come back without yielding to the event loop, and a loop that retries at
                # once would starve the driver's own tasks (its reconnection included).
                await asyncio.sleep(0.01)
                if not d.state.connected:
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout(5.0):
                            while not d.state.connected:
                                await asyncio.sleep(0.01)
            if d.last_move_id == mid:
                issued.append((mid, outcome))
            progress(
                min(1.0, cell.emu.stats.faults.on_commands / faults),
                f"campaign: {len(issued)} moves",
            )
        cell.emu.fault = FaultConfig()
        await asyncio.sleep(0.5)
        watcher.cancel()
        await asyncio.gather(watcher, return_exceptions=True)
        elapsed = time.perf_counter() - t0
        counts = _executions(cell.emu, d.session_id)
        result = _tally(issued, counts)
        result |= {
            "faults": cell.emu.stats.faults.as_dict(),
            "seconds": elapsed,
            "resends": d.stats["resends"],
            "rejected_lines_host": d.stats["rejected_lines"],
            "rejected_lines_controller": cell.emu.stats.rx_rejected,
            "duplicates_answered_from_cache": cell.emu.stats.duplicates,
            "outages": d.outages,
            "reconnect": _summary_ms(outages_s) if outages_s else {"n": 0},
        }
    return result


async def _watch_outages(d: SerialDriver, out: list[float]) -> None:
    """Append the length of every outage the driver's state shows (connected False -> True)."""
    since: float | None = None
    async for s in d.states():
        if not s.connected and since is None:
            since = time.monotonic()
        elif s.connected and since is not None:
            out.append(time.monotonic() - since)
            since = None


class _StallGuard:
    """Raise if a campaign stops injecting faults (the line went quiet for good)."""

    def __init__(self, count: Callable[[], int], limit_s: float = 60.0) -> None:
        self._count, self._limit_s = count, limit_s
        self._last, self._since = count(), time.monotonic()

    def check(self) -> None:
        now, n = time.monotonic(), self._count()
        if n != self._last:
            self._last, self._since = n, now
        elif now - self._since > self._limit_s:
            raise RuntimeError(f"campaign stalled: no fault injected for {self._limit_s:g} s")


def _executions(emu: Emulator, session: str | None) -> dict[int, int]:
    counts: dict[int, int] = {}
    for e in emu.executions:
        if session is None or e.session == session:
            counts[e.mid] = counts.get(e.mid, 0) + 1
    return counts


def _tally(issued: list[tuple[int, str]], counts: dict[int, int]) -> dict[str, object]:
    done = [m for m, o in issued if o == "done"]
    return {
        "motion_commands": len(issued),
        "reported_done": len(done),
        "reported_interrupted": sum(o == "interrupted" for _, o in issued),
        "refused": sum(o in ("refused", "not_sent") for _, o in issued),
        "lost": sum(counts.get(m, 0) == 0 for m in done),
        "duplicated": sum(counts.get(m, 0) > 1 for m, _ in issued),
        "executed_but_reported_refused": sum(
            counts.get(m, 0) > 0 for m, o in issued if o in ("refused", "not_sent")
        ),
    }


class NaiveHost:
    """Baseline: stop-and-wait, re-sends an unanswered command under a NEW number and move id.

    One command at a time; a reply must come within ``timeout_s``; otherwise the host asks
    again, as a fresh command (it has no notion of a command that may have run).  On BUSY it
    waits for the arm to stop and asks again.  It reconnects with a new session when the port
    drops.  This is what the protocol's sequence numbers and move ids are there to prevent.
    """

    def __init__(self, path: str, *, timeout_s: float = 0.05) -> None:
        self.path = path
        self.timeout_s = timeout_s
        self.session = secrets.token_hex(4).upper()
        self.parser = fr.FrameParser()
        self.link: SerialLink | None = None
        self.seq = 0
        self.mid = 0
        self.replies: dict[int, fr.Ack | fr.Nak] = {}
        self.arrived = asyncio.Event()

    def _feed(self, data: bytes) -> None:
        for f in self.parser.feed(data):
            if isinstance(f, fr.Ack | fr.Nak):
                self.replies[f.seq] = f
                self.arrived.set()

    async def _ensure_open(self) -> None:
        while self.link is None or not self.link.is_open:
            try:
                self.link = await SerialLink.open(self.path, baud=115200, on_bytes=self._feed)
                self.parser.clear()
                if isinstance(
                    await self.call(lambda s: fr.Hello(s, self.session), reopen=False), fr.Ack
                ):
                    return
            except DriverError:
                pass
            if self.link is not None:
                self.link.close()  # release the port's lock before trying again
            self.link = None
            await asyncio.sleep(0.05)

    async def call(
        self, make: Callable[[int], fr.Command], *, reopen: bool = True
    ) -> fr.Ack | fr.Nak | None:
        if reopen:
            await self._ensure_open()
        self.seq += 1
        seq = self.seq
        try:
            assert self.link is not None
            self.link.write(fr.encode(make(seq)))
            async with asyncio.timeout(self.timeout_s):
                while seq not in self.replies:
                    self.arrived.clear()
                    await self.arrived.wait()
        except (TimeoutError, DriverError):
            return None
        return self.replies.pop(seq)

    async def move(self, goal: np.ndarray) -> tuple[list[int], bool]:
        """Returns the move ids it sent and whether it believes the move was done."""
        mids = []
        for _ in range(6):
            self.mid += 1
            mids.append(self.mid)
            mid = self.mid
            r = await self.call(lambda s, m=mid: fr.MoveJoints(s, m, tuple(goal), speed=1.0))
            if isinstance(r, fr.Ack):
                await self._wait_still()
                return mids, True
            if isinstance(r, fr.Nak) and r.code == "BUSY":
                await self._wait_still()
        return mids, False

    async def _wait_still(self) -> None:
        for _ in range(100):
            r = await self.call(lambda s: fr.GetState(s))
            if isinstance(r, fr.Ack) and not fr.ArmSnapshot.from_args(r.args).moving:
                return
            await asyncio.sleep(0.005)

    def close(self) -> None:
        if self.link is not None:
            self.link.close()


async def bench_naive_campaign(faults: int, progress: Progress) -> dict[str, object]:
    async with _Cell(time_scale=50.0, watchdog_s=0.0) as cell:
        host = NaiveHost(cell.emu.path)
        await host._ensure_open()
        cell.emu.fault = CAMPAIGN_FAULTS
        logical: list[tuple[list[int], bool]] = []
        t0 = time.perf_counter()
        i = 0
        stall = _StallGuard(lambda: cell.emu.stats.faults.on_commands)
        while cell.emu.stats.faults.on_commands < faults:
            stall.check()
            i += 1
            logical.append(await host.move(Q_B if i % 2 else Q_A))
            progress(
                min(1.0, cell.emu.stats.faults.on_commands / faults), f"naive: {len(logical)} moves"
            )
        cell.emu.fault = FaultConfig()
        await asyncio.sleep(0.3)
        elapsed = time.perf_counter() - t0
        host.close()
        counts: dict[int, int] = {}
        for e in cell.emu.executions:
            counts[e.mid] = counts.get(e.mid, 0) + 1  # mids are unique across its sessions
        runs = [sum(counts.get(m, 0) for m in mids) for mids, _ in logical]
        return {
            "motion_commands": len(logical),
            "reported_done": sum(ok for _, ok in logical),
            "lost": sum(ok and r == 0 for (_, ok), r in zip(logical, runs, strict=True)),
            "duplicated": sum(r > 1 for r in runs),
            "extra_executions": sum(max(0, r - 1) for r in runs),
            "executed_but_reported_failed": sum(
                (not ok) and r > 0 for (_, ok), r in zip(logical, runs, strict=True)
            ),
            "faults": cell.emu.stats.faults.as_dict(),
            "seconds": elapsed,
        }


# -- report ----------------------------------------------------------------------------------
def _plot(results: dict[str, object]) -> Path | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - matplotlib is a runtime dependency
        return None
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    camp = results["campaign"]
    naive = results["campaign_naive"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    rt = results["round_trip"]
    labels = ["direct call", "raw PTY echo", "SerialDriver PTY", "SerialDriver 115200 model"]
    keys = ["direct_call", "raw_echo", "serial_pty", "serial_115200_model"]
    med = [rt[k]["median_ms"] for k in keys]  # type: ignore[index]
    p95 = [rt[k]["p95_ms"] for k in keys]  # type: ignore[index]
    x = np.arange(len(keys))
    axes[0].bar(x - 0.2, med, 0.4, label="median")
    axes[0].bar(x + 0.2, p95, 0.4, label="p95")
    axes[0].axhline(TARGETS["rtt_median_ms"], color="k", ls="--", lw=1, label="target 5 ms")
    axes[0].set_xticks(x, labels, rotation=15, fontsize=8)
    axes[0].set_ylabel("round trip, ms")
    axes[0].set_yscale("log")
    axes[0].legend(fontsize=8)
    bars = [camp["duplicated"], camp["lost"], naive["duplicated"], naive["lost"]]  # type: ignore[index]
    axes[1].bar(
        ["dup\nSerialDriver", "lost\nSerialDriver", "dup\nnaive", "lost\nnaive"],
        bars,
        color=["C0", "C0", "C3", "C3"],
    )
    axes[1].set_title(
        f"fault campaign ({camp['faults']['on_commands']} faults on commands)", fontsize=9
    )  # type: ignore[index]
    axes[1].set_ylabel("motion commands")
    fig.tight_layout()
    path = OUT_DIR / "serial.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _table(r: dict[str, object]) -> str:
    rt, st, rc, es = r["round_trip"], r["stream"], r["recovery"], r["estop"]  # type: ignore[misc]
    c, n = r["campaign"], r["campaign_naive"]  # type: ignore[misc]
    rows = [
        (
            "Round trip PING, PTY (median / p95)",
            f"{rt['serial_pty']['median_ms']:.3f} / {rt['serial_pty']['p95_ms']:.3f} ms",
            "<= 5 ms median",
            rt["serial_pty"]["median_ms"] <= 5.0,
        ),
        (
            "  paced at 115200 baud (model)",
            f"{rt['serial_115200_model']['median_ms']:.2f} / {rt['serial_115200_model']['p95_ms']:.2f} ms",
            f"wire alone {rt['wire_time_115200_ms']:.2f} ms",
            None,
        ),
        (
            "  baseline: raw PTY echo",
            f"{rt['raw_echo']['median_ms']:.3f} / {rt['raw_echo']['p95_ms']:.3f} ms",
            "",
            None,
        ),
        (
            "  baseline: direct call, no link",
            f"{rt['direct_call']['median_ms']:.4f} / {rt['direct_call']['p95_ms']:.4f} ms",
            "",
            None,
        ),
        (
            "move() of a 95-point trajectory, PTY / 115200 model",
            f"{rt['move_95_points_pty']['median_ms']:.1f} / "
            f"{rt['move_95_points_115200_model']['median_ms']:.0f} ms",
            "",
            None,
        ),
        (
            "State stream, PTY (asked 50 / 100 / 200 Hz)",
            f"{st['pty_50hz']['received_hz']:.1f} / {st['pty_100hz']['received_hz']:.1f} / {st['pty_200hz']['received_hz']:.1f} Hz",
            ">= 50 Hz",
            st["pty_100hz"]["received_hz"] >= 50.0,
        ),
        (
            "  paced at 115200 baud (asked 50 / 100 Hz)",
            f"{st['115200_model_50hz']['received_hz']:.1f} / {st['115200_model_100hz']['received_hz']:.1f} Hz",
            "",
            None,
        ),
        (
            "Reconnect after the port returns (0.3 s outage)",
            f"{rc['outage_0.3s']['median_ms']:.0f} / max {rc['outage_0.3s']['max_ms']:.0f} ms",
            "<= 1 s",
            rc["outage_0.3s"]["max_ms"] <= 1000.0,
        ),
        (
            "  after a 2 s outage (backoff at its cap)",
            f"{rc['outage_2s']['median_ms']:.0f} / max {rc['outage_2s']['max_ms']:.0f} ms",
            "<= 1 s",
            rc["outage_2s"]["max_ms"] <= 1000.0,
        ),
        ("  baseline: cold connect", f"{rc['cold_connect']['median_ms']:.1f} ms", "", None),
        (
            "E-stop ack, upload queued (median / p95)",
            f"{es['estop_during_upload']['median_ms']:.2f} / {es['estop_during_upload']['p95_ms']:.2f} ms",
            "<= 20 ms median",
            es["estop_during_upload"]["median_ms"] <= 20.0,
        ),
        (
            "E-stop ack, arm moving",
            f"{es['estop_during_motion']['median_ms']:.2f} / {es['estop_during_motion']['p95_ms']:.2f} ms",
            "<= 20 ms median",
            es["estop_during_motion"]["median_ms"] <= 20.0,
        ),
        (
            "  baseline: PING while upload queued",
            f"{es['ping_during_upload']['median_ms']:.1f} / {es['ping_during_upload']['p95_ms']:.1f} ms",
            "",
            None,
        ),
        *_campaign_rows(c, n),
    ]
    return _format(rows)


def _campaign_rows(c: Any, n: Any) -> list[tuple[str, str, str, bool | None]]:
    return [
        (
            f"Fault campaign: {c['faults']['on_commands']} faults, {c['motion_commands']} moves",
            f"lost {c['lost']}, duplicated {c['duplicated']}",
            "0 and 0",
            c["lost"] == 0 and c["duplicated"] == 0 and c["executed_but_reported_refused"] == 0,
        ),
        (
            f"  {c['outages']} outages in the campaign: reconnect (median / max)",
            f"{c['reconnect'].get('median_ms', float('nan')):.0f} / "
            f"{c['reconnect'].get('max_ms', float('nan')):.0f} ms",
            "",
            None,
        ),
        (
            f"  baseline naive host: {n['faults']['on_commands']} faults, {n['motion_commands']} moves",
            f"lost {n['lost']}, duplicated {n['duplicated']}",
            "",
            None,
        ),
    ]


def _format(rows: list[tuple[str, str, str, bool | None]]) -> str:
    w = max(len(a) for a, *_ in rows)
    v = max(len(b) for _, b, *_ in rows)
    lines = [f"{'measure':<{w}}  {'value':<{v}}  {'target':<16}  ok", "-" * (w + v + 24)]
    for a, b, t, ok in rows:
        lines.append(
            f"{a:<{w}}  {b:<{v}}  {t:<16}  {'' if ok is None else ('yes' if ok else 'NO')}"
        )
    return "\n".join(lines)


async def run(
    args: argparse.Namespace, progress: Callable[[str, float, str], None]
) -> dict[str, object]:
    results: dict[str, object] = {}
    steps: list[tuple[str, Callable[[Progress], object]]] = [
        ("round_trip", lambda p: bench_round_trip(args.round_trips, p)),
        ("stream", lambda p: bench_stream(args.stream_seconds, p)),
        ("recovery", lambda p: bench_recovery(args.outages, p)),
        ("estop", lambda p: bench_estop(args.estop_trials, p)),
        ("campaign", lambda p: bench_campaign(args.faults, p)),
        ("campaign_naive", lambda p: bench_naive_campaign(args.faults, p)),
    ]
    if args.campaign_only:
        steps = steps[-2:]
    for name, step in steps:
        results[name] = await step(lambda f, msg, n=name: progress(n, f, msg))  # type: ignore[misc]
    return results


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.serial", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument(
        "--faults", type=int, default=1000, help="faults injected per campaign (default 1000)"
    )
    ap.add_argument("--round-trips", type=int, default=500)
    ap.add_argument("--stream-seconds", type=float, default=2.0)
    ap.add_argument("--outages", type=int, default=10)
    ap.add_argument("--estop-trials", type=int, default=20)
    ap.add_argument(
        "--campaign-only",
        action="store_true",
        help="run only the fault campaign and its naive baseline (the soak test of the link)",
    )
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)

    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    console = Console(stderr=True)
    with Progress(
        TextColumn("{task.description:<40}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
    ) as bar:
        tasks: dict[str, int] = {}

        def report(section: str, fraction: float, msg: str) -> None:
            if section not in tasks:
                tasks[section] = bar.add_task(section, total=1.0)
            bar.update(tasks[section], completed=fraction, description=msg[:40])

        t0 = time.perf_counter()
        results = asyncio.run(run(args, report))
    results["meta"] = {
        "seconds": time.perf_counter() - t0,
        "python": platform.python_version(),
        "load_average_1min": os.getloadavg()[0],
        "cpus": os.cpu_count(),
        "machine": platform.machine(),
        "note": "PTY ignores the baud rate; '115200 model' rows pace bytes in the emulator",
        "targets": TARGETS,
        "campaign_faults": {k: v for k, v in vars(CAMPAIGN_FAULTS).items()},
    }
    if args.campaign_only:
        png = None
        print(_format(_campaign_rows(results["campaign"], results["campaign_naive"])))
    else:
        png = _plot(results)
        print(_table(results))
    meta = results["meta"]
    print(
        f"(one process, {meta['cpus']} CPUs, load average {meta['load_average_1min']:.1f} at the end; "  # type: ignore[index]
        "tails are scheduling noise when the machine is busy)"
    )
    if png is not None:
        print(f"plot: {png}")
    if args.json:
        print(json.dumps(results, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
