"""The simulated cell's furniture as collision boxes (for :mod:`robot.collision`)."""

from __future__ import annotations

from robot.collision import Box, CollisionWorld
from robot.model import ASEA, ArmModel
from robot.sim.world import WorldLayout

__all__ = ["collision_world"]

#: Height of the conveyor's side rails above the belt, metres (a little above the drawn ones).
_RAIL_M = 0.06


def collision_world(
    layout: WorldLayout | None = None, *, clearance_m: float = 0.02, model: ArmModel = ASEA
) -> CollisionWorld:
    """Table, conveyor (belt and side rails) and sorting bins of ``layout`` as boxes from the floor up, and the
    floor plane (a turned bin is represented by the axis-aligned box round it)."""
    lay = layout or WorldLayout()
    tx, ty = lay.table_centre_xy
    sx, sy = lay.table_size_xy
    c = lay.conveyor
    table = Box(
        "table", (tx - sx / 2, ty - sy / 2, 0.0), (tx + sx / 2, ty + sy / 2, lay.table_top_z_m)
    )
    # The belt up to its surface, and the two side rails above it (the drawn rails are 4 cm
    # wide beside the belt), so that a tool may come down between the rails.
    conveyor = Box(
        "conveyor",
        (c.centre_x_m - c.width_m / 2 - 0.04, c.start_y_m, 0.0),
        (c.centre_x_m + c.width_m / 2 + 0.04, c.end_y_m, c.surface_z_m),
    )
    rails = tuple(
        Box(
            f"conveyor rail {side}",
            (x0, c.start_y_m - 0.05, c.surface_z_m),
            (x0 + 0.04, c.end_y_m + 0.05, c.surface_z_m + _RAIL_M),
        )
        for side, x0 in (
            ("inner", c.centre_x_m - c.width_m / 2 - 0.04),
            ("outer", c.centre_x_m + c.width_m / 2),
        )
    )
    bins = tuple(
        Box.around(
            f"bin {b.name}",
            [(x, y, z) for x, y in b.corners_xy() for z in (0.0, b.rim_z_m)],
        )
        for b in lay.bins
    )
    return CollisionWorld((table, conveyor, *rails, *bins), 0.0, clearance_m, model=model)
