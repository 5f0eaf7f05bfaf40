"""The empty-belt backgrounds an inspection finds parts against: the still one of the top
view at the station (:func:`grab_background`) and the one registered to the belt's travel
(:func:`grab_belt_background`, a job: :func:`start_belt_background`)."""

from __future__ import annotations

import asyncio
import time
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from backend.inspection.context import Context, cam_pose, context, travel_of
from backend.planning import Shot, mounting_or_nominal, station_top
from vision.errors import Conflict, InvalidInput

if TYPE_CHECKING:
    from backend.runtime import CellRuntime
    from robot.cellworld import BeltSpan
    from robot.drivers.conveyor import Conveyor

__all__ = ["grab_background", "grab_belt_background", "start_belt_background"]


async def _station_top(rt: CellRuntime) -> tuple[Context, Shot]:
    """The context and the top view at the station, planned with the active hand-eye
    calibration (the nominal mounting without one)."""
    ctx = await context(rt)
    return ctx, await station_top(ctx.station, mounting_or_nominal(ctx.T_plan))


async def grab_background(rt: CellRuntime, *, speed: float | None = None) -> None:
    """Grab the empty-belt background of the top view at the station (the station must be
    empty), e.g. after the lights changed; stored with the teaches' backgrounds.  A belt
    background grabbed before it is no longer used (it holds the old light): grab that
    again too for constant belt speed."""
    _ctx, top = await _station_top(rt)
    frame = await rt.cell.look(top.q, speed=speed)
    rt.teach_backgrounds.put(top, frame.rgb)


async def grab_belt_background(
    rt: CellRuntime, *, speed: float | None = None, frames: int = 14, jog_m_s: float = 0.5
) -> Any:
    """Grab the empty-belt background of the top view at the station registered to the
    belt's travel (:class:`vision.segmentation.belt.BeltBackground`), for constant belt speed
    and for a belt that moved since the still background was grabbed.

    The station and the belt upstream must be empty.  The arm looks from the top view; the
    belt is jogged round its whole loop in ``frames`` steps (at ``jog_m_s``), one still frame
    after each, then left as it was.  Needs a conveyor the cell can jog and read and a belt
    in the cell's layout (a :class:`~vision.errors.Conflict` otherwise).  Kept on the
    runtime (``rt.inspection.belt_background``) until the next grab.
    """
    from vision.segmentation.belt import BeltGeometry, build_belt_background

    conveyor, belt = _jog_check(rt)
    if isinstance(frames, bool) or not isinstance(frames, int) or not 5 <= frames <= 64:
        raise InvalidInput(f"frames must be an integer in 5..64, got {frames!r}")
    if not (isinstance(jog_m_s, int | float) and 0.01 <= jog_m_s <= 2.0):
        raise InvalidInput(f"jog_m_s must be in [0.01, 2] m/s, got {jog_m_s!r}")
    ctx, top = await _station_top(rt)
    before = conveyor.status()
    shots: list[tuple[NDArray[np.uint8], float]] = []
    frame = await rt.cell.look(top.q, speed=speed)
    step = belt.length_m / frames
    try:
        await conveyor.stop()
        for _ in range(frames):
            frame = await rt.cell.look(None)
            shots.append((frame.rgb, travel_of(frame, rt)))
            start = conveyor.travel_at()
            await conveyor.start(mode="continuous", speed_m_s=float(jog_m_s))
            deadline = time.monotonic() + 60.0  # only a belt that does not move at all
            while conveyor.travel_at() - start < step:
                if time.monotonic() > deadline:
                    raise Conflict("the belt did not move while grabbing its background")
                await asyncio.sleep(0.005)
            await conveyor.stop()
    finally:  # left as it was: its mode and speed, running or not
        await conveyor.stop()
        await conveyor.set_mode(before.mode, speed_m_s=before.speed_m_s)
        if before.running:
            await conveyor.start()
    station = rt.layout.station_point
    geo = BeltGeometry(
        float(station[0]), belt.start_y_m, belt.width_m, float(station[2]), belt.length_m
    )
    bb = await asyncio.to_thread(build_belt_background, shots, camera=ctx.camera,
                                 T_base_cam=cam_pose(frame.robot_state.q, ctx.T_ee_cam), geometry=geo)  # fmt: skip
    rt.inspection.belt_background = bb
    return bb


def _jog_check(rt: CellRuntime) -> tuple[Conveyor, BeltSpan]:
    """The conveyor and the belt a belt background jogs, or :class:`Conflict` saying why not."""
    conveyor, belt = rt.conveyor, rt.layout.belt
    if not conveyor.controllable:
        raise Conflict(f"a belt background needs a conveyor the cell can jog: this cell's is "
                       f"a {conveyor.name}")  # fmt: skip
    if belt is None:
        raise Conflict(f"a belt background needs a belt in the cell's layout ({rt.layout.source})")
    return conveyor, belt


def start_belt_background(rt: CellRuntime) -> Any:
    """Start a job grabbing the belt background (:func:`grab_belt_background`); 409 at once
    when the arm is busy or e-stopped, or the cell has no conveyor it can jog."""
    _jog_check(rt)
    rt.cell.check_can_move()
    rt.jobs.check_arm_free()

    async def body(job: Any) -> dict[str, Any]:
        job.report(0.1, "jogging the empty belt round its loop")
        bb = await grab_belt_background(rt)
        return {"frames": bb.frames, "loop_m": bb.geometry.loop_m}

    return rt.jobs.start("belt-background", body, motion=True, params={})
