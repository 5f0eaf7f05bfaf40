"""Segmentation renders: the geom id at each pixel, and object masks in the camera image."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robot.errors import SimError
from robot.sim.catalogue import WHEELS
from robot.sim.imaging import capture, geom_id_image, object_masks
from robot.sim.poses import viewpoint
from vision.camera import PinholeCamera
from vision.segmentation import iou, mask_from_contour


def _top_view(engine, name: str, yaw_deg: float = 20.0):
    engine.clear_objects()
    belt = engine.config.layout.conveyor
    obj = engine.spawn(name, s_m=belt.station_s_m, yaw_rad=math.radians(yaw_deg))
    top = WHEELS[name][1].width_m
    q = viewpoint(belt.station_point + np.array([0.0, 0.0, top]), "top", distance_m=0.55)
    return obj, q


def test_wheel_mask_matches_the_projected_tread_edge(engine):
    """The mask is the silhouette the true camera model predicts: from above, a wheel's
    outline is the upper edge of its tread (radius R at height W - shoulder radius)."""
    obj, q = _top_view(engine, "wheel-5spoke")
    shot = capture(engine, q)
    mask = object_masks(engine, shot.snapshot)[obj.id]
    assert mask.shape == shot.rgb.shape[:2] and mask.dtype == bool
    d = WHEELS["wheel-5spoke"][1]
    t = np.linspace(0.0, 2.0 * math.pi, 360, endpoint=False)
    z = d.width_m - 0.28 * d.width_m
    rim = np.stack(
        [d.radius_m * np.cos(t), d.radius_m * np.sin(t), np.full_like(t, z), np.ones_like(t)]
    )
    pts = (obj.T_base_obj @ rim)[:3].T
    cam = engine.truth.camera
    uv = PinholeCamera(cam.K, cam.dist).project_world(
        pts, np.linalg.inv(engine.truth.T_base_cam(q))
    )
    predicted = mask_from_contour(uv, mask.shape)
    assert iou(mask, predicted) > 0.98
    # The rest of the image (belt, table) is other geoms; the wheel is nowhere else.
    labels = geom_id_image(engine, shot.snapshot)
    assert set(np.unique(labels[mask])) <= set(engine.object_geoms(obj.id).tolist())
    assert (labels[~mask] >= 0).mean() > 0.9


def test_removed_object_leaves_no_pixels_and_masks_follow_the_ids(engine):
    a, q = _top_view(engine, "wheel-steel")
    engine.set_joints(q)
    geoms = engine.object_geoms(a.id)
    assert object_masks(engine)[a.id].sum() > 10_000
    engine.remove(a.id)
    labels = geom_id_image(engine)
    assert not np.isin(labels, geoms).any()  # hidden (alpha 0) slot geoms are not drawn
    with pytest.raises(SimError, match="no object with id"):
        object_masks(engine, ids=[a.id])


def test_two_objects_get_disjoint_masks(engine):
    engine.clear_objects()
    belt = engine.config.layout.conveyor
    a = engine.spawn("wheel-steel", s_m=belt.station_s_m - 0.2, yaw_rad=0.0)
    b = engine.spawn("gear-housing", s_m=belt.station_s_m + 0.2, yaw_rad=0.0)
    engine.set_joints(
        viewpoint(belt.station_point + np.array([0.0, 0.0, 0.1]), "top", distance_m=0.9)
    )
    masks = object_masks(engine)
    assert set(masks) == {a.id, b.id}
    assert masks[a.id].any() and masks[b.id].any()
    assert not (masks[a.id] & masks[b.id]).any()
    # Downstream (+s) is to the right in the image at the station's top view.
    xa = np.nonzero(masks[a.id])[1].mean()
    xb = np.nonzero(masks[b.id])[1].mean()
    assert xa != pytest.approx(xb, abs=50)
    engine.clear_objects()
