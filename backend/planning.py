"""The station's planning layer, shared by teaching and inspecting.

Teaching (:mod:`backend.recognition.teach`) and inspecting (:mod:`backend.inspection`) both
stand on this module and on neither of each other:

- :func:`plan_shots`: the shots at the station (viewpoints planned by
  :func:`robot.viewpoints.plan_viewpoints`, the top view at several camera rolls), so an
  inspection's top view is the teach's and the empty-belt background grabbed by a teach
  applies to it;
- :class:`BackgroundStore`: the empty-belt image of each shot, by its joints;
- :func:`mounting_or_nominal`: the camera mounting the plans use, the cell's active
  hand-eye calibration, else the drawing's nominal one (the shots, and so their stored
  backgrounds, stay the same until a hand-eye calibration is activated);
- :func:`station_top`: the top view at the station as an inspection plans it.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from robot.viewpoints import VIEW_NAMES, plan_viewpoints

if TYPE_CHECKING:
    from robot.collision import CollisionWorld

__all__ = [
    "AIM_HEIGHT_M",
    "BackgroundStore",
    "Shot",
    "mounting_or_nominal",
    "plan_shots",
    "station_top",
]

#: Aiming height of the viewpoints (the teach's default object height), metres.
AIM_HEIGHT_M = 0.1


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


def mounting_or_nominal(T_ee_cam: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """``T_ee_cam`` (an active hand-eye calibration's), else the drawing's nominal mounting."""
    from backend.calibration import NOMINAL_T_EE_CAM

    return np.asarray(NOMINAL_T_EE_CAM if T_ee_cam is None else T_ee_cam, dtype=np.float64)


async def station_top(station: NDArray[np.float64], T_plan: NDArray[np.float64]) -> Shot:
    """The top view (viewpoint 1, roll 0) at ``station``, planned with ``T_plan`` at
    :data:`AIM_HEIGHT_M` as a teach plans it (in a worker thread)."""
    shots = await asyncio.to_thread(plan_shots, station, (1,), T_ee_cam=T_plan,
                                    object_height_m=AIM_HEIGHT_M, top_rolls_rad=(0.0,))  # fmt: skip
    return shots[0]
