"""Teaching a model with the arm: the chapter's training of section 3.5,
done by the cell.

With the object at the station the job

1. plans the viewpoints from the station point (:func:`robot.viewpoints.
   plan_viewpoints`, the planner inspections use): the top view (1) for a ``2d`` model; the
   top and the two side views (2 inner, 3 outer) for a ``3d`` one.  The top view is taken at
   several camera rolls about the optical axis (joint q5, :data:`TOP_ROLLS_RAD`), so a model
   is recognised at any yaw on the belt (how many was chosen by measurement: ``python -m
   benchmarks.teach_yaw``);
2. has an empty-belt background for each shot: grabbed first (``background="grab"``: the
   station must be empty; the job then waits until an object has arrived and lies still) or
   taken from an earlier teach with the same shots (``background="stored"``);
3. visits each shot (move, settle, and a frame exposed after the arm was still:
   ``cell.look``), segments the object with the active contour initialised from the
   background difference (:mod:`backend.recognition.segment`), extracts the features inside
   the object's region and stores the trained view (image, mask, features, joints, camera
   pose) in one transaction with the others, then in the live index;
4. measures the part's height (:mod:`backend.recognition.geometry`): from the features
   the top views at their three rolls share (triangulated), else from the top view's and
   the side views' regions (a 2d model's teach takes one side view more for this alone),
   and stores it with the model unless an engineer entered one: the pick needs it.  When
   it cannot be measured the result says so and the console asks for it;
5. recomputes the automatic threshold (:mod:`backend.recognition.thresholds`) and reports
   the models confusable from the top, with what to add when the views are too few.

Progress is reported per shot.  Nothing is stored unless every shot succeeded.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from backend import audit
from backend.db.session import Database
from backend.heavy import HeavyPool
from backend.recognition import thresholds
from backend.recognition.autothreshold import ThresholdKeeper
from backend.recognition.geometry import (
    HeightMeasurement,
    Silhouette,
    TopShot,
    height_from_features,
    measure_height,
)
from backend.recognition.index import IndexedModel, LiveIndex
from backend.recognition.models import get_model, set_measured_geometry, taught_rounds
from backend.recognition.segment import SegmentationFailed, foreground_mask, segment_object
from backend.recognition.views import ViewInput, add_views, view_public
from robot.collision import CollisionWorld
from robot.kinematics import T_base_ee
from robot.viewpoints import VIEW_NAMES, plan_viewpoints
from vision.camera import PinholeCamera
from vision.errors import Conflict, InvalidInput, VisionCellError
from vision.features.types import Features
from vision.segmentation import iou

__all__ = [
    "TOP_ROLLS_RAD",
    "BackgroundStore",
    "Shot",
    "TeachOptions",
    "TeachTimeout",
    "plan_shots",
    "rounds_guide",
    "run_teach",
    "teach_yaws_rad",
]

#: Camera rolls (q5 offsets, radians) of the top view: 0 and +-120 deg cover the circle in
#: thirds within q5's +-165.75 deg.  Measured (``benchmarks/teach_yaw.py``, 12 objects at 48
#: random yaws): one roll names 100 % with the object's own score at median 0.39, three
#: rolls 100 % at 0.47 (p10 0.034 -> 0.052): a wider margin above the threshold.
TOP_ROLLS_RAD = (0.0, math.radians(120.0), math.radians(-120.0))
#: Longest a teach waits for an object to arrive after grabbing the background, seconds.
MAX_WAIT_S = 600.0
#: Most teach rounds (object yaws) of one model.
MAX_ROUNDS = 12


def teach_yaws_rad(rounds: int) -> tuple[float, ...]:
    """Object yaws of ``rounds`` teach rounds (the operator or the simulator turns the object
    between rounds, :attr:`TeachOptions.yaw_rad`): ``k * 360 / rounds`` deg, k = 0 ..
    rounds-1, in (-180, 180], spread evenly over the whole turn.

    Other spreads were measured and lost (``benchmarks.recognition_yaw --teach-yaws 4
    --queries 3``, seeds 0, 1 and 2, side ROI and own bars on, 108 trained and 18 untrained
    queries; untrained all unknown in every plan): this plan (0, 90, 180, -90 deg) named
    108; the half turn (0, 45, 90, 135: every round shows the side views a new pair of
    faces, whereas here a 180 deg turn only swaps them) 106; a plan whose top rotations
    (yaw + camera roll, :data:`TOP_ROLLS_RAD`) tile the circle every 30 deg with four
    pairs of side faces (0, 30, -60, 90; ``--teach-yaws-deg``) 106, one of its misses a
    wrong twin.  Both raise the automatic top threshold from 0.107 to 0.131 (the largest
    impostor top score), and the objects they miss scored below it from the top.  With
    3, 6, 9 or 12 rounds this plan repeats the rolls' rotations (0, 120, -120 deg teach the
    top view three rotations thrice); those counts were not measured.

    Raises ``InvalidInput`` unless ``rounds`` is an integer in 1..:data:`MAX_ROUNDS`.
    """
    if isinstance(rounds, bool) or not isinstance(rounds, int) or not 1 <= rounds <= MAX_ROUNDS:
        raise InvalidInput(f"rounds must be an integer in 1..{MAX_ROUNDS}, got {rounds!r}")
    return tuple(math.remainder(2.0 * math.pi * k / rounds, 2.0 * math.pi) for k in range(rounds))


class TeachTimeout(VisionCellError):
    """No object arrived at the station in time."""

    code = "teach_timeout"


@dataclass(frozen=True)
class TeachOptions:
    """How to teach.

    Attributes
    ----------
    viewpoints : tuple of int, optional
        Viewpoints to take (default: ``(1,)`` for 2d models, ``(1, 2, 3)`` for 3d).
    top_rolls_rad : tuple of float
        Camera rolls of the top view, radians (each within +-pi).
    background : {"grab", "stored"}
        Grab the empty-belt backgrounds first, or use those of an earlier teach.
    object_height_m : float
        Rough height of the object (aims the camera at its top face), metres.
    yaw_rad : float
        The object's yaw relative to its taught pose, when an operator turned it by hand
        for another round of views (stored with the views); :func:`teach_yaws_rad` gives
        the yaws of a given number of rounds (over the whole turn).
    speed : float, optional
        Arm speed fraction (default: the cell's).
    wait_s : float
        With ``background="grab"``: longest wait for the object, seconds.
    replace : bool
        Delete the model's earlier views (in the same transaction as storing the new ones).
    threshold : bool
        Recompute the automatic threshold after storing (default).  ``False`` when more
        rounds of the same teach follow at once (the object turned by hand between rounds):
        the last round recomputes, so the choice is made once over all of them instead of
        after each (it re-runs recognition on every trained view).
    """

    viewpoints: tuple[int, ...] | None = None
    top_rolls_rad: tuple[float, ...] = TOP_ROLLS_RAD
    background: Literal["grab", "stored"] = "grab"
    object_height_m: float = 0.1
    yaw_rad: float = 0.0
    speed: float | None = None
    wait_s: float = 120.0
    replace: bool = False
    threshold: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.threshold, bool):
            raise InvalidInput(f"threshold must be true or false, got {self.threshold!r}")
        if self.viewpoints is not None:
            vps = tuple(self.viewpoints)
            if (
                not vps
                or len(set(vps)) != len(vps)
                or any(isinstance(v, bool) or v not in (1, 2, 3) for v in vps)
            ):
                raise InvalidInput(f"viewpoints must be distinct values of 1, 2, 3, got {vps!r}")
            object.__setattr__(self, "viewpoints", tuple(sorted(vps)))
        rolls = tuple(float(r) for r in self.top_rolls_rad)
        if not 1 <= len(rolls) <= 12 or not all(
            math.isfinite(r) and abs(r) <= math.pi for r in rolls
        ):
            raise InvalidInput(f"top_rolls_rad must be 1 to 12 angles within +-pi, got {rolls!r}")
        object.__setattr__(self, "top_rolls_rad", rolls)
        if self.background not in ("grab", "stored"):
            raise InvalidInput(f"background must be 'grab' or 'stored', got {self.background!r}")
        h = self.object_height_m
        if isinstance(h, bool) or not (math.isfinite(h) and 0.0 < h <= 0.5):
            raise InvalidInput(f"object_height_m must be in (0, 0.5] m, got {h!r}")
        if not (math.isfinite(self.yaw_rad) and abs(self.yaw_rad) <= math.pi):
            raise InvalidInput(f"yaw_rad must be within +-pi, got {self.yaw_rad!r}")
        if not (math.isfinite(self.wait_s) and 0.0 <= self.wait_s <= MAX_WAIT_S):
            raise InvalidInput(f"wait_s must be in [0, {MAX_WAIT_S:g}] s, got {self.wait_s!r}")
        if self.speed is not None and not (math.isfinite(self.speed) and 0.0 < self.speed <= 1.0):
            raise InvalidInput(f"speed must be in (0, 1], got {self.speed!r}")


@dataclass(frozen=True)
class Shot:
    """One image to take: viewpoint, camera roll and the joints that give them."""

    viewpoint: int
    name: str
    roll_rad: float
    q: NDArray[np.float64]
    T_base_cam: NDArray[np.float64]
    reason: str = ""
    """Why the planner replaced the nominal viewpoint (empty when it did not)."""
    geometry_only: bool = False
    """Taken only to measure the part's height (a 2d model's side view): not stored."""

    @property
    def key(self) -> tuple[float, ...]:
        """Joints rounded to 0.1 mrad: the same shot on another teach has the same key."""
        return tuple(round(float(v), 4) for v in self.q)


def plan_shots(
    point: NDArray[np.float64],
    viewpoints: tuple[int, ...],
    *,
    T_ee_cam: NDArray[np.float64],
    object_height_m: float,
    top_rolls_rad: tuple[float, ...],
    world: CollisionWorld | None = None,
) -> list[Shot]:
    """The shots of a teach at ``point`` (base frame): the top view at every roll, then
    the side views (roll 0)."""
    shots: list[Shot] = []
    for vp in viewpoints:
        name = VIEW_NAMES[vp - 1]
        rolls = top_rolls_rad if vp == 1 else (0.0,)
        for roll in rolls:
            plan = plan_viewpoints(
                point,
                T_ee_cam=T_ee_cam,
                views=(name,),
                object_height_m=object_height_m,
                roll_rad=roll,
                world=world,
            )
            v = plan.views[0]
            shots.append(Shot(vp, name, roll, v.q, v.T_base_cam, v.reason))
    return shots


@dataclass
class BackgroundStore:
    """Empty-belt images per shot (by joints), kept for later teaches of this cell."""

    images: dict[tuple[float, ...], NDArray[np.uint8]] = field(default_factory=dict)
    taken_at: float = 0.0
    #: Called with (key, image) after every :meth:`put` (the runtime stores it durably).
    on_put: Callable[[tuple[float, ...], NDArray[np.uint8]], None] | None = None

    def get(self, shot: Shot) -> NDArray[np.uint8] | None:
        return self.images.get(shot.key)

    def put(self, shot: Shot, image: NDArray[np.uint8]) -> None:
        self.images[shot.key] = image
        self.taken_at = time.time()
        if self.on_put is not None:
            self.on_put(shot.key, image)


async def _wait_for_object(
    cell: Any, shot: Shot, background: NDArray[np.uint8], wait_s: float, job: Any
) -> None:
    """Watch the top view until an object lies still at the station."""
    deadline = time.monotonic() + wait_s
    last: NDArray[np.bool_] | None = None
    job.report(job.progress, "waiting for an object at the station")
    while True:
        frame = await cell.look(None)
        try:
            mask = await asyncio.to_thread(foreground_mask, frame.rgb, background)
        except SegmentationFailed:
            mask = None
        if mask is not None and last is not None and iou(mask, last) > 0.97:
            return  # there, and not moving
        last = mask
        if time.monotonic() >= deadline:
            raise TeachTimeout(
                f"no object lay still at the station within {wait_s:g} s of grabbing the "
                "background; place the object and teach again with background='stored'"
            )
        await asyncio.sleep(0.3)


async def run_teach(
    job: Any,
    *,
    cell: Any,
    db: Database,
    live: LiveIndex,
    model_id: int,
    options: TeachOptions,
    point: NDArray[np.float64],
    T_ee_cam: NDArray[np.float64],
    store: BackgroundStore,
    world: CollisionWorld | None = None,
    by: audit.By | None = None,
    heavy: HeavyPool | None = None,
    camera: PinholeCamera | None = None,
    T_ee_cam_seen: NDArray[np.float64] | None = None,
    keeper: ThresholdKeeper | None = None,
) -> dict[str, Any]:
    """The teach job's body (module docstring); runs holding the arm.

    Parameters
    ----------
    job : Job
        For progress reports.
    cell : Cell
        Provides ``await cell.look(q, speed=...)`` (move, settle, fresh frame).
    point : ndarray of shape (3,)
        The station point (footprint centre of the object), base frame, metres.
    T_ee_cam : ndarray of shape (4, 4)
        Camera mounting (the active hand-eye calibration, or the nominal one).
    store : BackgroundStore
        Backgrounds of earlier teaches (read for ``"stored"``, written for ``"grab"``).
    camera : PinholeCamera, optional
        The camera model, for measuring the part's height (default: the nominal lens for
        the frames' size).
    T_ee_cam_seen : ndarray of shape (4, 4), optional
        The camera mounting the images are measured with (default ``T_ee_cam``): the
        planner keeps the nominal mounting so the shots (and their stored backgrounds)
        stay the same, the measurement needs the best one known.
    keeper : ThresholdKeeper, optional
        The cell's automatic threshold keeper: held while the teach runs, and the choice
        at its end is made through it (the same choice the keeper would make, once).
    """
    if keeper is None:
        return await _teach(job, cell=cell, db=db, live=live, model_id=model_id,
                            options=options, point=point, T_ee_cam=T_ee_cam, store=store,
                            world=world, by=by, heavy=heavy, camera=camera,
                            T_ee_cam_seen=T_ee_cam_seen, keeper=None)  # fmt: skip
    async with keeper.holding():
        return await _teach(job, cell=cell, db=db, live=live, model_id=model_id,
                            options=options, point=point, T_ee_cam=T_ee_cam, store=store,
                            world=world, by=by, heavy=heavy, camera=camera,
                            T_ee_cam_seen=T_ee_cam_seen, keeper=keeper)  # fmt: skip


async def _teach(
    job: Any,
    *,
    cell: Any,
    db: Database,
    live: LiveIndex,
    model_id: int,
    options: TeachOptions,
    point: NDArray[np.float64],
    T_ee_cam: NDArray[np.float64],
    store: BackgroundStore,
    world: CollisionWorld | None,
    by: audit.By | None,
    heavy: HeavyPool | None,
    camera: PinholeCamera | None,
    T_ee_cam_seen: NDArray[np.float64] | None,
    keeper: ThresholdKeeper | None,
) -> dict[str, Any]:
    T_seen = np.asarray(T_ee_cam if T_ee_cam_seen is None else T_ee_cam_seen, dtype=np.float64)
    async with db.session() as session:
        model = await get_model(session, model_id)
        kind, name = model.kind.value, model.name
    vps = options.viewpoints or ((1,) if kind == "2d" else (1, 2, 3))
    shots = await asyncio.to_thread(
        plan_shots,
        point,
        vps,
        T_ee_cam=T_ee_cam,
        object_height_m=options.object_height_m,
        top_rolls_rad=options.top_rolls_rad,
        world=world,
    )
    if 1 in vps and not any(s.viewpoint in (2, 3) for s in shots):
        # No side view among the views to store: one more, for the height alone.
        extra = await asyncio.to_thread(
            _geometry_shot, point, T_ee_cam, options.object_height_m, world
        )
        if extra is not None and (options.background == "grab" or store.get(extra) is not None):
            shots.append(extra)
    n = len(shots)
    steps = 2 * n if options.background == "grab" else n
    done = 0
    backgrounds: dict[int, NDArray[np.uint8]] = {}
    if options.background == "grab":
        for k, shot in enumerate(shots):
            job.report(done / steps, f"background {k + 1}/{n}: viewpoint {shot.viewpoint}")
            frame = await cell.look(shot.q, speed=options.speed)
            backgrounds[k] = frame.rgb
            store.put(shot, frame.rgb)
            done += 1
        first = await cell.look(shots[0].q, speed=options.speed)
        await _wait_for_object(cell, shots[0], backgrounds[0], options.wait_s, job)
        del first
    else:
        for k, shot in enumerate(shots):
            bg = store.get(shot)
            if bg is None:
                raise InvalidInput(
                    f"no stored background for viewpoint {shot.viewpoint} at roll "
                    f"{math.degrees(shot.roll_rad):.0f} deg: teach once with background='grab'"
                )
            backgrounds[k] = bg
    inputs: list[ViewInput] = []
    shots_out: list[dict[str, Any]] = []
    silhouettes: list[tuple[Shot, Silhouette]] = []
    frame_size: tuple[int, int] = (640, 480)
    for k, shot in enumerate(shots):
        job.report(
            done / steps,
            f"view {k + 1}/{n}: viewpoint {shot.viewpoint}, "
            f"roll {math.degrees(shot.roll_rad):.0f} deg",
        )
        t0 = time.monotonic()
        frame = await cell.look(shot.q, speed=options.speed)
        t1 = time.monotonic()
        try:
            region = await asyncio.to_thread(segment_object, frame.rgb, backgrounds[k])
        except SegmentationFailed as exc:
            raise SegmentationFailed(f"viewpoint {shot.viewpoint}: {exc.detail}") from exc
        mask = region.mask
        state = frame.robot_state
        q_seen = np.asarray(getattr(state, "q", shot.q), dtype=np.float64)
        frame_size = (int(frame.rgb.shape[1]), int(frame.rgb.shape[0]))
        silhouettes.append((shot, Silhouette(mask, T_base_ee(q_seen) @ T_seen)))
        shots_out.append(
            {
                "viewpoint": shot.viewpoint,
                "roll_rad": shot.roll_rad,
                "joints": [float(v) for v in q_seen],
                "mask_px": int(mask.sum()),
                "segmentation": region.method,
                "segmentation_note": region.note,
                "planner": shot.reason,
                "look_s": round(t1 - t0, 3),
                "segment_s": round(time.monotonic() - t1, 3),
                "geometry_only": shot.geometry_only,
            }
        )
        done += 1
        if shot.geometry_only:
            continue
        inputs.append(
            ViewInput(
                frame.rgb,
                shot.viewpoint,
                mask,
                yaw_rad=options.yaw_rad,
                roll_rad=shot.roll_rad,
                source="teach",
                joints=q_seen,
                T_base_cam=shot.T_base_cam,
                name=f"viewpoint {shot.viewpoint} roll {math.degrees(shot.roll_rad):.0f} deg",
            )
        )
    job.report(done / steps, "storing the views")
    rows = await add_views(db, live, model_id, inputs, replace=options.replace, by=by)
    job.report(done / steps, "measuring the part's height")
    stored = [s for s in silhouettes if not s[0].geometry_only]
    tops = [
        TopShot(Features.from_bytes(r.features), sil.T_base_cam)
        for r, (shot, sil) in zip(rows, stored, strict=True)
        if shot.viewpoint == 1 and r.viewpoint == 1
    ]
    geometry = await _measure(silhouettes, tops, camera, frame_size, float(point[2]))
    geometry_out = await _store_geometry(db, live, model_id, geometry)
    async with db.session() as session:
        taught = (await taught_rounds(session, [model_id]))[model_id]
    if not options.threshold:
        outcome = await thresholds.deferred(db)
    elif keeper is not None:
        job.report(1.0, "choosing the threshold")
        outcome = await keeper.choose(
            lambda f, msg: job.report(1.0, f"choosing the threshold: {msg}")
        )
    else:
        job.report(1.0, "choosing the threshold")
        outcome = await thresholds.recompute(db, live, heavy=heavy)
    return {
        "model": {"id": model_id, "name": name, "kind": kind},
        "views": [view_public(r) for r in rows],
        "shots": shots_out,
        "geometry": geometry_out,
        "threshold": outcome.public(),
        "confusable_from_top": list(outcome.confusable),
        "rounds": rounds_guide(taught, thresholds.recommended_rounds(kind)),
    }


def rounds_guide(taught: int, recommended: int) -> dict[str, Any]:
    """Where a model stands in its teach rounds (:data:`~backend.recognition.thresholds.
    RECOMMENDED_ROUNDS` for its kind), for the wizard and the CLI: ``taught``,
    ``recommended``, and while rounds remain ``next_round`` (1-based) and ``next_yaw_deg``,
    the yaw to turn the object to, from its first round's pose (:func:`teach_yaws_rad`)."""
    out: dict[str, Any] = {"taught": taught, "recommended": recommended,
                           "next_round": None, "next_yaw_deg": None}  # fmt: skip
    if taught < recommended:
        out["next_round"] = taught + 1
        out["next_yaw_deg"] = round(math.degrees(teach_yaws_rad(recommended)[taught]), 1)
    return out


def check_live_camera(cell: Any) -> None:
    """Refuse (409) a teach on a camera that replays a recording (the folder camera, a video
    file): the arm cannot make it look at the object at the station, and a replay never
    shows an object lying still on an empty belt.  Recorded images become trained views by
    import instead."""
    cam = getattr(getattr(cell, "feed", None), "camera", None)
    if getattr(cam, "recorded", False) is True:
        raise Conflict(
            f"the {getattr(cam, 'name', 'recorded')} camera replays recorded images: a teach "
            "needs a live camera the arm points at the object.  Import the images as trained "
            "views instead: `visioncell models import NAME FOLDER` (or POST "
            "/api/models/{id}/views)"
        )


def _geometry_shot(
    point: NDArray[np.float64],
    T_ee_cam: NDArray[np.float64],
    object_height_m: float,
    world: CollisionWorld | None,
) -> Shot | None:
    """The side view a top-only teach takes to measure the part's height (the inner side
    view, else the outer one; None when neither can be planned)."""
    for vp in (2, 3):
        try:
            (shot,) = plan_shots(point, (vp,), T_ee_cam=T_ee_cam, object_height_m=object_height_m,
                                 top_rolls_rad=(0.0,), world=world)  # fmt: skip
        except VisionCellError:
            continue
        return replace(shot, geometry_only=True)
    return None


async def _measure(
    silhouettes: list[tuple[Shot, Silhouette]],
    top_shots: list[TopShot],
    camera: PinholeCamera | None,
    frame_size: tuple[int, int],
    surface_z_m: float,
) -> HeightMeasurement:
    """The part's height (:mod:`backend.recognition.geometry`): from the top views'
    triangulated features, else from the first top view's and the side views' regions."""
    if camera is None:
        from backend.calibration import nominal_camera

        camera = nominal_camera(*frame_size)
    notes: list[str] = []
    if len(top_shots) >= 2:
        try:
            got = await asyncio.to_thread(height_from_features, top_shots[:24], camera,
                                          surface_z_m=surface_z_m)  # fmt: skip
        except (VisionCellError, ValueError) as exc:
            notes.append(f"features: {exc}")
        else:
            if got.height_m is not None:
                return got
            notes.append(got.note)
    else:
        notes.append("one top view: nothing to triangulate")
    tops = [s for shot, s in silhouettes if shot.viewpoint == 1]
    sides = [s for shot, s in silhouettes if shot.viewpoint in (2, 3)][:4]
    if not tops or not sides:
        return HeightMeasurement(None, (), (0.0, 0.0), "; ".join([*notes, "no side view"]))
    try:
        got = await asyncio.to_thread(measure_height, tops[0], sides, camera,
                                      surface_z_m=surface_z_m)  # fmt: skip
    except VisionCellError as exc:
        return HeightMeasurement(None, (), (0.0, 0.0), "; ".join([*notes, exc.detail]))
    return replace(got, note="; ".join([*notes, got.note]))


async def _store_geometry(
    db: Database, live: LiveIndex, model_id: int, got: HeightMeasurement
) -> dict[str, Any]:
    """Store a measured height with the model (unless an engineer entered one) and say what
    the model has now; ``needed`` is True when it has no height (the console asks)."""
    out: dict[str, Any] = {"measured": got.public(), "stored": False}
    if got.height_m is not None:
        row = await set_measured_geometry(db, model_id, got.height_m, None)
        out["stored"] = row is not None
    async with db.session() as session:
        row = await get_model(session, model_id)
    live.put_model(IndexedModel.of(row))
    out.update(height_m=row.height_m, source=row.geometry_source or "",
               needed=row.height_m is None)  # fmt: skip
    if row.height_m is None:
        out["ask"] = (f"The part's height could not be measured ({got.note}). Enter it (mm) so "
                      "the cell can pick the part into its bin.")  # fmt: skip
    return out


async def start_teach(
    *,
    cell: Any,
    db: Database,
    live: LiveIndex,
    model_id: int,
    options: TeachOptions,
    store: BackgroundStore,
    point: NDArray[np.float64] | None = None,
    by: audit.By | None = None,
    heavy: HeavyPool | None = None,
    camera: PinholeCamera | None = None,
    mounting: NDArray[np.float64] | None = None,
    keeper: ThresholdKeeper | None = None,
) -> Any:
    """Check what can be checked at once (the model exists, the arm is free), then start
    the teach as a motion job; returns the job.  ``heavy`` (the runtime's heavy-work pool)
    runs the threshold choice at its end, or ``keeper`` (the cell's automatic threshold
    keeper, held while the teach runs) makes it.

    ``point`` defaults to the station point of the cell's conveyor; the camera mounting is
    the active hand-eye calibration of the cell, else the nominal one; the camera model
    and mounting the part's height is measured with: the active calibration, else
    ``camera`` and ``mounting`` (the simulator's nominal ones, as inspections take them),
    else the nominal lens and mounting.
    """
    from backend.calibration import NOMINAL_T_EE_CAM, active_camera_calibration
    from robot.cellworld import CellLayout

    async with db.session() as session:
        await get_model(session, model_id)
        cell_id = getattr(cell, "db_id", None)
        T_ee_cam = None
        if cell_id is not None:
            cal = await active_camera_calibration(session, cell_id)
            T_ee_cam = cal.T_ee_cam
            camera = cal.camera or camera
    T = np.asarray(NOMINAL_T_EE_CAM if T_ee_cam is None else T_ee_cam, dtype=np.float64)
    T_seen = T if T_ee_cam is not None or mounting is None else np.asarray(mounting, np.float64)
    p = np.asarray(CellLayout().station_point if point is None else point, dtype=np.float64)
    if p.shape != (3,) or not np.all(np.isfinite(p)) or np.linalg.norm(p[:2]) > 1.6:
        raise InvalidInput(
            f"point must be 3 finite coordinates within 1.6 m of the column, got {p}"
        )
    cell.check_can_move()
    check_live_camera(cell)

    async def body(job: Any) -> dict[str, Any]:
        return await run_teach(
            job,
            cell=cell,
            db=db,
            live=live,
            model_id=model_id,
            options=options,
            point=p,
            T_ee_cam=T,
            store=store,
            by=by,
            heavy=heavy,
            camera=camera,
            T_ee_cam_seen=T_seen,
            keeper=keeper,
        )

    params = {
        "model_id": model_id,
        "background": options.background,
        "viewpoints": list(options.viewpoints) if options.viewpoints else None,
        "top_rolls_rad": list(options.top_rolls_rad),
        "point": [float(v) for v in p],
        "hand_eye": "active" if T_ee_cam is not None else "nominal",
    }
    return cell.jobs.start("teach", body, motion=True, params=params)
