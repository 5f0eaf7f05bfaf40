"""The hardware half of :class:`backend.runtime.CellRuntime`'s assembly: the robot
driver, camera and world the settings name wired into a started :class:`~backend.cell.Cell`
(:func:`assemble_cell`), and the viser 3D view over it (:func:`start_view3d`).

Each helper registers how to undo what it started on the runtime's exit stack, so the
runtime's exit undoes everything in the reverse order of its entry.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import TYPE_CHECKING, Any

from backend.cell import Cell, EventBus
from backend.db.session import Database
from backend.hardware import CellWorld, Hardware, make_hardware
from backend.jobs import Job
from backend.knowntokens import KnownTokens
from backend.settings import Settings
from backend.throttle import SignInThrottle

if TYPE_CHECKING:
    from backend.view3d import View3D
    from robot.sim import SimEngine

__all__ = ["assemble_cell", "start_view3d"]


def _arm_owner(cell: Cell) -> str | None:
    """Who holds the cell's motion lock now (None: nobody)."""
    holder = cell.jobs.arm_holder
    return None if holder is None else str(holder.owner)


async def assemble_cell(
    stack: contextlib.AsyncExitStack,
    settings: Settings,
    hardware: Hardware | None,
    *,
    db: Database,
    cell_id: int,
    bus: EventBus,
    interrupted: list[Job],
) -> tuple[Hardware, CellWorld, Cell]:
    """Build the hardware (``hardware``, else :func:`make_hardware` of ``settings``) and
    start the cell on it: the simulator's collision model, the conveyors the E-STOP halts,
    the motion log between the cell and its driver (``settings.motion_log``), the job
    journal (``interrupted``: the jobs the last process left running, listed as such).
    Returns the hardware, the cell's world and the started cell."""
    s = settings
    if hardware is None:
        hardware = await asyncio.to_thread(make_hardware, s)
    if hardware.sim is not None:
        engine = hardware.sim
        stack.push_async_callback(asyncio.to_thread, engine.stop)
    cell_world = hardware.cell_world()
    world = None
    if hardware.sim is not None:
        from robot.sim.obstacles import collision_world

        world = collision_world(hardware.sim.config.layout, model=hardware.sim.arm_model)
    # The E-STOP halts every conveyor that can move (a fixed station cannot).
    conveyors = [cell_world.conveyor] if cell_world.conveyor.controllable else []
    driver: Any = hardware.driver
    logged = None
    if s.motion_log is not None:  # the audit sits between the cell and its driver
        from backend.cell.motionlog import LoggedDriver, MotionLog

        motion_log = MotionLog(s.motion_log)
        stack.callback(motion_log.close)
        driver = logged = LoggedDriver(driver, motion_log)
    cell = Cell(s, driver, hardware.camera, world=world, conveyors=conveyors, bus=bus)
    if logged is not None:
        logged.holder = lambda: _arm_owner(cell)
    cell.db_id = cell_id
    # Jobs the last process left running are listed as interrupted; this process's
    # jobs are journalled so that the next one can do the same (the journal drains
    # after the cell has stopped its jobs, before the database goes).
    from backend.jobjournal import JobJournal

    cell.jobs.remember(interrupted)
    journal = JobJournal(db, cell_id)
    journal.start()
    stack.push_async_callback(journal.close)
    cell.jobs.add_listener(journal)
    await cell.start()
    stack.push_async_callback(cell.stop)
    return hardware, cell_world, cell


async def start_view3d(
    stack: contextlib.AsyncExitStack,
    settings: Settings,
    cell: Cell,
    *,
    db: Database,
    sim: SimEngine | None,
    bins: Any,
    throttle: SignInThrottle,
    known: KnownTokens,
) -> View3D:
    """Start the viser 3D view of ``cell`` (its own port; signs in with the cell's tokens,
    the sign-in throttle and the tokens known from memory); stopped on the stack's exit."""
    from backend.view3d import View3D, ViewAccess

    s = settings
    access = ViewAccess(
        db,
        secret=s.secret_key.get_secret_value(),
        auth_enabled=s.auth_enabled,
        throttle=throttle,
        known=known,
    )
    view = View3D(cell, host=s.viser_host, port=s.viser_port, sim=sim, access=access, bins=bins)
    await view.start()
    stack.push_async_callback(view.stop)
    return view
