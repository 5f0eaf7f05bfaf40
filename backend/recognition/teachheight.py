"""A teach's measurement of the part's height (step 4 of :mod:`backend.recognition.teach`).

From the features the top views at their rolls share (triangulated), else from the top
view's and the side views' regions (:mod:`backend.recognition.geometry`); stored with the
model unless an engineer entered one.  A top-only teach takes one side view more for this
alone (:func:`geometry_shot`).
"""

from __future__ import annotations

import asyncio
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend.db.session import Database
from backend.planning import Shot, plan_shots
from backend.recognition.geometry import (
    HeightMeasurement,
    Silhouette,
    TopShot,
    height_from_features,
    measure_height,
)
from backend.recognition.index import IndexedModel, LiveIndex
from backend.recognition.models import get_model, set_measured_geometry
from robot.collision import CollisionWorld
from vision.camera import PinholeCamera
from vision.errors import VisionCellError

__all__ = ["geometry_shot", "measure", "store_geometry"]


def geometry_shot(
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


async def measure(
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


async def store_geometry(
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
