"""Inspecting objects at the station: one object, or continuous operation.

One inspection (:func:`inspect_object`):

1. **find**: the top view (viewpoint 1) at the station, planned by
   :func:`backend.recognition.teach.plan_shots` as teaching plans it, so the empty-belt
   background grabbed by a teach applies.  Index mode: frames until a part lies still
   (the region nearest the station, whole along the belt, stable between two frames; in a
   run, not the part inspected last: :mod:`backend.inspection.waiting`).  Constant speed
   (chapter 4.1): of the frames where the moving object's region lies whole along the
   belt, the one nearest the station (:class:`Approach`) is the top view.  Waiting for a
   part is no inspection: nothing is stored until one is found;
2. **segment**: the active contour initialised from the background difference, as teaching
   does (:func:`backend.recognition.segment.segment_object`);
3. **recognise**: :func:`vision.recognition.recognise_views` with the live index and the
   thresholds in force; its ``look`` returns the top view for viewpoint 1 and moves the arm
   to side viewpoints 2 / 3 planned (:func:`robot.viewpoints.plan_viewpoints`)
   from where the top view found the object (predicted along the belt when it moves);
4. **decide**: ``recognized`` (a model), ``unknown`` (no model passes, or models too alike:
   ambiguous) or ``failed`` (segmentation, a move, e-stop, stop), with the reason;
5. **pose** (:mod:`vision.pose`) from the trained top views that verify on the
   top view; when it rests on too little (:func:`rests_on_too_little`) a second top view,
   turned about the camera's axis, gives it, or the object has no pose
   (:func:`_second_top_view`);
6. **pick** (``sort`` on): the part's bin, or only the approach pose (``sort`` off);
7. **store** one row (:mod:`backend.inspection.results`) and publish an
   :class:`InspectionDone` event.

Durations per stage (seconds of wall time): ``wait`` (for the part to lie still), ``move``,
``settle``, ``acquire``, ``segment``, ``features``+``match`` (recognition, per its timings),
``decide``, ``pose``, ``pick``.  The row's ``duration_s`` is the inspection's wall time, from
its start (the search's, or the moment its part came after a wait) to its end.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import functools
import logging
import math
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from datetime import timedelta
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import NDArray
from sqlalchemy import select

from backend.cell.events import CellEvent
from backend.db.models import TrainedView, utcnow
from backend.inspection import recovery, results
from backend.inspection.waiting import PartTracker, belt_status, conveyor_of, waiting_message
from backend.recognition import thresholds
from backend.recognition.images import encode_jpeg
from backend.recognition.segment import SegmentationFailed, foreground_mask, segment_object
from backend.planning import plan_shots
from backend.reports.scenes import SceneRecorder
from robot.errors import Unreachable
from robot.kinematics import T_base_ee
from robot.viewpoints import VIEW_NAMES, plan_viewpoints
from vision.errors import Conflict, InvalidInput, NothingTrained, VisionCellError
from vision.pose import (
    ObjectPose,
    PoseFailed,
    SilhouetteView,
    ViewMatch,
    estimate_pose_views,
    plane_points,
    pose_apart,
    predict_along_belt,
    rests_on_too_little,
)
from vision.pose.structure import FeatureHeights, HeightCache, TaughtTopView
from vision.recognition import POLICIES, recognise_views
from vision.recognition.light import apply_gain, light_gain, surround_colour
from vision.recognition.recognise import verify_view
from vision.segmentation import iou
from vision.segmentation.roi import SideRoi, height_bound, side_query, side_roi

if TYPE_CHECKING:
    from backend.runtime import CellRuntime
    from robot.cellworld import BeltSpan, Bin
    from robot.drivers.conveyor import Conveyor

__all__ = ["InspectOptions", "InspectionDone", "InspectionRun", "hold_until_ready", "inspect_object", "readiness", "start_inspection", "start_run"]  # fmt: skip

log = logging.getLogger(__name__)

#: Longest wait for an object at the station, seconds; most objects in one run.
MAX_WAIT_S = 600.0
MAX_COUNT = 10_000
#: Most models one set of options (a recipe) may name.
MAX_RECIPE_MODELS = 200
#: Belt modes a recipe may set (:data:`robot.sim.world.CONVEYOR_MODES`).
BELT_MODES = ("index", "continuous")
#: Why an inspection cannot start before a teach (the console links its Models page on the
#: error's code, ``nothing_trained``).
NOT_TRAINED = (
    "no trained views: teach a model first (the console's Models page, "
    "`visioncell models teach NAME` or POST /api/models/{id}/teach)"
)
#: Aiming height of the viewpoints (as teaching's default), metres.
AIM_HEIGHT_M = 0.1


@dataclass(frozen=True)
class InspectionDone(CellEvent):
    """An inspection ended (WebSocket ``{"type": "inspection", ...}``)."""

    inspection_id: int
    decision: str
    model: str | None
    reason: str
    score: float | None
    viewpoints: tuple[int, ...]
    T_base_obj: tuple[tuple[float, ...], ...] | None
    T_base_cams: tuple[tuple[tuple[float, ...], ...], ...]
    pick: dict[str, Any] | None = None
    #: The recipe the inspection ran under (id, name; None: none).
    recipe_id: int | None = None
    recipe: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "id": self.inspection_id,
            "decision": self.decision,
            "model": self.model,
            "reason": self.reason,
            "score": self.score,
            "viewpoints": list(self.viewpoints),
            "T_base_obj": None if self.T_base_obj is None else [list(r) for r in self.T_base_obj],
            "T_base_cams": [[list(r) for r in T] for T in self.T_base_cams],
            "pick": self.pick,
            "recipe_id": self.recipe_id,
            "recipe": self.recipe,
        }


@dataclass(frozen=True)
class InspectOptions:
    """How to inspect.

    Attributes
    ----------
    policy : {"naive", "top-only", "two-views", "best-next"}
    sort : bool
        Pick and sort into the part's bin (reject bin for unknown / failed); else move to
        the object's approach pose only.
    max_views : int
        1..3.
    wait_s : float
        Longest wait for a part at the station, seconds, of one inspection (a run waits
        until a part comes or it is stopped).
    speed : float, optional
        Arm speed fraction (default: the cell's).
    balance_light : bool
        Scale the views' channels back to the light the models were taught under, by the
        belt's colour round the object (:mod:`vision.recognition.light`); off only to
        measure what it does.
    models : tuple of str
        The models in play (empty: every trained model): an object recognised as another
        model is ``unknown`` (and goes to the reject bin when sorting).
    bins : tuple of (model, bin) pairs
        The bin each named model is sorted into, instead of its part's bin.
    threshold : float, optional
        A fixed global score threshold in [0, 1] (None: the cell's thresholds in force,
        automatic or as set).
    belt_mode : {"index", "continuous"}, optional
        The belt's mode to set before the object comes (None: the belt as it is); needs a
        conveyor the cell can configure (the simulator's).
    recipe_id, recipe_name : optional
        The recipe these options came from (:mod:`backend.recipes`), stored on the row.
    """

    policy: str = "two-views"
    sort: bool = False
    max_views: int = 3
    wait_s: float = 60.0
    speed: float | None = None
    balance_light: bool = True
    models: tuple[str, ...] = ()
    bins: tuple[tuple[str, str], ...] = ()
    threshold: float | None = None
    belt_mode: str | None = None
    recipe_id: int | None = None
    recipe_name: str | None = None

    def __post_init__(self) -> None:
        if self.policy not in POLICIES:
            raise InvalidInput(f"policy must be one of {', '.join(POLICIES)}, got {self.policy!r}")
        if not isinstance(self.sort, bool):
            raise InvalidInput(f"sort must be true or false, got {self.sort!r}")
        if not isinstance(self.balance_light, bool):
            raise InvalidInput(f"balance_light must be true or false, got {self.balance_light!r}")
        mv = self.max_views
        if isinstance(mv, bool) or not isinstance(mv, int) or not 1 <= mv <= 3:
            raise InvalidInput(f"max_views must be an integer in 1..3, got {mv!r}")
        w = self.wait_s
        if isinstance(w, bool) or not (math.isfinite(w) and 0.0 <= w <= MAX_WAIT_S):
            raise InvalidInput(f"wait_s must be in [0, {MAX_WAIT_S:g}] s, got {w!r}")
        sp = self.speed
        if sp is not None and (isinstance(sp, bool) or not (math.isfinite(sp) and 0.0 < sp <= 1.0)):
            raise InvalidInput(f"speed must be in (0, 1], got {sp!r}")
        if (
            not isinstance(self.models, tuple)
            or not all(isinstance(m, str) and 1 <= len(m) <= 64 for m in self.models)
            or len(self.models) > MAX_RECIPE_MODELS
        ):
            raise InvalidInput(f"models must be a tuple of at most {MAX_RECIPE_MODELS} names, "
                               f"got {self.models!r}"[:300])  # fmt: skip
        if not isinstance(self.bins, tuple) or len(self.bins) > MAX_RECIPE_MODELS or not all(
            isinstance(p, tuple) and len(p) == 2 and all(isinstance(x, str) and 1 <= len(x) <= 64
                                                         for x in p) for p in self.bins
        ):  # fmt: skip
            raise InvalidInput(f"bins must be (model, bin) name pairs, got {self.bins!r}"[:300])
        t = self.threshold
        if t is not None and (
            isinstance(t, bool) or not isinstance(t, int | float) or not 0.0 <= t <= 1.0
        ):
            raise InvalidInput(f"threshold must be in [0, 1] or null (automatic), got {t!r}")
        if self.belt_mode not in (None, *BELT_MODES):
            raise InvalidInput(
                f"belt_mode must be one of {', '.join(BELT_MODES)} or null, got {self.belt_mode!r}"
            )

    def bin_of(self, model: str | None) -> str | None:
        """The bin these options send ``model`` to (None: its part's bin)."""
        return next((b for m, b in self.bins if m == model), None) if model else None


#: Where a run reads its options again before each object (the active recipe's, with the
#: request's explicit options over them: :func:`backend.recipes.service.follower`).
Resolve = Callable[[], Awaitable[InspectOptions]]


async def resolved(resolve: Resolve | None, opts: InspectOptions) -> InspectOptions:
    """The options ``resolve`` gives now; ``opts`` (those in force) when there is no
    ``resolve`` or it fails (a database outage, the recipe deleted): the object is
    inspected as the one before, said in the log."""
    if resolve is None:
        return opts
    try:
        return await resolve()
    except Exception:  # the run goes on with the options it has
        log.warning("could not read the recipe again: keeping the options in force", exc_info=True)
        return opts


def check_belt_mode(rt: CellRuntime, opts: InspectOptions) -> None:
    """:class:`Conflict` when the options set a belt mode and the cell's conveyor cannot
    be configured (a fixed station)."""
    if opts.belt_mode is not None and not rt.conveyor.controllable:
        raise Conflict(
            f"{'recipe ' + repr(opts.recipe_name) if opts.recipe_name else 'the options'} sets"
            f" the belt to {opts.belt_mode} mode, and this cell's conveyor cannot be configured"
        )


async def apply_belt_mode(rt: CellRuntime, opts: InspectOptions) -> None:
    """Set the belt to the options' mode (nothing when they set none or it is so already)."""
    check_belt_mode(rt, opts)
    st = rt.conveyor.status()
    if opts.belt_mode is not None and st.mode != opts.belt_mode:
        await rt.conveyor.set_mode(opts.belt_mode, speed_m_s=st.speed_m_s)


class CarriedAway(VisionCellError):
    """Constant speed: the belt carried the object past its end before a side view."""

    code = "carried_away"


def carried_point(found: NDArray[np.float64], ahead_m: float, end_y_m: float,
                  vp: int) -> NDArray[np.float64]:  # fmt: skip
    """Where a side view (viewpoint ``vp``) looks for an object found at ``found`` in the
    top view, carried ``ahead_m`` along the belt since (its travel since the top view's
    exposure and during the move); :class:`CarriedAway` past the belt's end (``end_y_m``):
    the object has left the belt there (the simulator's belt brings it round to its start),
    so no view of it can be planned from the travel, and a point metres beyond the arm's
    reach would only fail the viewpoint planner with a workspace error."""
    point = np.asarray(found, dtype=np.float64) + np.array([0.0, float(ahead_m), 0.0])
    if not math.isfinite(float(ahead_m)) or point[1] > end_y_m:
        raise CarriedAway(
            f"viewpoint {vp}: the belt carried the object {float(ahead_m):.2f} m on since the "
            f"top view, past the belt's end (y {end_y_m:g} m): the views took too long"
        )
    return point


class NotReady(NothingTrained):
    """A setup step is missing (nothing trained, no empty-belt background of the top view):
    no inspection can start; a run ends with the reason."""


class NoObject(VisionCellError):
    """No object came to the station in time."""

    code = "no_object"


@dataclass
class _Ctx:
    """What one inspection needs from the runtime (built by :func:`context`)."""

    rt: CellRuntime
    camera: Any
    T_ee_cam: NDArray[np.float64]
    source: str
    station: NDArray[np.float64]
    surface_z: float
    #: Why a pose (and so a pick) cannot be trusted here: empty when the camera model and
    #: its mounting are calibrated (or are the simulator's own, exact by construction).
    uncalibrated: str = ""
    #: Where parts leave the belt (base y, metres; infinite: no belt).
    belt_end_y_m: float = math.inf


async def context(rt: CellRuntime) -> _Ctx:
    """Camera model and mounting: the cell's active calibrations, else the camera's exact
    nominal ones (the simulator's), else the drawing's (reported in ``source``); the
    station, its surface and the belt's end from the cell's layout."""
    from backend.calibration import NOMINAL_T_EE_CAM, active_camera_calibration, nominal_camera

    async with rt.database.session() as session:
        cal = await active_camera_calibration(session, rt.cell_id)
    camera, T = cal.camera, cal.T_ee_cam
    src = []
    nominal = rt.nominal_camera
    if camera is None:
        if nominal is not None:
            camera, s = nominal.camera, f"{nominal.label} intrinsics"
        else:
            frame = rt.cell.latest_frame
            w, h = (640, 480) if frame is None else (frame.width, frame.height)
            camera, s = nominal_camera(w, h), "nominal intrinsics (uncalibrated)"
        src.append(s)
    else:
        src.append("active intrinsics")
    if T is None:
        if nominal is not None:
            T, s = np.asarray(nominal.T_ee_cam), f"{nominal.label} mounting"
        else:
            T, s = np.asarray(NOMINAL_T_EE_CAM), "drawing's mounting (uncalibrated)"
        src.append(s)
    else:
        src.append("active hand-eye")
    layout = rt.layout
    end = layout.belt_end_y_m
    missing = [s for s in src if "uncalibrated" in s]
    why = ("needs an active camera calibration (intrinsics and hand-eye): this cell uses the "
           + " and the ".join(missing)) if missing else ""  # fmt: skip
    return _Ctx(rt, camera, np.asarray(T, dtype=np.float64), ", ".join(src),
                layout.station_point, float(layout.surface_z_m), why,
                math.inf if end is None else float(end))  # fmt: skip


def _belt(rt: CellRuntime) -> tuple[str, float, float]:
    """(mode, speed m/s, travel m) of the cell's conveyor: ``continuous`` only while it runs
    at a speed (its encoder gives the travel); a fixed station is ``index`` at 0 m."""
    st = rt.conveyor.status()
    moving = st.running and st.mode == "continuous" and st.speed_m_s > 0
    return ("continuous" if moving else "index"), float(st.speed_m_s), float(st.travel_m)


def _truth_near(rt: CellRuntime, point: NDArray[np.float64],
                back_m: float = 0.0) -> dict[str, Any] | None:  # fmt: skip
    """For evaluation only, where the cell knows it (the simulator): the object nearest
    ``point`` (never read by decisions), moved back ``back_m`` along the belt (its travel
    since the exposure)."""
    truth = rt.truth
    return None if truth is None else truth.object_near(point, back_m)


def _draw(rgb: NDArray[np.uint8], mask: NDArray[np.bool_] | None, label: str) -> bytes:
    img = rgb.copy()
    if mask is not None and mask.any():
        cs, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(img, cs, -1, (0, 255, 0), 2)
    cv2.putText(img, label, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 0), 2)
    return encode_jpeg(img)


def _add(d: dict[str, float], key: str, v: float) -> None:
    d[key] = round(d.get(key, 0.0) + float(v), 4)


def _look_times(frame: Any, durations: dict[str, float]) -> None:
    lk = frame.meta.get("look", {})
    for k in ("move", "settle", "acquire"):
        _add(durations, k, lk.get(f"{k}_s", 0.0))


def _travel_of(frame: Any, rt: CellRuntime) -> float:
    """The belt's travel at the frame's exposure: the encoder count latched with it
    (``meta["belt_travel_m"]``), else the conveyor's encoder at its exposure time."""
    t = frame.meta.get("belt_travel_m")
    if isinstance(t, int | float) and math.isfinite(t):
        return float(t)
    stamp = getattr(frame, "stamp_s", None)
    return float(rt.conveyor.travel_at(stamp if isinstance(stamp, float) else None))


def _background_for(ctx: _Ctx, frame: Any, bg: NDArray[np.uint8]) -> NDArray[np.uint8]:
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
    if not bb.matches(_T_cam(frame.robot_state.q, ctx.T_ee_cam)):
        return bg
    return bb.at(_travel_of(frame, ctx.rt))


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


async def _next_frame(cell: Any, prev: Any) -> Any:
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
    NaN when not measured), when its inspection began (``time.monotonic()``: the start of
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


def _indexing(rt: CellRuntime) -> bool:
    """Whether an indexing belt is carrying its parts to the station now (it runs and holds
    none there): two alike frames then mean only that the camera saw the belt at one
    instant twice, not a part at rest."""
    st = belt_status(rt)
    return st is not None and st.mode == "index" and st.running and not st.holding


def _station_px(ctx: _Ctx, T_cam: NDArray[np.float64], z_m: float) -> NDArray[np.float64]:
    p = ctx.station.copy()
    p[2] = z_m
    return ctx.camera.project_world(p[None, :], np.linalg.inv(T_cam))[0]


def _belt_coordinate(ctx: _Ctx, mask: NDArray[np.bool_], T_cam: NDArray[np.float64],
                     z_m: float, travel_m: float) -> float:  # fmt: skip
    """Where the region's centre rides on the belt: its offset along the travel (base
    ``+y``) less the belt's travel at the exposure, metres (fixed to the belt)."""
    ys, xs = np.nonzero(mask)
    centre = plane_points(np.array([[xs.mean(), ys.mean()]]), ctx.camera, T_cam, z_m)[0]
    return float(centre[1] - travel_m)


async def _find(ctx: _Ctx, opts: InspectOptions, q_top: NDArray[np.float64], bg: NDArray[np.uint8],
                durations: dict[str, float], *, tracker: Any = None,
                waiting: Waiting | None = None,
                clock: Callable[[], float] = time.monotonic) -> Found | None:  # fmt: skip
    """The top-view frame of a part at the station (:class:`Found`), or None when
    ``waiting.stopped()`` ended the wait.

    Index mode: a region nearest the station that stays still between two frames, and --
    with a ``tracker`` (:class:`~backend.inspection.waiting.PartTracker`, a run) -- is not
    the part inspected last by its belt coordinate.  Constant speed: :class:`Approach`.
    While nothing is there, the wait is reported and never counted as an inspection: the
    stage times of a search that had to wait start when the part came.  :class:`NoObject`
    when ``opts.wait_s`` passes first (unless ``waiting.forever``), measured on
    ``clock`` (seconds)."""
    w = waiting or Waiting()
    cell = ctx.rt.cell
    deadline = None if w.forever else clock() + opts.wait_s
    last = None
    last_t = 0.0
    approach = Approach(start_m=_belt(ctx.rt)[2])
    z_mid = ctx.surface_z + AIM_HEIGHT_M / 2
    t0 = time.monotonic()
    frame = await cell.look(q_top, speed=opts.speed)
    looks: dict[str, float] = {}
    _look_times(frame, looks)
    T_cam = _T_cam(frame.robot_state.q, ctx.T_ee_cam)
    near = _station_px(ctx, T_cam, z_mid)
    waited, said, first_seen = False, "", None
    u = math.nan
    while True:
        if w.stopped is not None and w.stopped():
            return None
        mode, _, _ = _belt(ctx.rt)
        bg_now = _background_for(ctx, frame, bg)
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
                T_now = _T_cam(frame.robot_state.q, ctx.T_ee_cam)
                region = along_belt(mask, ctx.camera, T_now, ctx.station, z_mid)
                first_seen = first_seen if first_seen is not None else time.monotonic()
            chosen = approach.take(frame, region, _travel_of(frame, ctx.rt))
            if chosen is not None:
                frame = chosen
                bg_now = _background_for(ctx, frame, bg)
                start = first_seen if waited and first_seen is not None else t0
                break
        elif mask is None:
            if tracker is not None:
                tracker.station_empty()
        elif last is not None and iou(mask, last) > 0.97 and not _indexing(ctx.rt):
            travel = _travel_of(frame, ctx.rt)
            u = _belt_coordinate(ctx, mask, T_cam, z_mid, travel)
            # a neighbour cut by the image's edge along the belt is not at the station
            whole = along_belt(mask, ctx.camera, T_cam, ctx.station, z_mid)[0]
            if whole and (tracker is None or tracker.is_new(u, mask)):
                start = last_t if waited else t0
                break
            idle, same = True, whole  # only a neighbour, or the part inspected last
        if mask is not None and (last is None or iou(mask, last) <= 0.97):
            last_t = time.monotonic()  # a part came, or moved: its still frames start here
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
            frame = await _next_frame(cell, frame)
        else:
            await asyncio.sleep(0.2)
            frame = await cell.look(None)
    found_t = time.monotonic()
    if start == t0:  # the part was there at once: the move to the top view is its own
        for k, v in looks.items():
            _add(durations, k, v)
        _add(durations, "wait", found_t - t0 - sum(looks.values()))
    else:  # the arm waited at the top view: no move of this part's own
        for k in looks:
            _add(durations, k, 0.0)
        _add(durations, "wait", found_t - start)
    travel = _travel_of(frame, ctx.rt)
    if mode == "continuous":
        u = math.nan
    return Found(frame, travel, bg_now, u, start, mask)


async def _look_whole(ctx: _Ctx, opts: InspectOptions, q_top: NDArray[np.float64],
                      durations: dict[str, float]) -> Found:  # fmt: skip
    """The top view of a cell with no empty-belt background: the next frame at the station
    (a recorded cell's next image), to be recognised whole."""
    t0 = time.monotonic()
    frame = await ctx.rt.cell.look(q_top, speed=opts.speed)
    _look_times(frame, durations)
    return Found(frame, _travel_of(frame, ctx.rt), None, math.nan, t0, None)


def _T_cam(q: Any, T_ee_cam: NDArray[np.float64]) -> NDArray[np.float64]:
    return T_base_ee(np.asarray(q, dtype=np.float64)) @ T_ee_cam


#: What the cell assumes of an object it cannot name (no stored height): the tallest the
#: station admits (its viewpoints aim for objects up to this), metres.
UNKNOWN_MAX_HEIGHT_M = 0.25


#: How far above a measured height the pick's guarded descent starts, metres: more than the
#: teach's measurement falls short of the part's top on the catalogue's parts but one
#: (``python -m benchmarks.teach_height``: 26 mm at most; a thin upright plate with no
#: features on its edge is the exception, and its approach still starts above it).
MEASURED_MARGIN_M = 0.04


def _geometry(live: Any, name: str | None) -> tuple[float | None, NDArray[np.float64] | None]:
    """Height and suction point of a recognised model, as stored with it (``height_m``,
    ``grasp_obj``: measured at teach time or entered by an engineer); ``(None, None)`` for
    an unknown object or a model without them.  Never the simulator's catalogue."""
    m = None if name is None else live.model_of_name(name)
    if m is None:
        return None, None
    g = None if m.grasp_obj is None else np.asarray(m.grasp_obj, dtype=np.float64)
    return m.height_m, g


def _geometry_source(live: Any, name: str | None) -> str:
    """How a recognised model's height was stored: ``measured``, ``entered`` or ``""``."""
    m = None if name is None else live.model_of_name(name)
    return "" if m is None else str(getattr(m, "geometry_source", "") or "")


def _footprint_radius(
    mask: NDArray[np.bool_],
    camera: Any,
    T_cam: NDArray[np.float64],
    centre: NDArray[np.float64],
    z_m: float,
) -> float:
    """Half-width of the object's region seen from the top, on the plane ``z_m`` about
    ``centre`` (its obstacle box for the approach), metres, plus 1 cm."""
    ys, xs = np.nonzero(mask)
    step = max(1, len(xs) // 2000)
    pts = plane_points(
        np.stack([xs[::step], ys[::step]], axis=1).astype(np.float64), camera, T_cam, z_m
    )
    return float(min(0.5, np.linalg.norm(pts[:, :2] - centre[:2], axis=1).max() + 0.01))


@dataclass(frozen=True, eq=False)
class _SideView:
    """A side viewpoint visited: the frame, its camera pose, the query's region, how long
    planning and the region took (seconds) and the notes for the inspection's reason."""

    frame: Any
    T_base_cam: NDArray[np.float64]
    roi: SideRoi
    plan_s: float
    roi_s: float
    notes: tuple[str, ...]


async def _look_with_region(ctx: _Ctx, q: NDArray[np.float64], *, top_mask: NDArray[np.bool_],
                            T_cam_top: NDArray[np.float64], height_m: float,
                            travel0: float | None, speed: float | None,
                            **roi_options: Any) -> tuple[Any, NDArray[np.float64], SideRoi, float]:  # fmt: skip
    """Visit joints ``q``; the frame, its camera pose, the region of its image where the
    object found in the top view (``top_mask`` seen from ``T_cam_top``) can be
    (:func:`vision.segmentation.roi.side_roi`, up to ``height_m``, with ``roi_options``; with
    ``travel0`` -- the belt's travel at the top view's exposure, constant speed -- moved by
    the belt's travel since) and the seconds the region took."""
    f = await ctx.rt.cell.look(q, speed=speed)
    T_cam = _T_cam(f.robot_state.q, ctx.T_ee_cam)
    moved = None if travel0 is None else np.array([0.0, _travel_of(f, ctx.rt) - travel0, 0.0])
    t = time.monotonic()
    roi = await asyncio.to_thread(
        side_roi, top_mask, camera=ctx.camera, T_base_cam_top=T_cam_top, T_base_cam_side=T_cam,
        surface_z_m=ctx.surface_z, height_m=height_m, image_shape=f.rgb.shape[:2], moved_m=moved,
        **roi_options,
    )  # fmt: skip
    return f, T_cam, roi, time.monotonic() - t


async def _side_view(ctx: _Ctx, vp: int, point: NDArray[np.float64], *, T_plan: NDArray[np.float64],
                     top_mask: NDArray[np.bool_], T_cam_top: NDArray[np.float64], height_m: float,
                     travel0: float | None, speed: float | None) -> _SideView:  # fmt: skip
    """Viewpoint ``vp`` (2 or 3) planned at ``point`` (:func:`plan_viewpoints`), visited, and
    the region of its image where the object can be (:func:`_look_with_region`).  A region
    that cannot be made is the whole frame, noted."""
    t = time.monotonic()
    plan = await asyncio.to_thread(plan_viewpoints, point, T_ee_cam=T_plan, views=(VIEW_NAMES[vp - 1],),
                                   object_height_m=AIM_HEIGHT_M)  # fmt: skip
    plan_s = time.monotonic() - t
    notes = [f"viewpoint {vp}: {plan.views[0].reason}"] if plan.views[0].reason else []
    f, T_cam, roi, roi_s = await _look_with_region(
        ctx, plan.views[0].q, top_mask=top_mask, T_cam_top=T_cam_top, height_m=height_m,
        travel0=travel0, speed=speed,
    )  # fmt: skip
    if roi.mask is None:
        notes.append(f"viewpoint {vp}: {roi.reason}")
    return _SideView(f, T_cam, roi, plan_s, roi_s, tuple(notes))


def _carried(ctx: _Ctx, found: NDArray[np.float64], travel0: float, speed_m_s: float,
             vp: int) -> NDArray[np.float64]:  # fmt: skip
    """Where to plan viewpoint ``vp`` of the object found at ``found`` in the top view (belt
    travel ``travel0`` then) at constant speed: where the belt will have carried it 1.5 s
    from now (:func:`carried_point`)."""
    ahead = _belt(ctx.rt)[2] - travel0 + 1.5 * speed_m_s
    return carried_point(found, ahead, ctx.belt_end_y_m, vp)


async def inspect_object(ctx: _Ctx, opts: InspectOptions, job: Any = None, *,
                         tracker: Any = None, waiting: Waiting | None = None,
                         db_wait_s: float | None = None,
                         resolve: Resolve | None = None) -> dict[str, Any] | None:  # fmt: skip
    """Inspect the next part at the station and store the result (module docstring).

    First the part is found (:func:`_find`): waiting for it is not an inspection, so it
    stores nothing -- :class:`NoObject` when none comes within ``opts.wait_s``, None when
    ``waiting.stopped()`` ends the wait (a run asked to stop), and a cancellation while
    waiting leaves no row.  ``tracker`` (continuous operation, index mode): the part
    inspected last is not taken again (:class:`~backend.inspection.waiting.PartTracker`).

    Returns the stored inspection's public form; its ``duration_s`` is the wall time from
    the inspection's start (the part found at once: the search's start; else the moment it
    came) to its end.  Cut short (cancel: e-stop or stop), the complete ``failed`` row is
    stored with the reason before the cancellation goes on.

    Faults: an in-progress marker is committed once the part is found (waiting,
    without moving, up to ``db_wait_s`` -- None: until cancelled -- while the database is
    unavailable); any failure inside becomes a ``failed`` row with its reason; the row is
    stored with retries until the database takes it, in the transaction that removes the
    marker.

    ``resolve`` (a run following a recipe): the options are read again once the part is
    found, so a recipe selected while the run waited applies to this part.
    """
    cell = ctx.rt.cell
    report = (lambda f, m: job.report(f, m)) if job is not None else (lambda f, m: None)
    if waiting is None:
        waiting = Waiting(report=lambda m: report(0.05, m))
    plan = await recovery.retry_database(
        "reading the calibration", lambda: _plan_top(ctx), max_wait_s=db_wait_s,
        on_wait=lambda m: report(0.0, "holding: " + m),
    )  # fmt: skip
    durations: dict[str, float] = {}
    report(0.05, "looking for a part at the station")
    if plan.bg is None:
        found: Found | None = await _look_whole(ctx, opts, plan.top.q, durations)
    else:
        found = await _find(ctx, opts, plan.top.q, plan.bg, durations, tracker=tracker,
                            waiting=waiting)  # fmt: skip
    if found is None:
        return None
    opts = await resolved(resolve, opts)
    t_start = found.t_start
    started = utcnow() - timedelta(seconds=time.monotonic() - t_start)
    views: list[results.ViewRecord] = []
    cams: list[NDArray[np.float64]] = []
    state: dict[str, Any] = {"decision": "failed", "reason": "", "truth": None, "scores": {},
                             "model": None, "model_id": None, "score": None, "pose": None,
                             "viewpoints": (), "pick": None, "u_m": found.u_m}  # fmt: skip
    view = ctx.rt.view3d
    state["scene"] = SceneRecorder(getattr(view, "server", None))
    db = ctx.rt.database
    # The durable marker goes in before the inspection moves the arm past the top view (a
    # database outage holds here: no motion); the result's transaction removes it.
    marker = await recovery.retry_database(
        "starting an inspection", lambda: recovery.begin(db, ctx.rt.cell_id, opts.policy),
        max_wait_s=db_wait_s, on_wait=lambda m: report(0.05, "holding: " + m),
    )  # fmt: skip
    try:
        await _inspect_body(ctx, opts, plan, found, durations, views, cams, state, report)
    except asyncio.CancelledError:
        state["decision"] = "failed"
        state["reason"] = (
            "emergency stop" if cell.estopped else "stopped"
        ) + f" during {state.get('stage', 'the inspection')}"
        await asyncio.shield(
            _store(ctx, opts, started, durations, views, cams, state, marker, t_start)
        )
        raise
    except (VisionCellError, ValueError) as exc:
        state["decision"] = "failed"
        code = getattr(exc, "code", "error")
        detail = getattr(exc, "detail", str(exc))
        state["reason"] = f"{code}: {detail}"
        await _reject_failed(ctx, opts, state)
    except Exception as exc:  # never a lost inspection: the cause goes into a failed row
        state["decision"] = "failed"
        if recovery.is_database_error(exc):
            state["reason"] = (f"database_unavailable: during {state.get('stage', 'the start')}: "
                               f"{type(exc).__name__}: {str(exc)[:300]}")  # fmt: skip
        else:
            log.exception("inspection failed unexpectedly")
            state["reason"] = f"internal_error: {type(exc).__name__}: {str(exc)[:300]}"
    out = await _store(ctx, opts, started, durations, views, cams, state, marker, t_start)
    if tracker is not None and out["decision"] != "failed":
        tracker.inspected(found.u_m, found.mask)
    return out


@dataclass(frozen=True, eq=False)
class _TopPlan:
    """The top view at the station, the plan's mounting, the thresholds in force and the
    empty-belt background of that view (read once per inspection)."""

    top: Any
    T_plan: NDArray[np.float64]
    choice: Any
    bg: NDArray[np.uint8] | None


async def _plan_top(ctx: _Ctx) -> _TopPlan:
    """:class:`_TopPlan`; :class:`NotReady` when nothing is trained or the top view has no
    empty-belt background (a setup step missing: no inspection, no row)."""
    rt = ctx.rt
    if len(rt.live_index) == 0:
        raise NotReady(NOT_TRAINED)
    from backend.calibration import NOMINAL_T_EE_CAM, active_camera_calibration

    async with rt.database.session() as session:
        T_plan = (await active_camera_calibration(session, rt.cell_id)).T_ee_cam
        choice = await thresholds.current_choice(session)
    T_plan = np.asarray(NOMINAL_T_EE_CAM if T_plan is None else T_plan, dtype=np.float64)
    top = (await asyncio.to_thread(plan_shots, ctx.station, (1,), T_ee_cam=T_plan,
                                   object_height_m=AIM_HEIGHT_M, top_rolls_rad=(0.0,)))[0]  # fmt: skip
    bg = rt.teach_backgrounds.get(top)
    # A real or recorded camera may have models imported or uploaded and no teach (so no
    # background): its top view is recognised whole.  The simulated camera is always taught.
    if bg is None and rt.cell.camera_status().name == "sim":
        raise NotReady(
            "no empty-belt background of the top view at the station: teach a model first"
        )
    return _TopPlan(top, T_plan, choice, bg)


async def _reject_failed(ctx: _Ctx, opts: InspectOptions, state: dict[str, Any]) -> None:
    """A failed inspection whose object was found on the belt (after the top view): with
    ``sort``, into the reject bin (the guarded pick of an unknown object), once."""
    found = state.get("_found")
    if not opts.sort or found is None or state.get("pick") is not None or ctx.rt.cell.estopped:
        return
    if _belt(ctx.rt)[0] == "continuous":  # gone on with the belt: left to the belt's end
        state["pick"] = {"sorted": True, "ok": False,
                         "reason": "not rejected: the belt carried it on (constant speed)"}  # fmt: skip
        return
    try:
        state["pick"] = await _pick_unknown(
            ctx, opts, state, None, found, state.get("_radius", 0.18)
        )
    except (VisionCellError, ValueError) as exc:
        state["pick"] = {"sorted": True, "ok": False, "reason": f"cannot reject: {exc}"}
    _note_pick(state)


async def _store(ctx: _Ctx, opts: InspectOptions, started: Any, durations: dict[str, float],
                 views: list[results.ViewRecord], cams: list[NDArray[np.float64]],
                 state: dict[str, Any], marker: int | None = None,
                 t_start: float | None = None) -> dict[str, Any]:  # fmt: skip
    duration = None if t_start is None else max(0.0, time.monotonic() - t_start)
    # One clock read for the end: the stored end is the start plus the duration, so the two
    # agree even when the thread is preempted between reading two clocks.
    finished = utcnow() if duration is None else started + timedelta(seconds=duration)
    rec = results.InspectionRecord(
        started_at=started, finished_at=finished, decision=state["decision"], reason=state["reason"],
        policy=opts.policy, model_id=state["model_id"], model_name=state["model"],
        score=state["score"], viewpoints=tuple(state["viewpoints"]), scores=state["scores"],
        pose=state["pose"], durations=durations, pick=state["pick"], truth=state["truth"],
        views=tuple(views), duration_s=duration, recipe_id=opts.recipe_id,
        recipe_name=opts.recipe_name,
    )  # fmt: skip
    scene = await state["scene"].finish() if state.get("scene") is not None else None
    db = ctx.rt.database
    retention = ctx.rt.settings.image_retention
    iid = await recovery.retry_database(
        "storing an inspection",
        lambda: results.store(
            db, ctx.rt.cell_id, rec, retention=retention, scene=scene, marker_id=marker
        ),
    )
    pose = state["pose"]
    ev = InspectionDone(
        iid, rec.decision, rec.model_name, rec.reason, rec.score, rec.viewpoints,
        None if pose is None else tuple(tuple(r) for r in pose["T_base_obj"]),
        tuple(tuple(tuple(float(v) for v in r) for r in T) for T in cams), rec.pick,
        rec.recipe_id, rec.recipe_name,
    )  # fmt: skip
    ctx.rt.bus.publish(ev)

    async def read() -> dict[str, Any]:
        async with db.session() as session:
            return results.inspection_public(await results.get_inspection(session, iid))

    return await recovery.retry_database("reading an inspection back", read)


async def _inspect_body(ctx: _Ctx, opts: InspectOptions, plan: _TopPlan, part: Found,
                        durations: dict[str, float], views: list[results.ViewRecord],
                        cams: list[NDArray[np.float64]], state: dict[str, Any],
                        report: Any) -> None:  # fmt: skip
    rt, cell = ctx.rt, ctx.rt.cell
    live = rt.live_index
    T_plan, choice = plan.T_plan, plan.choice
    frame, travel0, bg = part.frame, part.travel_m, part.bg
    # No empty-belt background (a real or recorded camera whose models were imported or
    # uploaded: only a teach grabs one): the top view is recognised whole, said so.
    whole = bg is None
    report(0.1, "inspecting the part at the station")
    mode, speed_m_s, _ = _belt(rt)
    T_cam_top = _T_cam(frame.robot_state.q, ctx.T_ee_cam)
    z_mid = ctx.surface_z + AIM_HEIGHT_M / 2
    state["stage"] = "segmenting"
    if bg is None:  # whole
        region: Any = _WholeImage(np.ones(frame.rgb.shape[:2], dtype=bool))
    else:
        assert bg is not None  # not whole: there is a background
        t = time.monotonic()
        near = None if mode == "continuous" else _station_px(ctx, T_cam_top, z_mid)
        region = await asyncio.to_thread(segment_object, frame.rgb, bg, near_px=near)
        _add(durations, "segment", time.monotonic() - t)
    ys, xs = np.nonzero(region.mask)
    found = plane_points(np.array([[xs.mean(), ys.mean()]]), ctx.camera, T_cam_top, z_mid)[0]
    found[2] = ctx.surface_z
    state["_found"] = found
    state["truth"] = _truth_near(rt, found, _belt(rt)[2] - travel0)
    # The light: every view's channels scaled back to the light the views were taught
    # under, by the belt round the object now against the belt in the trained top views.
    gain = None
    if opts.balance_light and not whole:
        gain = light_gain(live.light_reference(), surround_colour(frame.rgb, region.mask))
    state["light_gain"] = None if gain is None else [round(float(g), 4) for g in gain]
    frames: dict[int, tuple[Any, NDArray[np.bool_] | None, str]] = {
        1: (frame, region.mask, region.method)
    }
    cams.append(T_cam_top)

    planning: dict[str, Any] = {"s": 0.0, "roi_s": 0.0, "notes": []}
    roi_height = height_bound(
        (m.height_m for m in live.models().values()), default_m=UNKNOWN_MAX_HEIGHT_M
    )

    top_features: list[Any] = []  # the top view's query features, for the pose

    async def look(vp: int) -> Any:
        if vp == 1:
            feats = await asyncio.to_thread(live.extract, apply_gain(frame.rgb, gain), region.mask)
            top_features.append(feats)
            return feats
        state["stage"] = f"viewpoint {vp}"
        report(0.3 + 0.2 * len(frames), f"viewpoint {vp}")
        point = _carried(ctx, found, travel0, speed_m_s, vp) if mode == "continuous" else found
        if whole:  # no top-view region to carry over: the side view is recognised whole
            plan = await asyncio.to_thread(plan_viewpoints, point, T_ee_cam=T_plan,
                                           views=(VIEW_NAMES[vp - 1],), object_height_m=AIM_HEIGHT_M)  # fmt: skip
            f = await cell.look(plan.views[0].q, speed=opts.speed)
            _look_times(f, durations)
            cams.append(_T_cam(f.robot_state.q, ctx.T_ee_cam))
            frames[vp] = (f, None, WHOLE_IMAGE_NOTE)
            return apply_gain(f.rgb, gain)
        side = await _side_view(
            ctx, vp, point, T_plan=T_plan, top_mask=region.mask, T_cam_top=T_cam_top,
            height_m=roi_height, travel0=travel0 if mode == "continuous" else None,
            speed=opts.speed,
        )  # fmt: skip
        planning["s"] += side.plan_s
        planning["roi_s"] += side.roi_s
        planning["notes"].extend(side.notes)
        _look_times(side.frame, durations)
        cams.append(side.T_base_cam)
        frames[vp] = (side.frame, None if side.roi.mask is None else side.roi.mask.astype(bool),
                      side.roi.reason)  # fmt: skip
        return side_query(apply_gain(side.frame.rgb, gain), side.roi)

    if opts.threshold is not None:
        choice = thresholds.choice_from_detail(
            float(opts.threshold), {"rule": f"fixed by recipe {opts.recipe_name or ''}".strip()}
        )
    state["stage"] = "recognition"
    t = time.monotonic()
    with live.reading() as index:
        res = await recognise_views(look, index, policy=opts.policy, max_views=opts.max_views,
                                    threshold=choice)  # fmt: skip
    spent = time.monotonic() - t
    move_like = sum(frames[vp][0].meta.get("look", {}).get(k, 0.0) for vp in frames if vp != 1
                    for k in ("move_s", "settle_s", "acquire_s"))  # fmt: skip
    feat = sum(r.retrieval_s for r in res.views)
    match = sum(r.verification_s for r in res.views)
    _add(durations, "match", match)
    _add(durations, "plan", planning["s"])
    _add(durations, "segment", planning["roi_s"])  # the side views' regions
    other = spent - move_like - planning["s"] - planning["roi_s"] - feat - match
    _add(durations, "features", max(0.0, other) + feat)
    t = time.monotonic()
    state["viewpoints"] = res.viewpoints
    state["scores"] = {k: round(float(v), 4) for k, v in res.scores.items()}
    for vp, r in zip(res.viewpoints, res.views, strict=True):
        f, m, how = frames[vp]
        label = f"vp{vp} {r.best_model or '-'} {r.score:.2f}"
        views.append(results.ViewRecord(vp, await asyncio.to_thread(_draw, f.rgb, m, label),
                                        {"segmentation": how, "decision": r.decision,
                                         "light_gain": state["light_gain"],
                                         "scores": {k: round(float(s), 4) for k, s in r.scores.items()}}))  # fmt: skip
    if res.decision == "recognized" and opts.models and res.model not in opts.models:
        state["decision"], state["score"] = "unknown", float(res.score)
        state["reason"] = (f"{res.model} scored {res.score:.2f}: not a model of recipe "
                           f"{opts.recipe_name or '(options)'}")  # fmt: skip
    elif res.decision == "recognized":
        state["decision"], state["model"], state["score"] = (
            "recognized",
            res.model,
            float(res.score),
        )
        indexed = None if res.model is None else live.model_of_name(res.model)
        state["model_id"] = None if indexed is None else indexed.id
        state["reason"] = f"{res.model} scored {res.score:.2f} over {len(res.viewpoints)} view(s)"
    else:
        state["decision"], state["score"] = "unknown", float(res.score)
        if res.decision == "ambiguous" and len(res.contenders) > 1:
            state["reason"] = f"ambiguous between {', '.join(res.contenders)}"
        elif res.decision == "ambiguous":
            state["reason"] = (f"{res.contenders[0]} not confirmed by the side views "
                               f"(fused score {res.score:.2f})")  # fmt: skip
        else:
            state["reason"] = f"no model passed its threshold (best score {res.score:.2f})"
    if planning["notes"]:
        state["reason"] += "; " + "; ".join(planning["notes"])
    if whole:
        state["reason"] += f"; {WHOLE_IMAGE_NOTE}"
    if ctx.uncalibrated:
        state["reason"] += f"; camera: {ctx.source}"
    _add(durations, "decide", time.monotonic() - t)
    # -- pose --------------------------------------------------------------------------
    t = time.monotonic()
    pose_err = ""
    pose: ObjectPose | None = None
    stored_h, grasp = _geometry(live, state["model"])
    height = AIM_HEIGHT_M if stored_h is None else stored_h
    radius = await asyncio.to_thread(
        _footprint_radius, region.mask, ctx.camera, T_cam_top, found, ctx.surface_z + height
    )
    state["_radius"] = radius
    travel_pose = travel0  # the belt's travel at the exposure the pose is of
    second: dict[str, Any] | None = None
    if state["decision"] == "recognized" and ctx.uncalibrated:
        pose_err = ctx.uncalibrated
    elif state["decision"] == "recognized":
        try:
            pose = await _pose(ctx, _top_candidate(res, state["model"]), state["model"],
                               T_cam_top, height, top_features[0] if top_features else None,
                               region.mask)  # fmt: skip
        except PoseFailed as exc:
            pose_err = exc.detail
        if rests_on_too_little(pose):
            state["stage"] = "second top view"
            report(0.8, "second top view (the pose rested on too little)")
            looked = sum(durations.get(k, 0.0) for k in ("move", "settle", "acquire"))
            again = await _second_top_view(
                ctx, opts, state["model"], found, first=pose, first_err=pose_err,
                T_plan=T_plan, top_mask=region.mask, T_cam_top=T_cam_top, height=height,
                travel0=travel0, gain=gain, mode=mode, speed_m_s=speed_m_s,
            )  # fmt: skip
            pose, pose_err = again.pose, again.error
            if again.shot is not None:
                f2, T_cam2, record2 = again.shot
                _look_times(f2, durations)
                cams.append(T_cam2)
                state["viewpoints"] = (*state["viewpoints"], 1)
                views.append(record2)
                if again.used:
                    travel_pose = _travel_of(f2, rt)
            # the pose stage's own time: the second look's motion counts as motion
            t += sum(durations.get(k, 0.0) for k in ("move", "settle", "acquire")) - looked
            second = again.summary
    belt_stopped = False
    if mode == "continuous" and opts.sort and rt.conveyor.controllable:
        # Picking from a moving belt would need conveyor tracking the 5-DOF arm's controller
        # has not: the cell stops the belt (the encoder then says where the object is: the
        # prediction below is exact) and starts it again after the pick.
        await rt.conveyor.stop()
        belt_stopped = True
    if pose is not None:
        pub = pose.public()
        pub["at_exposure"] = pose.T_base_obj.tolist()
        if mode == "continuous":
            # predicted from the exposure the pose is of; the travel reported counts from
            # the top view's (the truth's) exposure
            travel_now = _belt(rt)[2]
            pose = predict_along_belt(pose, travel_now - travel_pose)
            pub.update(T_base_obj=pose.T_base_obj.tolist(),
                       position_m=[float(v) for v in pose.T_base_obj[:3, 3]],
                       predicted_travel_m=travel_now - travel0,
                       at_exposure_travel_m=travel_pose - travel0)  # fmt: skip
        pub.update(camera_model=ctx.source, belt_mode=mode, z_plane_m=ctx.surface_z + height,
                   second_top_view=second)  # fmt: skip
        state["pose"] = pub
    elif pose_err:
        state["reason"] += f"; pose not computed: {pose_err}"
    _add(durations, "pose", time.monotonic() - t)
    # -- pick / approach ------------------------------------------------------------------
    state["stage"] = "pick"
    t = time.monotonic()
    try:
        await _pick_stage(ctx, opts, state, pose, stored_h, radius, grasp, found, mode, travel0)
    finally:
        if belt_stopped and not cell.estopped:
            with contextlib.suppress(Exception):
                await rt.conveyor.start(mode="continuous", speed_m_s=speed_m_s)
    _add(durations, "pick", time.monotonic() - t)


async def _pick_stage(ctx: _Ctx, opts: InspectOptions, state: dict[str, Any], pose: ObjectPose | None,
                      stored_h: float | None, radius: float, grasp: NDArray[np.float64] | None,
                      found: NDArray[np.float64], mode: str, travel0: float) -> None:  # fmt: skip
    """The pick (or the approach) of the inspected object, by what the model stores.

    A recognised part goes to its own bin: straight to an engineer's entered height and
    grasp point; by a short guarded descent from just above a height the teach measured
    (the measurement's error is taken up by the vacuum switch); by the guarded descent from
    the tallest admitted height when no height is stored (slow: the reason says to teach
    or enter it).  An unknown or failed object goes to the reject bin.  A pick that cannot
    be planned or does not hold the part says so in the inspection's reason."""
    rt = ctx.rt
    recognised = state["decision"] == "recognized"
    if pose is None and ctx.uncalibrated:
        why = f"not picked: a pick {ctx.uncalibrated}"
        pick: dict[str, Any] = {"sorted": opts.sort, "ok": False}
        if opts.sort:  # where it would go: the sorting itself is planned without the pose
            b = _bin_for(rt, _part_of(rt, state) if recognised else None)
            if b is None:
                why += f"; {_no_bin(rt)}"
            else:
                pick.update(bin=b.name, reject=bool(b.reject))
                why += f"; it would go to bin {b.name!r}"
        state["pick"] = {**pick, "reason": why}
        return
    source = _geometry_source(rt.live_index, state["model"]) if recognised else ""
    at = found.copy()
    if mode == "continuous":
        at[1] += _belt(rt)[2] - travel0
    if not opts.sort:
        if pose is not None:
            # Sorting off: the approach pose (above the tallest admitted object without a height).
            h_pick = UNKNOWN_MAX_HEIGHT_M if stored_h is None else stored_h
            state["pick"] = await _pick(ctx, opts, state, pose, h_pick, radius, grasp)
        else:
            state["pick"] = await _pick_unknown(ctx, opts, state, pose, at, radius)
    elif recognised and stored_h is not None and source != "measured" and pose is not None:
        state["pick"] = await _pick(ctx, opts, state, pose, stored_h, radius, grasp)
    elif recognised:
        if stored_h is not None:
            top = min(0.5, stored_h + MEASURED_MARGIN_M)
            why = (f"height {stored_h * 1e3:.0f} mm {source or 'stored'}: guarded descent from "
                   f"{MEASURED_MARGIN_M * 1e3:.0f} mm above it")  # fmt: skip
            if pose is None:
                why += "; no pose: over the footprint's centre"
        else:
            top = UNKNOWN_MAX_HEIGHT_M
            why = (f"no height stored for {state['model']}: guarded descent from "
                   f"{UNKNOWN_MAX_HEIGHT_M * 1e3:.0f} mm (teach the model again or enter its "
                   "height on the Models page to pick it directly)")  # fmt: skip
        state["pick"] = await _pick_unknown(ctx, opts, state, pose, at, radius,
                                            max_height_m=top, why=why)  # fmt: skip
    else:
        state["pick"] = await _pick_unknown(ctx, opts, state, pose, at, radius)
    _note_pick(state)


def _note_pick(state: dict[str, Any]) -> None:
    """Say in the inspection's reason when its pick did not place the part where it belongs."""
    pick = state.get("pick")
    if not isinstance(pick, dict) or not pick.get("sorted") or pick.get("ok"):
        return
    where = f" into {pick['bin']}" if pick.get("bin") else ""
    state["reason"] = (state["reason"] + "; " if state["reason"] else "") + (
        f"not sorted{where}: {pick.get('reason', 'unknown')}"
    )


#: The second top view, taken when the first one's pose rests on too little
#: (:func:`rests_on_too_little`).  The camera turns about its axis by ``ROLL`` (one of
#: the teach's rolls: its camera centre relative to the object is a taught one's) at the
#: top view's distance; the region is the top view's carried over, widened by
#: ``MARGIN_PX`` only (the belt's own features round the object cost correspondences).
#: Measured with a second top view after every first one (pipe flange, seed 8, 40 objects
#: in index mode): roll 120 deg, margin 2 px: 39 of 40 within 2 mm and 1 deg, 40 joint
#: fits; roll 120 deg with the side views' margins (1 cm + 6 px): 37; roll 60 deg (a
#: camera centre not taught): 33; roll 60 deg at 0.30 m: 26.
SECOND_TOP_ROLL_RAD = math.radians(120.0)
SECOND_TOP_MARGIN_PX = 2
#: Two answers that each rest on too little (the first and the second top view's) are
#: taken when they agree within these (two images, each with its own features).
WEAK_AGREE_M = 0.0015
WEAK_AGREE_YAW_RAD = math.radians(0.75)


@dataclass(frozen=True, eq=False)
class _SecondTop:
    """What the second top view gave: the pose to use (None: ``error``), the frame with its
    camera and its stored image (None when no frame was taken), whether the pose is of its
    exposure, and the summary stored with the pose."""

    pose: ObjectPose | None
    error: str
    shot: tuple[Any, NDArray[np.float64], results.ViewRecord] | None = None
    used: bool = False
    summary: dict[str, Any] = field(default_factory=dict)


def _weakness(pose: ObjectPose) -> str:
    if pose.method == "plane":
        return "the plane answer of one trained view: too few correspondences for the joint fit"
    return f"one trained view's {pose.n_points} correspondences"


def _pose_brief(pose: ObjectPose | None, err: str) -> dict[str, Any]:
    if pose is None:
        return {"error": err}
    return {"method": pose.method, "n_points": pose.n_points, "views": pose.views,
            "position_m": [round(float(v), 5) for v in pose.T_base_obj[:3, 3]],
            "yaw_rad": round(float(pose.yaw_rad), 5)}  # fmt: skip


async def _second_top_view(
    ctx: _Ctx, opts: InspectOptions, model: str, found: NDArray[np.float64], *,
    first: ObjectPose | None, first_err: str, T_plan: NDArray[np.float64],
    top_mask: NDArray[np.bool_], T_cam_top: NDArray[np.float64], height: float,
    travel0: float, gain: Any, mode: str, speed_m_s: float,
) -> _SecondTop:  # fmt: skip
    """Look at the object from the top again (turned by :data:`SECOND_TOP_ROLL_RAD`; at
    constant speed over where the belt will have carried it) and compute the pose there,
    in the first top view's region ``top_mask`` carried into the new view
    (:func:`side_roi`, up to ``height``).

    The second view's pose is taken unless it too rests on too little
    (:func:`rests_on_too_little`); two such answers are taken when they agree within
    :data:`WEAK_AGREE_M` and :data:`WEAK_AGREE_YAW_RAD` (at constant speed the first
    carried by the belt's travel between the exposures); otherwise there is no pose, with
    the reason (a pose resting on one view's handful of features would be picked wrong)."""
    rt = ctx.rt
    summary: dict[str, Any] = {"first": _pose_brief(first, first_err)}

    def none(why: str, shot: Any = None) -> _SecondTop:
        summary.setdefault("second", {"error": why})
        first_txt = (f"the top view's pose rested on too little ({_weakness(first)})"
                     if first is not None else first_err)  # fmt: skip
        return _SecondTop(None, f"{first_txt}; the second top view: {why}", shot,
                          summary=summary)  # fmt: skip

    point = found
    if mode == "continuous":
        try:
            point = _carried(ctx, found, travel0, speed_m_s, 1)
        except Unreachable as exc:
            return none(str(exc))
    try:
        plan = await asyncio.to_thread(
            plan_viewpoints, point, T_ee_cam=T_plan, views=(VIEW_NAMES[0],),
            object_height_m=AIM_HEIGHT_M, roll_rad=SECOND_TOP_ROLL_RAD,
        )  # fmt: skip
    except (Unreachable, ValueError) as exc:
        return none(f"cannot be reached: {exc}")
    f, T_cam, roi, _roi_s = await _look_with_region(
        ctx, plan.views[0].q, top_mask=top_mask, T_cam_top=T_cam_top, height_m=height,
        travel0=travel0 if mode == "continuous" else None, speed=opts.speed,
        margin_m=0.0, margin_px=SECOND_TOP_MARGIN_PX,
    )  # fmt: skip
    second: ObjectPose | None = None
    err = ""
    mask = None if roi.mask is None else roi.mask.astype(bool)
    if mask is None:
        err = f"no region: {roi.reason}"
    else:
        feats = await asyncio.to_thread(rt.live_index.extract, apply_gain(f.rgb, gain), mask)
        try:
            second = await _pose(ctx, None, model, T_cam, height, feats, mask)
        except PoseFailed as exc:
            err = exc.detail
    summary["second"] = _pose_brief(second, err)
    label = f"vp1 again {model} {'-' if second is None else second.method}"
    record = results.ViewRecord(1, await asyncio.to_thread(_draw, f.rgb, mask, label),
                                {"segmentation": "the top view's region carried over",
                                 "second_top_view": summary, "light_gain": None if gain is None
                                 else [round(float(g), 4) for g in gain]})  # fmt: skip
    shot = (f, T_cam, record)
    if second is None:
        return none(err, shot)
    if not rests_on_too_little(second):
        summary["chosen"] = "second"
        return _SecondTop(second, "", shot, used=True, summary=summary)
    apart = ""
    if first is not None:
        carried = first
        if mode == "continuous":  # the first carried by the belt's travel since the top view
            carried = predict_along_belt(first, _travel_of(f, rt) - travel0)
        d, dyaw = pose_apart(carried, second)
        if d <= WEAK_AGREE_M and dyaw <= WEAK_AGREE_YAW_RAD:
            summary["chosen"] = "first"
            return _SecondTop(first, "", shot, summary=summary)
        apart = f", {d * 1e3:.1f} mm and {math.degrees(dyaw):.1f} deg from the first"
    return none(f"too little again ({_weakness(second)}){apart}", shot)


#: Most trained top views the pose is computed from (the recognised one and the others of
#: the model that verify best on the top view), and the fewest inliers a view needs.
POSE_MAX_VIEWS = 6
POSE_MIN_INLIERS = 6
#: Triangulated feature heights of the models' taught top views, per process (keyed by the
#: views' features and poses and the calibration, so a model taught again gets new ones).
FEATURE_HEIGHTS = HeightCache()


def _top_candidate(res: Any, model: str) -> Any:
    """The recognition's candidate of ``model`` on the top view (viewpoint 1) with a
    homography: the trained view the pose starts from."""
    top = next((r for vp, r in zip(res.viewpoints, res.views, strict=True) if vp == 1), None)
    cand = (
        None
        if top is None
        else next((c for c in top.candidates if c.model == model and c.H is not None), None)
    )
    if cand is None or cand.viewpoint != 1:
        raise PoseFailed("the top view did not verify the recognised model (no homography)")
    return cand


async def _pose(
    ctx: _Ctx, cand: Any, model: str, T_cam_now: NDArray[np.float64], height: float,
    query: Any = None, query_mask: NDArray[np.bool_] | None = None,
) -> ObjectPose:  # fmt: skip
    """The pose from the trained top view ``cand`` (the recognition's candidate on the top
    view; None: the model's top view that verifies best on ``query`` leads) and the model's
    other top views that verify on the top view's features ``query``
    (:func:`estimate_pose_views`; the top view's region ``query_mask`` judges answers that
    disagree by their silhouettes)."""
    live = ctx.rt.live_index

    def verify_others() -> tuple[Any, list[Any], list[int]]:
        with live.reading() as index:
            top_ids = [v.view_id for v in index.views_of(model, viewpoint=1)]
            if query is None:
                return cand, [], top_ids
            skip = None if cand is None else cand.view_id
            got = [verify_view(index, vid, query) for vid in top_ids if vid != skip]
        ok = sorted((c for c in got if c.H is not None and c.n_inliers >= POSE_MIN_INLIERS),
                    key=lambda c: (-c.n_inliers, c.view_id))  # fmt: skip
        lead = cand if cand is not None else (ok.pop(0) if ok else None)
        return lead, ok[: POSE_MAX_VIEWS - 1], top_ids

    cand, others, top_ids = await asyncio.to_thread(verify_others)
    if cand is None:
        raise PoseFailed(f"no trained top view of {model} verified on this view")
    cands = [cand, *others]
    async with ctx.rt.database.session() as session:
        rows = await session.execute(
            select(TrainedView.id, TrainedView.joints, TrainedView.yaw_rad, TrainedView.mask_png,
                   TrainedView.height, TrainedView.width)
            .where(TrainedView.id.in_({c.view_id for c in cands} | set(top_ids)))
        )  # fmt: skip
        stored = {int(vid): (j, y, m, (h, w)) for vid, j, y, m, h, w in rows.all()}
    if stored.get(cand.view_id, (None,))[0] is None:
        raise PoseFailed(f"trained view {cand.view_id} has no camera pose (uploaded, not taught)")
    from backend.recognition.images import mask_from_png

    def heights_of_inliers() -> dict[int, NDArray[np.float64]]:
        # the heights of each candidate's inlier features, looked up by their trained pixels
        fh, present = _feature_heights(ctx, model, height, {v: (j, y) for v, (j, y, _m, _s)
                                                             in stored.items()})  # fmt: skip
        return {
            c.view_id: fh.of(c.view_id, c.inlier_xy[:, :2], present[c.view_id].features.keypoints.xy)
            for c in cands if c.inlier_xy is not None and c.view_id in present
        }  # fmt: skip

    known = await asyncio.to_thread(heights_of_inliers)
    matches = []
    for c in cands:
        joints, yaw, mask_png, shape = stored.get(c.view_id, (None, 0.0, None, (0, 0)))
        if joints is None or c.inlier_xy is None:
            continue  # deleted meanwhile, or uploaded without a camera pose
        matches.append(ViewMatch(
            c.H, c.inlier_xy, _T_cam(joints, ctx.T_ee_cam), _taught_at(ctx, yaw),
            None if mask_png is None else mask_from_png(mask_png), shape, known.get(c.view_id),
        ))  # fmt: skip
    # Every taught top view of the model with a region judges answers that disagree by
    # their silhouettes (the region decoded only for the views nearest an answer's).
    silhouettes = [
        SilhouetteView(_T_cam(joints, ctx.T_ee_cam), _taught_at(ctx, yaw),
                       functools.cache(functools.partial(mask_from_png, mask_png)))
        for vid, (joints, yaw, mask_png, _shape) in sorted(stored.items())
        if joints is not None and mask_png is not None
    ]  # fmt: skip
    return await asyncio.to_thread(
        estimate_pose_views, matches, camera=ctx.camera, T_base_cam_now=T_cam_now,
        z_plane_m=ctx.surface_z + height, z_floor_m=ctx.surface_z, query_mask=query_mask,
        silhouettes=silhouettes,
    )  # fmt: skip


def _taught_at(ctx: _Ctx, yaw: float) -> NDArray[np.float64]:
    """The model frame as a teach saw it: the station, turned by the teach's yaw."""
    T = np.eye(4)
    co, si = math.cos(yaw), math.sin(yaw)
    T[:2, :2] = [[co, -si], [si, co]]
    T[:3, 3] = ctx.station
    return T


def _feature_heights(
    ctx: _Ctx, model: str, height: float, poses: dict[int, tuple[Any, float]]
) -> tuple[FeatureHeights, dict[int, Any]]:
    """The triangulated heights of ``model``'s taught top views (:data:`FEATURE_HEIGHTS`:
    computed once per set of views and calibration) and the index's views by id; ``poses``
    gives each view's stored joints and teach yaw (views without joints were uploaded and
    take no part).  Runs in a worker thread."""
    live = ctx.rt.live_index
    with live.reading() as index:
        present = {v.view_id: v for v in index.views_of(model, viewpoint=1)}
    taught = [
        TaughtTopView(vid, present[vid].features, _T_cam(j, ctx.T_ee_cam), _taught_at(ctx, y))
        for vid, (j, y) in sorted(poses.items()) if j is not None and vid in present
    ]  # fmt: skip
    fh = FEATURE_HEIGHTS.get(taught, camera=ctx.camera, z_floor_m=ctx.surface_z,
                             z_top_m=ctx.surface_z + height)  # fmt: skip
    return fh, present


async def warm_feature_heights(ctx: _Ctx) -> int:
    """Triangulate every model's taught top views before the first inspection needs them
    (up to a second or two per model for the wheels on this machine's cores); returns the
    models done.  A model without a stored height is skipped (its pose is not computed)."""
    models = [m for m in ctx.rt.live_index.models().values() if m.height_m is not None]
    if not models:
        return 0
    async with ctx.rt.database.session() as session:
        rows = await session.execute(
            select(TrainedView.model_id, TrainedView.id, TrainedView.joints, TrainedView.yaw_rad)
            .where(TrainedView.model_id.in_([m.id for m in models]), TrainedView.viewpoint == 1)
        )  # fmt: skip
        poses: dict[int, dict[int, tuple[Any, float]]] = {}
        for mid, vid, j, y in rows.all():
            poses.setdefault(int(mid), {})[int(vid)] = (j, float(y))
    done = 0
    for m in models:
        if poses.get(m.id) and m.height_m is not None:  # (the list holds only those)
            await asyncio.to_thread(_feature_heights, ctx, m.name, float(m.height_m), poses[m.id])
            done += 1
    return done


#: What a result says when the top view had no empty-belt background to segment against.
WHOLE_IMAGE_NOTE = "recognised on the whole image (no empty-belt background: no teach on this cell)"
#: What a result says when it should sort in a cell that has no bins.
NO_BINS = "sorting is not available: this cell has no bins"


def _no_bin(rt: CellRuntime) -> str:
    """Why no bin takes a part: the layout has no bins, or no reject bin."""
    layout = rt.layout
    if not layout.bins:
        return (f"{NO_BINS} (layout: {layout.source}; a real cell lists its bins in the "
                "layout file VISIONCELL_CELL_LAYOUT)")  # fmt: skip
    return f"no bin takes this part and the cell's layout ({layout.source}) has no reject bin"


@dataclass(frozen=True, eq=False)
class _WholeImage:
    """The top view's region when there is no background to segment against: every pixel."""

    mask: NDArray[np.bool_]
    method: str = WHOLE_IMAGE_NOTE


def _bin_for(rt: CellRuntime, part: str | None, named: str | None = None) -> Bin | None:
    """The layout's bin for ``part`` (``named``: the options' bin for the model, when the
    layout has one of that name); the reject bin for None or a part no bin takes."""
    if named is not None:
        b = next((b for b in rt.layout.bins if b.name == named), None)
        if b is not None:
            return b
    return rt.layout.bin_for(part)


def _part_of(rt: CellRuntime, state: dict[str, Any]) -> str | None:
    """The part the recognised model is (its ``part``, else its name)."""
    m = rt.live_index.model_of_name(state["model"]) if state["model"] else None
    return None if m is None else m.part


async def _pick_unknown(ctx: _Ctx, opts: InspectOptions, state: dict[str, Any],
                        pose: ObjectPose | None, at: NDArray[np.float64], radius: float, *,
                        max_height_m: float = UNKNOWN_MAX_HEIGHT_M,
                        why: str | None = None) -> dict[str, Any]:  # fmt: skip
    """A pick by a guarded descent over the footprint centre from ``max_height_m``
    (:func:`robot.pick.execute_search_pick_place`: the height is found by the vacuum
    switch).  With ``why`` (a recognised part; ``why`` says which height it starts from)
    into the part's own bin; without it (unknown or failed) into the reject bin.  Without
    ``sort``, left on the belt."""
    from robot.pick import execute_search_pick_place

    rt, cell = ctx.rt, ctx.rt.cell
    if not opts.sort:
        return {"sorted": False, "ok": False,
                "reason": "not picked: no pose or no stored height for this object (sorting off)"}  # fmt: skip
    part = None
    if why is not None:
        m = rt.live_index.model_of_name(state["model"]) if state["model"] else None
        part = None if m is None else m.part
    b = _bin_for(rt, part, opts.bin_of(state["model"]) if why is not None else None)
    if b is None:
        return {"sorted": True, "ok": False, "reason": _no_bin(rt)}
    if why is not None and b.reject:
        why += f"; no bin takes part {part!r}: rejected"
    T = np.eye(4)
    if pose is not None:
        T[:3, :3] = pose.T_base_obj[:3, :3]
        T[:2, 3] = pose.T_base_obj[:2, 3]
    else:
        T[:2, 3] = at[:2]
    T[2, 3] = ctx.surface_z
    q0 = np.asarray(cell.driver.state.q, dtype=np.float64)
    try:
        with cell._arm("a pick"):  # the job holds the arm; this is its motion
            out, h = await execute_search_pick_place(
                cell.driver, T, np.asarray(b.drop_point), max_height_m=max_height_m,
                object_radius_m=radius, world=cell.world, q_return=q0,
            )  # fmt: skip
    except Unreachable as exc:
        return {"sorted": True, "ok": False, "bin": b.name, "reject": bool(b.reject),
                "reason": f"cannot pick: {exc}", "search": True, "how": why}  # fmt: skip
    return {"sorted": True, "ok": out.ok, "bin": b.name, "reject": bool(b.reject),
            "stage": out.stage, "reason": out.reason, "search": True, "found_height_m": h,
            "how": why}  # fmt: skip


async def _pick(ctx: _Ctx, opts: InspectOptions, state: dict[str, Any], pose: ObjectPose,
                height: float, radius: float, grasp: NDArray[np.float64] | None) -> dict[str, Any]:  # fmt: skip
    from robot.pick import execute_pick_place, plan_pick_place

    rt, cell = ctx.rt, ctx.rt.cell
    part = None
    m = rt.live_index.model_of_name(state["model"]) if state["model"] else None
    if m is not None:
        part = m.part
    q0 = np.asarray(cell.driver.state.q, dtype=np.float64)
    ok = state["decision"] == "recognized"
    b = _bin_for(rt, part if ok else None, opts.bin_of(state["model"]) if ok else None)
    drop = ctx.station + np.array([0.0, 0.0, 0.3]) if b is None else np.asarray(b.drop_point)
    try:
        plan = await asyncio.to_thread(plan_pick_place, q0, pose.T_base_obj, height, drop,
                                       object_radius_m=radius, grasp_obj=grasp, world=cell.world)  # fmt: skip
    except Unreachable as exc:
        return {"sorted": opts.sort, "ok": False, "bin": None if b is None else b.name,
                "reject": bool(b is not None and b.reject), "reason": f"cannot pick: {exc}"}  # fmt: skip
    if not opts.sort:
        approach = plan.steps[0].trajectory
        assert approach is not None  # a planned pick's first step moves
        await cell.execute(approach)
        return {
            "sorted": False,
            "ok": True,
            "stage": "approach",
            "reason": "moved to the approach pose",
        }
    if b is None:
        return {"sorted": True, "ok": False, "reason": _no_bin(rt)}
    with cell._arm("a pick"):  # the job holds the arm; this is its motion
        out = await execute_pick_place(cell.driver, plan)
    return {"sorted": True, "ok": out.ok, "bin": b.name, "reject": bool(b.reject),
            "stage": out.stage, "reason": out.reason,
            "how": f"height {height * 1e3:.0f} mm stored: planned pick to the grasp point"}  # fmt: skip


# -- jobs -------------------------------------------------------------------------------------
@dataclass
class InspectionRun:
    """Continuous operation: inspect objects until stopped or ``count`` done."""

    options: InspectOptions
    count: int | None
    #: Reads the options again before each object (None: ``options`` throughout).
    resolve: Resolve | None = None
    done: int = 0
    ids: list[int] = field(default_factory=list)
    stop_requested: bool = False
    job: Any = None


async def _station_top(rt: CellRuntime) -> tuple[_Ctx, Any]:
    """The context and the top view at the station, planned with the active hand-eye
    calibration (the nominal mounting without one)."""
    from backend.calibration import NOMINAL_T_EE_CAM, active_camera_calibration

    async with rt.database.session() as session:
        T = (await active_camera_calibration(session, rt.cell_id)).T_ee_cam
    T = np.asarray(NOMINAL_T_EE_CAM if T is None else T, dtype=np.float64)
    ctx = await context(rt)
    top = (await asyncio.to_thread(plan_shots, ctx.station, (1,), T_ee_cam=T,
                                   object_height_m=AIM_HEIGHT_M, top_rolls_rad=(0.0,)))[0]  # fmt: skip
    return ctx, top


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
            shots.append((frame.rgb, _travel_of(frame, rt)))
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
                                 T_base_cam=_T_cam(frame.robot_state.q, ctx.T_ee_cam), geometry=geo)  # fmt: skip
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


def _check_ready(rt: CellRuntime) -> None:
    """409 at once (not in the job): e-stop, arm busy, nothing trained."""
    rt.cell.check_can_move()
    rt.jobs.check_arm_free()
    if len(rt.live_index) == 0:
        raise NothingTrained(NOT_TRAINED)


async def start_inspection(rt: CellRuntime, opts: InspectOptions) -> Any:
    """Start a job inspecting the object at the station; returns the job.  The options'
    belt mode (a recipe's) is set before the part is looked for."""
    _check_ready(rt)
    check_belt_mode(rt, opts)
    ctx = await context(rt)

    async def body(job: Any) -> dict[str, Any]:
        await apply_belt_mode(rt, opts)
        out = await inspect_object(ctx, opts, job, db_wait_s=opts.wait_s)
        assert out is not None  # only a run's wait can be stopped
        return {"inspection": out, "inspection_id": out["id"]}

    return rt.jobs.start("inspect", body, motion=True,
                         params={"policy": opts.policy, "sort": opts.sort, "camera_model": ctx.source,
                                 "recipe": opts.recipe_name})  # fmt: skip


def readiness(rt: CellRuntime) -> list[str]:
    """What keeps the cell from starting an inspection now (empty: ready): the camera
    failing, the arm's link down; the database is checked by :func:`hold_until_ready`."""
    why = []
    cam = rt.cell.camera_status()
    if not cam.ok:
        why.append(f"camera {cam.name}: {cam.error or 'no frames yet'}")
    st = rt.cell.state
    if not st.connected:
        why.append(f"robot link down{': ' + st.fault if st.fault else ''}")
    return why


async def hold_until_ready(rt: CellRuntime, job: Any, *, max_s: float | None = None) -> float:
    """Wait, without moving, until :func:`readiness` is empty and the database answers
    (backoff with jitter between checks); returns the seconds held.  A continuous run
    calls it before every object, so a fault holds the cell and the run goes on by itself
    when the fault clears."""
    from robot.backoff import Backoff

    b = Backoff(initial_s=0.1, max_s=2.0)
    t0 = time.monotonic()
    said = ""
    while True:
        why = readiness(rt)
        if not why and not await rt.database.ping():
            why.append("database unavailable")
        if not why:
            if said:
                log.info("cell ready again after %.1f s", time.monotonic() - t0)
                job.report(job.progress, "ready again: inspecting")
            return time.monotonic() - t0
        msg = "holding: " + "; ".join(why)
        if msg != said:
            log.warning("%s", msg)
            said = msg
        job.report(job.progress, msg)
        if max_s is not None and time.monotonic() - t0 >= max_s:
            raise Conflict(f"the cell is not ready after {max_s:g} s: {msg}")
        await b.sleep()


def start_run(
    rt: CellRuntime, opts: InspectOptions, count: int | None, *, resolve: Resolve | None = None
) -> InspectionRun:
    """Start continuous operation (a job); :func:`stop_run` ends it after the current object.

    ``resolve`` (a run following the active recipe): the options are read again before
    each object (its belt mode set then) and once the part is found, so a recipe selected
    between two objects applies to the next one; ``opts`` are those of the first."""
    if count is not None and (
        isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_COUNT
    ):
        raise InvalidInput(f"count must be an integer in 1..{MAX_COUNT} or null, got {count!r}")
    cur = rt.inspection.run
    if (
        cur is not None
        and cur.job is not None
        and cur.job.task is not None
        and not cur.job.task.done()
    ):
        raise Conflict("an inspection run is already going: stop it first")
    _check_ready(rt)
    check_belt_mode(rt, opts)
    run = InspectionRun(opts, count, resolve)

    async def body(job: Any) -> dict[str, Any]:
        ctx = await recovery.retry_database(
            "reading the calibration", lambda: context(rt), on_wait=lambda m: job.report(0.0, m)
        )
        job.report(0.0, "triangulating the models' taught top views")
        try:
            await warm_feature_heights(ctx)
        except Exception:  # the pose triangulates on first use instead
            log.warning("could not triangulate the taught views ahead of the run", exc_info=True)
        decisions: dict[str, int] = {}
        tracker = PartTracker()
        conveyor = conveyor_of(rt)
        if conveyor is not None:  # the run indexes the belt: each part waits for its release
            await conveyor.hold_at_station(True)
        try:
            while not run.stop_requested and (count is None or run.done < count):
                await hold_until_ready(rt, job)
                run.options = await resolved(resolve, run.options)
                progress = 0.0 if count is None else run.done / count
                waiting = Waiting(report=lambda m, p=progress: job.report(p, m),
                                  stopped=lambda: run.stop_requested, forever=True)  # fmt: skip
                try:
                    await apply_belt_mode(rt, run.options)
                    out = await inspect_object(ctx, run.options, None, tracker=tracker,
                                               waiting=waiting, resolve=resolve)  # fmt: skip
                except NotReady:
                    raise
                except (VisionCellError, ValueError) as exc:  # looking for a part failed
                    why = f"{getattr(exc, 'code', 'error')}: {getattr(exc, 'detail', exc)}"
                    log.warning("looking for a part: %s", why)
                    job.report(progress, f"looking for a part failed ({why}): trying again")
                    await asyncio.sleep(1.0)
                    continue
                if out is None:  # stopped while waiting for a part
                    break
                run.done += 1
                run.ids.append(out["id"])
                decisions[out["decision"]] = decisions.get(out["decision"], 0) + 1
                job.report(0.0 if count is None else run.done / count,
                           f"{run.done} inspected: {out['decision']} {out['model'] or ''}".strip())  # fmt: skip
                # A failed inspection looks at the same part again; after any other the
                # belt brings the next (index mode: the part held at the station goes on).
                if out["decision"] != "failed" and conveyor is not None and _belt(rt)[0] == "index":
                    with contextlib.suppress(Exception):
                        await conveyor.release()
        finally:
            if conveyor is not None:
                with contextlib.suppress(Exception):
                    await conveyor.hold_at_station(False)
        return {"inspected": run.done, "inspection_ids": run.ids, "decisions": decisions,
                "stopped": run.stop_requested}  # fmt: skip

    run.job = rt.jobs.start("inspection-run", body, motion=True,
                            params={"policy": opts.policy, "sort": opts.sort, "count": count,
                                    "recipe": opts.recipe_name})  # fmt: skip
    rt.inspection.run = run
    return run


def stop_run(rt: CellRuntime) -> InspectionRun:
    """Ask the run to end after the current object (:class:`Conflict` if none is going)."""
    run = rt.inspection.run
    if run is None or run.job is None or run.job.task is None or run.job.task.done():
        raise Conflict("no inspection run is going")
    run.stop_requested = True
    return run
