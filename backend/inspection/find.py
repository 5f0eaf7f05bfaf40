"""The find stage: the top-view frame of a part at the station.

Index mode: frames until a part lies still (the region nearest the station, whole along
the belt, stable between two frames; in a run, not the part inspected last:
:mod:`backend.inspection.waiting`).  Constant speed (chapter 4.1): of the frames where the
moving object's region lies whole along the belt, the one nearest the station
(:class:`Approach`) is the top view.  Waiting for a part is no inspection: nothing is
stored until one is found.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from backend.inspection.context import Context, belt_state, cam_pose, station_px, travel_of
from backend.inspection.errors import NoObject
from backend.inspection.options import InspectOptions
from backend.inspection.stopwatch import Stopwatch
from backend.inspection.waiting import belt_status, waiting_message
from backend.planning import AIM_HEIGHT_M
from backend.recognition.segment import SegmentationFailed, foreground_mask
from vision.errors import InvalidInput
from vision.pose import plane_points
from vision.segmentation import iou

if TYPE_CHECKING:
    from backend.runtime import CellRuntime

__all__ = ["BORDER_PX", "Approach", "Found", "Waiting", "add_look", "along_belt",
           "background_for", "find_part", "look_whole"]  # fmt: skip

#: The cell's own timings of one look (``frame.meta["look"]``), as stage names.
LOOK_STAGES = ("move", "settle", "acquire")


def look_times(frame: Any) -> dict[str, float]:
    """How long the look that took ``frame`` moved, settled and acquired (the cell's own
    timings), seconds."""
    lk = frame.meta.get("look", {})
    return {k: float(lk.get(f"{k}_s", 0.0)) for k in LOOK_STAGES}


def add_look(watch: Stopwatch, frame: Any) -> None:
    """Count the look that took ``frame`` in the stages ``move``, ``settle``, ``acquire``."""
    for k, v in look_times(frame).items():
        watch.add(k, v)


def background_for(ctx: Context, frame: Any, bg: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """The empty-belt background for ``frame``: the belt background registered to the
    belt's travel at its exposure (:mod:`vision.segmentation.belt`) when one was grabbed
    from this camera pose and no still background was grabbed after it, else the still
    background ``bg`` (right while the belt stands where it stood when ``bg`` was grabbed).

    A still background grabbed later makes the belt background stale: it is grabbed when
    the lights changed (:func:`grab_background`), and the belt background still holds the
    old light.  Preferring it whatever its age segmented the objects under half light and
    a colour cast against the belt of the normal light, after a constant-speed run had
    grabbed a belt background.
    """
    bb = ctx.rt.inspection.belt_background
    if bb is None or frame.robot_state is None:
        return bg
    store = ctx.rt.teach_backgrounds
    if store.taken_at > bb.taken_at:
        return bg
    if not bb.matches(cam_pose(frame.robot_state.q, ctx.T_ee_cam)):
        return bg
    return bb.at(travel_of(frame, ctx.rt))


#: How close to the image border (pixels) a region may come and still count as whole.
BORDER_PX = 3


def along_belt(mask: NDArray[np.bool_], camera: Any, T_base_cam: NDArray[np.float64],
               station: NDArray[np.float64], z_m: float) -> tuple[bool, float]:  # fmt: skip
    """Where a region seen from ``T_base_cam`` lies along the belt: whether it is whole
    *along* the belt, and its centre's offset along the belt's travel (base ``+y``, metres)
    from the station, on the plane ``z_m``.

    Whole along the belt means touching no image border the belt runs across (the ones
    whose normal is within 60 degrees of the belt's direction in the image).  A border
    along the belt does not count: how far the object reaches across the belt does not
    change as the belt moves, and the top view taught at the station frames it the same
    way (a wheel cut by the image's lower edge is cut there at every travel, and was cut
    there when it was taught), so waiting for it to become whole there never ends.
    """
    h, w = mask.shape
    ys, xs = np.nonzero(mask)
    if xs.size == 0:
        raise InvalidInput("along_belt needs a region with at least one pixel")
    T_cam_base = np.linalg.inv(np.asarray(T_base_cam, dtype=np.float64))
    a, b = station.copy(), station.copy()
    a[2] = b[2] = z_m
    b[1] += 0.05
    uv = camera.project_world(np.stack([a, b]), T_cam_base)
    e = uv[1] - uv[0]
    n = float(np.hypot(*e))
    e = e / n if math.isfinite(n) and n > 1e-9 else np.array([1.0, 0.0])
    touches = {  # border normal -> region touches that border
        (-1.0, 0.0): xs.min() < BORDER_PX,
        (1.0, 0.0): xs.max() >= w - BORDER_PX,
        (0.0, -1.0): ys.min() < BORDER_PX,
        (0.0, 1.0): ys.max() >= h - BORDER_PX,
    }
    whole = not any(t and abs(nx * e[0] + ny * e[1]) > 0.5 for (nx, ny), t in touches.items())
    centre = plane_points(np.array([[xs.mean(), ys.mean()]]), camera, T_base_cam, z_m)[0]
    return whole, float(centre[1] - station[1])


@dataclass
class Approach:
    """Which frame of an object carried along the moving belt is its top view (chapter 4.1).

    The camera delivers frames at its own rate, so consecutive frames see the object a
    belt travel ``step`` apart (at time scale 20 in the simulator, 5-20 cm); no fixed window
    round the station is sure to hold one of them.  The top view is the frame nearest the
    station among those where the object is whole along the belt: a frame is taken when the
    next one (predicted one ``step`` -- the travel between the last two frames -- further)
    would be farther from the station; otherwise it is held, and given back when the next
    frame turns out farther (or no longer whole).  Only an object that was upstream of the
    station when the search began (travel ``start_m``) counts: one that passed the station
    while the arm came to the top view is taken at once, wherever it is as long as it is
    whole, but one inspected before and leaving is not taken again.
    """

    start_m: float
    seen_upstream: bool = False
    last_travel: float | None = None
    step: float | None = None
    held: tuple[Any, float] | None = None

    def take(self, frame: Any, region: tuple[bool, float] | None, travel_m: float) -> Any:
        """The top view, or None to look at the next frame: ``frame`` itself or the one
        held before it.  ``region`` is :func:`along_belt` of the frame's object (None: no
        object), ``travel_m`` the belt's travel at its exposure."""
        if self.last_travel is not None and travel_m > self.last_travel:
            self.step = travel_m - self.last_travel
        self.last_travel = travel_m
        held, self.held = self.held, None
        if region is not None and region[1] - (travel_m - self.start_m) < 0.0:
            self.seen_upstream = True  # upstream of the station when the search began
        if region is None or not (region[0] and self.seen_upstream):
            return None if held is None else held[0]
        offset = region[1]
        if held is not None and abs(held[1]) <= abs(offset):
            return held[0]
        if offset >= 0.0 or (self.step is not None and abs(offset + self.step) >= abs(offset)):
            return frame
        self.held = (frame, offset)
        return None


async def next_frame(cell: Any, prev: Any) -> Any:
    """The camera's next frame after ``prev`` without moving or settling (the arm stays at
    the top view): the newest frame exposed after ``prev`` -- not one exposed after now, as
    ``look`` waits for, which would skip the frame already delivered while ``prev`` was
    processed and double the belt's travel between the frames examined."""
    f = await cell.next_frame(after=prev.stamp_s)
    state = f.robot_state if f.robot_state is not None else prev.robot_state
    return dataclasses.replace(f, robot_state=state, meta={**f.meta, "look": {}})


@dataclass(frozen=True, eq=False)
class Found:
    """A part at the station: its top-view frame, the belt's travel at its exposure, the
    background it was found against, its belt coordinate (:mod:`backend.inspection.waiting`;
    NaN when not measured), when its inspection began (on the stopwatch's clock: the start of
    the search, or the moment the part came when the search had to wait for it) and its
    region in the frame as found."""

    frame: Any
    travel_m: float
    bg: NDArray[np.uint8] | None
    u_m: float
    t_start: float
    mask: NDArray[np.bool_] | None = None


@dataclass(frozen=True)
class Waiting:
    """How a search waits for a part: ``report(message)`` says what it waits for (the job's
    progress); ``stopped()`` true ends the wait without a part (a run asked to stop);
    ``forever`` waits until then (a run), else ``wait_s`` of the options bounds it."""

    report: Any = None
    stopped: Any = None
    forever: bool = False


def indexing(rt: CellRuntime) -> bool:
    """Whether an indexing belt is carrying its parts to the station now (it runs and holds
    none there): two alike frames then mean only that the camera saw the belt at one
    instant twice, not a part at rest."""
    st = belt_status(rt)
    return st is not None and st.mode == "index" and st.running and not st.holding


def belt_coordinate(ctx: Context, mask: NDArray[np.bool_], T_cam: NDArray[np.float64],
                     z_m: float, travel_m: float) -> float:  # fmt: skip
    """Where the region's centre rides on the belt: its offset along the travel (base
    ``+y``) less the belt's travel at the exposure, metres (fixed to the belt)."""
    ys, xs = np.nonzero(mask)
    centre = plane_points(np.array([[xs.mean(), ys.mean()]]), ctx.camera, T_cam, z_m)[0]
    return float(centre[1] - travel_m)


async def find_part(ctx: Context, opts: InspectOptions, q_top: NDArray[np.float64],
                    bg: NDArray[np.uint8], watch: Stopwatch, *, tracker: Any = None,
                    waiting: Waiting | None = None,
                    clock: Callable[[], float] = time.monotonic) -> Found | None:  # fmt: skip
    """The top-view frame of a part at the station (:class:`Found`), or None when
    ``waiting.stopped()`` ended the wait.

    Index mode: a region nearest the station that stays still between two frames, and --
    with a ``tracker`` (:class:`~backend.inspection.waiting.PartTracker`, a run) -- is not
    the part inspected last by its belt coordinate.  Constant speed: :class:`Approach`.
    While nothing is there, the wait is reported and never counted as an inspection: the
    stage times of a search that had to wait start when the part came (on ``watch``'s
    clock, as :attr:`Found.t_start`).  :class:`NoObject`
    when ``opts.wait_s`` passes first (unless ``waiting.forever``), measured on
    ``clock`` (seconds)."""
    w = waiting or Waiting()
    with watch.stage("wait"):
        found = await _search(ctx, opts, q_top, bg, watch, tracker, w, clock)
    return found


async def _search(ctx: Context, opts: InspectOptions, q_top: NDArray[np.float64],
                  bg: NDArray[np.uint8], watch: Stopwatch, tracker: Any, w: Waiting,
                  clock: Callable[[], float]) -> Found | None:  # fmt: skip
    """:func:`find_part`'s search, timed as the stage ``wait`` by the caller."""
    cell = ctx.rt.cell
    now = watch.clock
    deadline = None if w.forever else clock() + opts.wait_s
    last = None
    last_t = 0.0
    approach = Approach(start_m=belt_state(ctx.rt)[2])
    z_mid = ctx.surface_z + AIM_HEIGHT_M / 2
    t0 = now()
    with watch.pause():  # the cell times the look itself
        frame = await cell.look(q_top, speed=opts.speed)
    looks = look_times(frame)
    T_cam = cam_pose(frame.robot_state.q, ctx.T_ee_cam)
    near = station_px(ctx, T_cam, z_mid)
    waited, said, first_seen = False, "", None
    u = math.nan
    while True:
        if w.stopped is not None and w.stopped():
            return None
        mode, _, _ = belt_state(ctx.rt)
        bg_now = background_for(ctx, frame, bg)
        try:  # index mode: the part nearest the station, not a larger neighbour in view
            mask = await asyncio.to_thread(foreground_mask, frame.rgb, bg_now,
                                           near_px=None if mode == "continuous" else near)  # fmt: skip
        except SegmentationFailed:
            mask = None
        idle = mask is None  # nothing there: waiting (else a part comes, or is there)
        same = False
        if mode == "continuous":
            region = None
            if mask is not None:
                T_now = cam_pose(frame.robot_state.q, ctx.T_ee_cam)
                region = along_belt(mask, ctx.camera, T_now, ctx.station, z_mid)
                first_seen = first_seen if first_seen is not None else now()
            chosen = approach.take(frame, region, travel_of(frame, ctx.rt))
            if chosen is not None:
                frame = chosen
                bg_now = background_for(ctx, frame, bg)
                start = first_seen if waited and first_seen is not None else t0
                break
        elif mask is None:
            if tracker is not None:
                tracker.station_empty()
        elif last is not None and iou(mask, last) > 0.97 and not indexing(ctx.rt):
            travel = travel_of(frame, ctx.rt)
            u = belt_coordinate(ctx, mask, T_cam, z_mid, travel)
            # a neighbour cut by the image's edge along the belt is not at the station
            whole = along_belt(mask, ctx.camera, T_cam, ctx.station, z_mid)[0]
            if whole and (tracker is None or tracker.is_new(u, mask)):
                start = last_t if waited else t0
                break
            idle, same = True, whole  # only a neighbour, or the part inspected last
        if mask is not None and (last is None or iou(mask, last) <= 0.97):
            last_t = now()  # a part came, or moved: its still frames start here
        last = mask
        if idle:
            waited = True
            msg = waiting_message(belt_status(ctx.rt), same_part=same)
            if msg != said and w.report is not None:
                w.report(msg)
            said = msg
        if deadline is not None and clock() >= deadline:
            raise NoObject(f"no object came to the station within {opts.wait_s:g} s")
        if mode == "continuous":
            frame = await next_frame(cell, frame)
        else:
            await asyncio.sleep(0.2)
            frame = await cell.look(None)
    if start == t0:  # the part was there at once: the move to the top view is its own
        for k, v in looks.items():
            watch.add(k, v)
    else:  # the arm waited at the top view: no move of this part's own, and the wait
        for k in looks:  # counts from the moment the part came
            watch.add(k, 0.0)
        watch.restart(start)
    travel = travel_of(frame, ctx.rt)
    if mode == "continuous":
        u = math.nan
    return Found(frame, travel, bg_now, u, start, mask)


async def look_whole(ctx: Context, opts: InspectOptions, q_top: NDArray[np.float64],
                     watch: Stopwatch) -> Found:  # fmt: skip
    """The top view of a cell with no empty-belt background: the next frame at the station
    (a recorded cell's next image), to be recognised whole."""
    t0 = watch.clock()
    frame = await ctx.rt.cell.look(q_top, speed=opts.speed)
    add_look(watch, frame)
    return Found(frame, travel_of(frame, ctx.rt), None, math.nan, t0, None)
