"""The simulated cell's world behind the backend's protocols: its :class:`CellLayout` (from
the MuJoCo cell's :class:`~robot.sim.world.WorldLayout`) and its objects' truth as a
:class:`~robot.cellworld.TruthSource` (for evaluations only)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from robot.cellworld import BeltSpan, Bin, CellLayout

if TYPE_CHECKING:
    from robot.sim.engine import SimEngine
    from robot.sim.world import WorldLayout

__all__ = ["SimObjectTruth", "cell_layout"]


def cell_layout(world: WorldLayout) -> CellLayout:
    """The station, the belt and the bins of the simulated cell's ``world``."""
    c = world.conveyor
    bins = tuple(
        Bin(b.name, tuple(b.parts), (float(b.centre_xy[0]), float(b.centre_xy[1]), float(b.rim_z_m)),
            reject=bool(b.reject), size_m=float(b.size_m), yaw_rad=float(b.yaw_rad))
        for b in world.bins
    )  # fmt: skip
    return CellLayout(
        station_xy_m=(float(c.centre_x_m), float(c.station_y_m)),
        surface_z_m=float(c.surface_z_m),
        belt=BeltSpan(float(c.start_y_m), float(c.end_y_m), float(c.width_m)),
        bins=bins,
        source="simulator",
    )


class SimObjectTruth:
    """Where the simulator's objects truly are (a :class:`~robot.cellworld.TruthSource`)."""

    def __init__(self, engine: SimEngine) -> None:
        self.engine = engine

    def object_near(self, point: NDArray[np.float64], back_m: float = 0.0) -> dict[str, Any] | None:
        """The object nearest ``point`` moved back ``back_m`` along the belt (+y), or None."""
        objs = self.engine.objects()
        if not objs:
            return None
        p = np.asarray(point, dtype=np.float64)
        o = min(
            objs, key=lambda o: float(np.linalg.norm(o.T_base_obj[:2, 3] - p[:2] + [0, back_m]))
        )
        T = o.T_base_obj.copy()
        T[1, 3] -= back_m
        return {"id": o.id, "name": o.name, "trainable": o.trainable,
                "T_base_obj": T.tolist(), "yaw_rad": o.yaw_rad}  # fmt: skip
