"""What an inspection reads from the cell, once: :class:`Context` (camera model and
mounting, station, belt) and :class:`TopPlan` (the top view, the plan's mounting, the
thresholds in force, the empty-belt background); helpers every stage uses."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import NDArray

from backend.inspection.errors import NOT_TRAINED, NotReady
from backend.planning import Shot, mounting_or_nominal, station_top
from backend.recognition import thresholds
from backend.recognition.images import encode_jpeg
from robot.kinematics import T_base_ee

if TYPE_CHECKING:
    from backend.runtime import CellRuntime

__all__ = ["Context", "TopPlan", "belt_state", "cam_pose", "context", "draw", "read_plan",
           "station_px", "travel_of", "truth_near"]  # fmt: skip


@dataclass
class Context:
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
    #: The active hand-eye calibration's mounting, which the station's shots are planned
    #: with (None: the nominal one, :func:`backend.planning.mounting_or_nominal`).
    T_plan: NDArray[np.float64] | None = None


async def context(rt: CellRuntime) -> Context:
    """Camera model and mounting: the cell's active calibrations, else the camera's exact
    nominal ones (the simulator's), else the drawing's (reported in ``source``); the
    station, its surface and the belt's end from the cell's layout; the mounting the shots
    are planned with (the active hand-eye calibration, else the drawing's: the teach's
    shots and backgrounds).  The calibration is read once, for all of them."""
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
    return Context(rt, camera, np.asarray(T, dtype=np.float64), ", ".join(src),
                   layout.station_point, float(layout.surface_z_m), why,
                   math.inf if end is None else float(end),
                   None if cal.T_ee_cam is None else np.asarray(cal.T_ee_cam, np.float64))  # fmt: skip


@dataclass(frozen=True, eq=False)
class TopPlan:
    """The top view at the station, the plan's mounting, the thresholds in force and the
    empty-belt background of that view (read once per inspection by :func:`read_plan`)."""

    top: Shot
    T_plan: NDArray[np.float64]
    choice: Any
    bg: NDArray[np.uint8] | None


async def read_plan(ctx: Context) -> TopPlan:
    """:class:`TopPlan` (the thresholds read from the database, the mounting the context
    read); :class:`NotReady` when nothing is trained or the top view has no empty-belt
    background (a setup step missing: no inspection, no row)."""
    rt = ctx.rt
    if len(rt.live_index) == 0:
        raise NotReady(NOT_TRAINED)
    T_plan = mounting_or_nominal(ctx.T_plan)
    async with rt.database.session() as session:
        choice = await thresholds.current_choice(session)
    top = await station_top(ctx.station, T_plan)
    bg = rt.teach_backgrounds.get(top)
    # A real or recorded camera may have models imported or uploaded and no teach (so no
    # background): its top view is recognised whole.  The simulated camera is always taught.
    if bg is None and rt.cell.camera_status().name == "sim":
        raise NotReady(
            "no empty-belt background of the top view at the station: teach a model first"
        )
    return TopPlan(top, T_plan, choice, bg)


def belt_state(rt: CellRuntime) -> tuple[str, float, float]:
    """(mode, speed m/s, travel m) of the cell's conveyor: ``continuous`` only while it runs
    at a speed (its encoder gives the travel); a fixed station is ``index`` at 0 m."""
    st = rt.conveyor.status()
    moving = st.running and st.mode == "continuous" and st.speed_m_s > 0
    return ("continuous" if moving else "index"), float(st.speed_m_s), float(st.travel_m)


def cam_pose(q: Any, T_ee_cam: NDArray[np.float64]) -> NDArray[np.float64]:
    """The camera's pose in the base frame at joints ``q``."""
    return T_base_ee(np.asarray(q, dtype=np.float64)) @ T_ee_cam


def travel_of(frame: Any, rt: CellRuntime) -> float:
    """The belt's travel at the frame's exposure: the encoder count latched with it
    (``meta["belt_travel_m"]``), else the conveyor's encoder at its exposure time."""
    t = frame.meta.get("belt_travel_m")
    if isinstance(t, int | float) and math.isfinite(t):
        return float(t)
    stamp = getattr(frame, "stamp_s", None)
    return float(rt.conveyor.travel_at(stamp if isinstance(stamp, float) else None))


def truth_near(rt: CellRuntime, point: NDArray[np.float64],
               back_m: float = 0.0) -> dict[str, Any] | None:  # fmt: skip
    """For evaluation only, where the cell knows it (the simulator): the object nearest
    ``point`` (never read by decisions), moved back ``back_m`` along the belt (its travel
    since the exposure)."""
    truth = rt.truth
    return None if truth is None else truth.object_near(point, back_m)


def station_px(ctx: Context, T_cam: NDArray[np.float64], z_m: float) -> NDArray[np.float64]:
    """Where the station (at height ``z_m``) is in the image of a camera at ``T_cam``."""
    p = ctx.station.copy()
    p[2] = z_m
    return ctx.camera.project_world(p[None, :], np.linalg.inv(T_cam))[0]


def draw(rgb: NDArray[np.uint8], mask: NDArray[np.bool_] | None, label: str) -> bytes:
    """The stored image of a view: its region's contour and ``label`` drawn, as JPEG."""
    img = rgb.copy()
    if mask is not None and mask.any():
        cs, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(img, cs, -1, (0, 255, 0), 2)
    cv2.putText(img, label, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 0), 2)
    return encode_jpeg(img)
