"""The simulated cell in the viser view: conveyor, objects riding it, calibration boards.

``robot.sim`` (and with it MuJoCo) is imported only when a simulation is drawn.

Everything is drawn from the simulation's state (``SimEngine``): the static conveyor and
table from its layout, the objects and boards from their true poses, refreshed by
:meth:`SimScene.update` at the view's rate.  Updates are sent only for what changed, so a
stopped belt costs nothing.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
import viser
import viser.transforms as vtf

if TYPE_CHECKING:
    from robot.sim import SimEngine

__all__ = ["SimScene"]


def _wxyz(R: np.ndarray) -> np.ndarray:
    return vtf.SO3.from_matrix(R).wxyz


def _yaw_wxyz(yaw: float) -> tuple[float, float, float, float]:
    return (math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0))


class SimScene:
    """Owns the viser nodes of the simulated cell (under ``/sim``)."""

    def __init__(self, server: viser.ViserServer, engine: SimEngine) -> None:
        self.server = server
        self.engine = engine
        self._objects: dict[int, tuple[Any, tuple[float, ...]]] = {}
        self._boards: dict[str, tuple[Any, tuple[float, ...]]] = {}
        self._cleats: list[Any] = []
        self._travel = -1.0
        self.updates = 0
        self._build_static()

    def _build_static(self) -> None:
        scene = self.server.scene
        layout = self.engine.config.layout
        c = layout.conveyor
        ym = (c.start_y_m + c.end_y_m) / 2
        scene.add_box(
            "/sim/conveyor/belt",
            color=(45, 47, 50),
            dimensions=(c.width_m, c.length_m, 0.04),
            position=(c.centre_x_m, ym, c.surface_z_m - 0.02),
        )
        for side in (-1, 1):
            x = c.centre_x_m + side * (c.width_m / 2 + 0.02)
            scene.add_box(
                f"/sim/conveyor/rail{side:+d}",
                color=(180, 184, 190),
                dimensions=(0.04, c.length_m + 0.1, 0.09),
                position=(x, ym, c.surface_z_m - 0.015),
            )
            for k, y in enumerate(np.linspace(c.start_y_m + 0.1, c.end_y_m - 0.1, 4)):
                scene.add_box(
                    f"/sim/conveyor/leg{side:+d}_{k}",
                    color=(64, 66, 70),
                    dimensions=(0.05, 0.05, c.surface_z_m - 0.06),
                    position=(x, y, (c.surface_z_m - 0.06) / 2),
                )
            scene.add_box(
                f"/sim/conveyor/station{side:+d}",
                color=(240, 200, 30),
                dimensions=(0.042, 0.02, 0.003),
                position=(x, c.station_y_m, c.surface_z_m + 0.031),
            )
        n = len(self.engine.cell.cleat_bodies)
        for i in range(n):
            self._cleats.append(
                scene.add_box(
                    f"/sim/conveyor/stripe{i}",
                    color=(110, 112, 116),
                    dimensions=(c.width_m - 0.02, 0.016, 0.002),
                    position=(c.centre_x_m, c.start_y_m, c.surface_z_m + 0.001),
                )
            )
        tx, ty = layout.table_centre_xy
        sx, sy = layout.table_size_xy
        scene.add_box(
            "/sim/table",
            color=(158, 128, 92),
            dimensions=(sx, sy, 0.03),
            position=(tx, ty, layout.table_top_z_m - 0.015),
        )

    def _add_object(self, obj_id: int, name: str) -> Any:
        from robot.sim.catalogue import CATALOGUE

        frame = self.server.scene.add_frame(f"/sim/objects/{obj_id}", show_axes=False)
        geo = CATALOGUE[name].geometry()
        for i, piece in enumerate(geo.pieces):
            self.server.scene.add_mesh_simple(
                f"/sim/objects/{obj_id}/{i}",
                piece.mesh.vertices.astype(np.float32),
                piece.mesh.faces.astype(np.uint32),
                color=geo.color_of(piece),
                side="double",
            )
        return frame

    def _add_board(self, kind: str) -> Any:
        spec = next(b for b in self.engine.config.boards if b.kind == kind)
        frame = self.server.scene.add_frame(f"/sim/boards/{kind}", show_axes=False)
        xl, xr, yt, yb = spec.print_extent_m()
        # viser draws an image in its xy plane facing +z with image rows along -y; the
        # printed face looks along -z_board with rows along +y_board.
        self.server.scene.add_image(
            f"/sim/boards/{kind}/print",
            spec.image,
            render_width=xr - xl,
            render_height=yb - yt,
            wxyz=_wxyz(np.diag([1.0, -1.0, -1.0])),
            position=((xl + xr) / 2, (yt + yb) / 2, -0.0005),
        )
        return frame

    def update(self) -> None:
        """Bring objects, boards and the belt's stripes up to date with the simulation."""
        objects = self.engine.objects()
        boards = self.engine.boards()
        travel = self.engine.conveyor_state.travel_m
        changed = False
        with self.server.atomic():
            seen = set()
            for o in objects:
                seen.add(o.id)
                pose = (*o.T_base_obj[:3, 3], o.yaw_rad)
                entry = self._objects.get(o.id)
                if entry is None:
                    entry = (self._add_object(o.id, o.name), ())
                if entry[1] != pose:
                    entry[0].position = o.T_base_obj[:3, 3]
                    entry[0].wxyz = _yaw_wxyz(o.yaw_rad)
                    changed = True
                self._objects[o.id] = (entry[0], pose)
            for obj_id in set(self._objects) - seen:
                self._objects.pop(obj_id)[0].remove()
                changed = True
            placed = set()
            for b in boards:
                placed.add(b.kind)
                key = tuple(b.T_base_board.ravel())
                entry = self._boards.get(b.kind)
                if entry is None:
                    entry = (self._add_board(b.kind), ())
                if entry[1] != key:
                    entry[0].position = b.T_base_board[:3, 3]
                    entry[0].wxyz = _wxyz(b.T_base_board[:3, :3])
                    changed = True
                self._boards[b.kind] = (entry[0], key)
            for kind in set(self._boards) - placed:
                self._boards.pop(kind)[0].remove()
                changed = True
            if travel != self._travel:
                from robot.sim.world import cleat_positions

                self._travel = travel
                pos = cleat_positions(self.engine.config.layout.conveyor, travel, len(self._cleats))
                for handle, p in zip(self._cleats, pos, strict=True):
                    handle.position = p
                changed = True
        if changed:
            self.updates += 1
