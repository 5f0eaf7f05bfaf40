"""E-STOP while a job stores its result through a database outage: the stop latches, the
cell-wide event goes out and ``Cell.estop`` returns while the job is still winding down
(an inspection cancelled by the stop stores its failed row, retrying until the database is
back); the job ends after, in the background."""

from __future__ import annotations

import asyncio

import pytest
from sqlalchemy.exc import OperationalError

from backend.cell import CellStopped
from backend.inspection.recovery import retry_database
from backend.jobs import JobState
from robot.errors import LinkDown
from robot.model import ASEA
from tests.utils.cells import ideal_cell
from tests.utils.factories import make_settings

#: Bounds a hang only.
HANG_S = 120.0


class Belt:
    def __init__(self) -> None:
        self.name = "belt"
        self.halted = False

    async def halt(self) -> None:
        self.halted = True

    async def resume(self) -> None:
        self.halted = False


async def test_estop_does_not_wait_for_a_job_storing_through_an_outage(tmp_path):
    belt = Belt()
    cell, driver, _ = ideal_cell(make_settings(tmp_path, time_scale=1.0), conveyors=[belt])
    await cell.start()
    database_back = asyncio.Event()
    storing = asyncio.Event()
    attempts = 0

    async def store() -> int:
        nonlocal attempts
        attempts += 1
        storing.set()
        if not database_back.is_set():
            raise OperationalError("INSERT", {}, Exception("database is locked"))
        return 1

    async def body(job):  # what an inspection does when it is cancelled mid-way
        try:
            await cell.move_to(ASEA.q_ready, speed=0.05)
        except asyncio.CancelledError:
            await asyncio.shield(retry_database("storing an inspection", store))
            raise
        return {}

    events: list[CellStopped] = []
    cell.bus.add_listener(events.append, CellStopped)
    try:
        job = cell.jobs.start("inspect", body, motion=True)
        await asyncio.sleep(0)  # the job starts moving
        async with asyncio.timeout(HANG_S):
            while not driver.state.moving:
                await asyncio.sleep(0.01)
            await cell.estop(by="alice", role="viewer", source="test")
        # answered: latched and announced, the job still storing its row
        assert driver.state.estopped and belt.halted and cell.estopped
        assert [(e.active, e.jobs) for e in events] == [(True, (job.id,))]
        async with asyncio.timeout(HANG_S):
            await storing.wait()
        assert job.state is JobState.running  # the stop did not wait for it
        database_back.set()
        async with asyncio.timeout(HANG_S):
            await cell.jobs.wait(job)
        assert job.state is JobState.cancelled and attempts >= 2
    finally:
        database_back.set()
        await cell.stop()


async def test_estop_does_not_wait_for_a_slow_conveyor(settings):
    """A conveyor that takes long to confirm its halt (a PLC) delays neither the arm's stop
    nor the answer beyond the latch's bound; the others are halted at once."""
    release = asyncio.Event()

    class SlowBelt(Belt):
        async def halt(self) -> None:
            await release.wait()
            self.halted = True

    slow, quick = SlowBelt(), Belt()
    slow.name = "slow"
    cell, driver, _ = ideal_cell(settings, conveyors=[slow, quick])
    await cell.start()
    events: list[CellStopped] = []
    cell.bus.add_listener(events.append, CellStopped)
    try:
        async with asyncio.timeout(HANG_S):
            await cell.estop()
        assert driver.state.estopped and quick.halted and not slow.halted
        assert events[0].conveyors == ("belt",)
        release.set()
        async with asyncio.timeout(HANG_S):
            while not slow.halted:
                await asyncio.sleep(0.01)
    finally:
        release.set()
        await cell.stop()


async def test_an_arm_that_cannot_be_reached_still_halts_the_belts(settings):
    """The arm's driver failing (a serial link down) halts the belts all the same and
    announces the stop with ``arm_latched`` false; the caller gets the driver's error."""
    belt = Belt()
    cell, driver, _ = ideal_cell(settings, conveyors=[belt])
    await cell.start()

    async def unreachable() -> None:
        raise LinkDown("the serial link is down")

    events: list[CellStopped] = []
    cell.bus.add_listener(events.append, CellStopped)
    driver.estop = unreachable
    try:
        with pytest.raises(LinkDown):
            async with asyncio.timeout(HANG_S):
                await cell.estop(by="bob", role="operator", source="test")
        assert belt.halted and cell.estopped
        assert [(e.active, e.arm_latched, e.conveyors) for e in events] == [
            (True, False, ("belt",))
        ]
    finally:
        await cell.stop()
