"""The inspection's side view passes the region of interest made from the top view
(:func:`vision.segmentation.roi.side_roi`) to recognition as the query's mask."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from backend.calibration.autoplan import NOMINAL_T_EE_CAM
from backend.inspection.context import Context
from backend.inspection.look import side_view
from backend.inspection.stopwatch import Stopwatch
from backend.planning import plan_shots
from robot.drivers.conveyor import FixedStation
from robot.kinematics import T_base_ee
from robot.sim.camera import CameraSpec
from robot.sim.world import ConveyorSpec
from tests.vision.test_segmentation_roi import H, W, _box, _inside, _silhouette
from vision.segmentation.roi import side_query


class _Cell:
    """Answers ``look(q)`` with a blank frame taken at ``q`` (the arm reached it)."""

    def __init__(self) -> None:
        self.looked: list[np.ndarray] = []

    async def look(self, q, *, speed=None):
        self.looked.append(np.asarray(q))
        return SimpleNamespace(rgb=np.zeros((H, W, 3), np.uint8), meta={},
                               robot_state=SimpleNamespace(q=np.asarray(q)))  # fmt: skip


@pytest.mark.parametrize("vp", [2, 3])
async def test_the_services_side_view_passes_the_region_as_the_query_mask(vp):
    spec = CameraSpec()
    cam, T_ee_cam = spec.pinhole, np.asarray(spec.T_ee_cam)
    belt = ConveyorSpec()
    station = np.asarray(belt.station_point, float)
    top = plan_shots(station, (1,), T_ee_cam=np.asarray(NOMINAL_T_EE_CAM), object_height_m=0.1,
                     top_rolls_rad=(0.0,))[0]  # fmt: skip
    T_top = T_base_ee(np.asarray(top.q)) @ T_ee_cam
    base = np.array([station[0], station[1], belt.surface_z_m])
    box = _box(base, (0.06, 0.05), 0.09)
    rt = SimpleNamespace(cell=_Cell(), conveyor=FixedStation())
    ctx = Context(rt, cam, T_ee_cam, "test", station, float(belt.surface_z_m))
    side = await side_view(
        ctx, vp, station, watch=Stopwatch(), T_plan=np.asarray(NOMINAL_T_EE_CAM), top_mask=_silhouette(cam, T_top, box),
        T_cam_top=T_top, height_m=0.1, travel0=None, speed=None,
    )  # fmt: skip
    assert len(rt.cell.looked) == 1
    assert side.roi.mask is not None, side.roi.reason
    assert _inside(side.roi.mask, cam, side.T_base_cam, box).all()
    assert side.roi.fraction < 0.6
    got = side_query(side.frame.rgb, side.roi)
    assert isinstance(got, tuple) and got[1].shape == (H, W) and got[1].any()
