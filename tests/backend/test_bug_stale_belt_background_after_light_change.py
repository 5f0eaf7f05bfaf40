"""A belt background grabbed under the old light was still used after the lights changed
(issue 14's campaign: 96.9 % named under half light and 80.6 % under a colour cast).

The campaign grabs the belt background registered to the travel (constant belt speed) under
the normal light, then dims the lamps or gives them a cast and grabs the still background
again (`service.grab_background`, what an operator does after the lights changed).  The
index-mode inspections under the new light then segmented against the belt background,
which matched the camera pose and was preferred whatever its age: the whole belt differed
from the old light's background, the regions were wrong, plain parts scored 0.02-0.06.
Now a still background grabbed after the belt background makes it stale.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np

from backend.inspection.context import Context
from backend.inspection.find import background_for
from backend.inspection.state import InspectionState
from backend.planning import BackgroundStore, Shot
from robot.drivers.conveyor import FixedStation
from tests.backend.test_bug_constant_speed_object_never_found import (
    CAM,
    GEO,
    STATION,
    T_EE_CAM,
    Q,
    _render,
    belt,  # noqa: F401  (the module's fixture: the synthetic belt's background)
)
from vision.sources import Frame


def _ctx(bb, store):
    rt = SimpleNamespace(
        inspection=InspectionState(belt_background=bb),
        teach_backgrounds=store,
        conveyor=FixedStation(),
    )
    return Context(rt, CAM, T_EE_CAM, "test", STATION.copy(), GEO.surface_z_m)


def test_a_still_background_grabbed_later_wins_over_the_belt_background(belt):  # noqa: F811
    travel = 0.37
    frame = Frame(_render(travel), stamp_s=1.0, index=0, robot_state=SimpleNamespace(q=Q),
                  meta={"belt_travel_m": travel})  # fmt: skip
    dim = (_render(0.0) // 2).astype(np.uint8)  # the still background under half light
    store = BackgroundStore()
    # Belt background newer than the still one (the teach's): it is the one for the frame.
    store.taken_at = belt.taken_at - 10.0
    got = background_for(_ctx(belt, store), frame, dim)
    assert np.array_equal(got, belt.at(travel))
    # The lights changed and the still background was grabbed again: that one now.
    store.put(Shot(1, "top", 0.0, Q, np.eye(4)), dim)
    assert store.taken_at >= belt.taken_at
    got = background_for(_ctx(belt, store), frame, dim)
    assert got is dim
    # A belt background grabbed after that is used again.
    fresh = dataclasses.replace(belt, taken_at=store.taken_at + 1.0)
    assert np.array_equal(background_for(_ctx(fresh, store), frame, dim), fresh.at(travel))
