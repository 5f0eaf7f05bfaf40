"""The simulated cell: conveyor, objects with their true poses, lights, boards, camera sensor.

Engineer role only: these endpoints change the world and reveal ground truth (true object
poses), which operators' tools must not lean on.  When the cell does not run the simulator,
every endpoint answers 409 ``not_simulated``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Any, Literal

from fastapi import APIRouter, Depends, Path, Response, status
from pydantic import BaseModel, Field, field_validator, model_validator

from backend.api.deps import CellDep, EngineerUser, SettingsDep, get_sim_or_none
from backend.api.errors import ApiError
from backend.api.routes.simpublic import (
    BoardOut,
    BoardsOut,
    CameraOut,
    CataloguePublic,
    ConveyorOut,
    ConveyorReadOut,
    LightOut,
    ObjectOut,
    ObjectPublic,
)
from backend.api.schemas import Page, page
from backend.api.types import (
    MAX_DB_ID,
    MAX_NAME_LENGTH,
    Limit,
    Matrix4,
    NameStr,
    Offset,
    StrictBool,
    bounded_float,
)
from vision.errors import NotFound

if TYPE_CHECKING:
    from robot.sim import SimEngine

router = APIRouter(prefix="/sim", tags=["simulation"])


def _catalogue() -> dict[str, Any]:
    # Imported on use: robot.sim loads MuJoCo, which must see MUJOCO_GL first (set by
    # backend.hardware when the simulator starts).
    from robot.sim.catalogue import CATALOGUE

    return CATALOGUE


def get_sim(sim: Annotated[Any, Depends(get_sim_or_none)], settings: SettingsDep) -> SimEngine:
    """The simulation engine, or 409 when this cell drives real (or ideal) hardware."""
    if sim is None:
        raise ApiError(
            409,
            "not_simulated",
            f"the simulator is not running (driver={settings.driver!r}, camera={settings.camera!r}); "
            "start the cell with VISIONCELL_DRIVER=sim VISIONCELL_CAMERA=sim",
        )
    return sim


SimDep = Annotated[Any, Depends(get_sim)]


# -- schemas ---------------------------------------------------------------------------------
class ConveyorIn(BaseModel):
    """Belt settings; fields left out keep their value."""

    running: StrictBool | None = Field(None, description="Run or stop the belt")
    speed_m_s: Annotated[float, bounded_float(0.0, 2.0, "Belt speed, m/s")] | None = None
    mode: Literal["continuous", "index"] | None = Field(
        None, description="continuous, or index: stop each object at the station"
    )
    dwell_s: (
        Annotated[float, bounded_float(0.0, 3600.0, "Index mode: seconds at the station")] | None
    ) = None


class ObjectIn(BaseModel):
    """An object to put on the belt."""

    name: str = Field(
        max_length=MAX_NAME_LENGTH,
        description="Catalogue name (GET /api/sim/catalogue)",
        examples=["wheel-5spoke"],
    )
    at: Literal["station", "entry"] | None = Field(
        None,
        description="Where to put it: the inspection station or the belt's entry (give this "
        "or position_along_belt_m, not both; neither: the station while the belt is stopped, "
        "the entry while it runs)",
    )
    position_along_belt_m: (
        Annotated[
            float,
            bounded_float(0.0, 100.0, "Distance from the belt's entry, m (default: see at)"),
        ]
        | None
    ) = None
    lateral_m: Annotated[
        float, bounded_float(-5.0, 5.0, "Offset from the belt's centre line, m")
    ] = 0.0
    yaw_rad: (
        Annotated[
            float,
            bounded_float(
                -2 * math.pi, 2 * math.pi, "Rotation about the vertical, rad (default: random)"
            ),
        ]
        | None
    ) = None

    @field_validator("name")
    @classmethod
    def _known(cls, v: str) -> str:
        names = _catalogue()
        if v not in names:
            raise ValueError(f"unknown catalogue name {v!r}; valid names: {', '.join(names)}")
        return v

    @model_validator(mode="after")
    def _one_place(self) -> ObjectIn:
        if self.at is not None and self.position_along_belt_m is not None:
            raise ValueError(
                f"give at or position_along_belt_m, not both (got at={self.at!r}, "
                f"position_along_belt_m={self.position_along_belt_m!r})"
            )
        return self

    def along_belt_m(self, station_s_m: float, belt_running: bool) -> float:
        """Where along the belt (metres from its entry) the object goes."""
        if self.position_along_belt_m is not None:
            return float(self.position_along_belt_m)
        at = self.at or ("entry" if belt_running else "station")
        return float(station_s_m) if at == "station" else 0.0


class LightIn(BaseModel):
    intensity: Annotated[float, bounded_float(0.0, 5.0, "Factor on the light's default intensity")]


class BoardIn(BaseModel):
    """Where to place a board: a 4x4 ``T_base_board`` or a preset."""

    T_base_board: Matrix4 | None = Field(
        None, description="Pose of the board frame in the base frame (4x4, metres)"
    )
    preset: Literal["table", "station"] | None = Field(
        None, description="table: face up on the table; station: face up on the belt at the station"
    )

    @model_validator(mode="after")
    def _one(self) -> BoardIn:
        if (self.T_base_board is None) == (self.preset is None):
            raise ValueError("give exactly one of T_base_board and preset")
        return self


class CameraIn(BaseModel):
    """Sensor settings of the simulated camera; fields left out keep their value."""

    exposure_s: Annotated[float, bounded_float(1e-5, 1.0, "Exposure time, s")] | None = None
    gain: Annotated[float, bounded_float(0.01, 16.0, "Analogue gain")] | None = None
    noise_std_dn: Annotated[float, bounded_float(0.0, 50.0, "Read noise, DN")] | None = None
    motion_blur: StrictBool | None = None


ObjectId = Annotated[int, Path(ge=1, le=MAX_DB_ID, description="Object id, 1 .. 2^63 - 1")]


# -- conveyor --------------------------------------------------------------------------------
@router.get(
    "/conveyor",
    summary="Belt settings and whether an object waits at the station",
    response_model=ConveyorReadOut,
)
async def read_conveyor(_: EngineerUser, sim: SimDep) -> dict[str, Any]:
    # station_s_m: where along the belt the station is (the console places objects there);
    # length_m: the belt from entry to exit (objects leaving it come back at its entry).
    spec = sim.config.layout.conveyor
    return {"conveyor": {**sim.conveyor_state.as_dict(), "station_s_m": float(spec.station_s_m),
                         "length_m": float(spec.length_m)}}  # fmt: skip


@router.post(
    "/conveyor",
    summary="Start/stop the belt, set its speed, mode and dwell",
    response_model=ConveyorOut,
)
async def update_conveyor(_: EngineerUser, sim: SimDep, body: ConveyorIn) -> dict[str, Any]:
    dwell: float | str | None = "keep" if "dwell_s" not in body.model_fields_set else body.dwell_s
    state = sim.configure_conveyor(
        running=body.running, speed_m_s=body.speed_m_s, mode=body.mode, dwell_s=dwell
    )
    return {"conveyor": state.as_dict()}


@router.post(
    "/conveyor/release",
    summary="Index mode: let the object at the station go on",
    response_model=ConveyorOut,
)
async def create_release(_: EngineerUser, sim: SimDep) -> dict[str, Any]:
    sim.release_conveyor()
    return {"conveyor": sim.conveyor_state.as_dict()}


# -- catalogue and objects -------------------------------------------------------------------
@router.get(
    "/catalogue", summary="Objects that can be spawned", response_model=Page[CataloguePublic]
)
async def read_catalogue(
    _: EngineerUser, sim: SimDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    data = [entry.summary() for entry in _catalogue().values()]
    return page(data, limit=limit, offset=offset)


@router.get(
    "/objects",
    summary="Objects on the belt with their true poses",
    response_model=Page[ObjectPublic],
)
async def read_objects(
    _: EngineerUser, sim: SimDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    data = [o.as_dict() for o in sim.objects()]
    return page(data, limit=limit, offset=offset)


@router.post(
    "/objects",
    status_code=status.HTTP_201_CREATED,
    summary='Put an object on the belt: at the station ("at": "station"), its entry '
    '("at": "entry") or a position along it; by default at the station while the belt is '
    "stopped, at the entry while it runs",
    response_model=ObjectOut,
)
async def create_object(_: EngineerUser, sim: SimDep, body: ObjectIn) -> dict[str, Any]:
    station = float(sim.config.layout.conveyor.station_s_m)
    obj = sim.spawn(
        body.name,
        s_m=body.along_belt_m(station, bool(sim.conveyor_state.running)),
        lateral_m=body.lateral_m,
        yaw_rad=body.yaw_rad,
    )
    return {"object": obj.as_dict()}


def get_object(sim: SimDep, obj_id: ObjectId) -> Any:
    """The object on the belt with this id; :class:`NotFound` otherwise."""
    for o in sim.objects():
        if o.id == obj_id:
            return o
    raise NotFound(f"no object with id {obj_id} on the belt")


ObjectDep = Annotated[Any, Depends(get_object)]


@router.get("/objects/{obj_id}", summary="One object's true pose", response_model=ObjectOut)
async def read_object(_: EngineerUser, obj: ObjectDep) -> dict[str, Any]:
    return {"object": obj.as_dict()}


@router.delete(
    "/objects/{obj_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Take an object off the belt",
)
async def delete_object(_: EngineerUser, sim: SimDep, obj: ObjectDep) -> Response:
    sim.remove(obj.id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


# -- lights ----------------------------------------------------------------------------------
@router.get("/lights", summary="Intensity factor of each light", response_model=Page[LightOut])
async def read_lights(
    _: EngineerUser, sim: SimDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    data = [{"name": k, "intensity": v} for k, v in sim.lights().items()]
    return page(data, limit=limit, offset=offset)


def get_light(sim: SimDep, name: NameStr) -> str:
    """The name of an existing light; :class:`NotFound` otherwise."""
    if name not in sim.lights():
        raise NotFound(f"no light named {name!r}; lights: {', '.join(sim.lights())}")
    return name


def get_board_kind(sim: SimDep, kind: NameStr) -> str:
    """A kind of board this cell has; :class:`NotFound` otherwise."""
    if kind not in sim.board_kinds:
        raise NotFound(f"no {kind!r} board; boards: {', '.join(sim.board_kinds)}")
    return kind


LightDep = Annotated[str, Depends(get_light)]
BoardKindDep = Annotated[str, Depends(get_board_kind)]


@router.put(
    "/lights/{name}",
    summary="Set a light's intensity (1 = default, 0 = off)",
    response_model=LightOut,
)
async def update_light(
    _: EngineerUser, sim: SimDep, name: LightDep, body: LightIn
) -> dict[str, Any]:
    sim.set_light(name, body.intensity)
    return {"name": name, "intensity": sim.lights()[name]}


# -- calibration boards ----------------------------------------------------------------------
def _preset(sim: SimEngine, preset: str) -> list[list[float]]:
    layout = sim.config.layout
    if preset == "table":
        x, y = layout.table_centre_xy
        pos = (x - 0.12, y + 0.1, layout.table_top_z_m + 0.002)
    else:
        c = layout.conveyor
        pos = (c.centre_x_m - 0.1, c.station_y_m - 0.12, c.surface_z_m + 0.002)
    # Face up: z_board (into the board) points down, x_board along +x of the base.
    return [[1, 0, 0, pos[0]], [0, -1, 0, pos[1]], [0, 0, -1, pos[2]], [0, 0, 0, 1]]


@router.get(
    "/boards", summary="Placed calibration boards with their true poses", response_model=BoardsOut
)
async def read_boards(
    _: EngineerUser, sim: SimDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    data = [b.as_dict() for b in sim.boards()]
    return {**page(data, limit=limit, offset=offset), "kinds": list(sim.board_kinds)}


@router.put(
    "/boards/{kind}",
    summary="Place a calibration board (chessboard or charuco)",
    response_model=BoardOut,
)
async def update_board(
    _: EngineerUser, sim: SimDep, kind: BoardKindDep, body: BoardIn
) -> dict[str, Any]:
    T = body.T_base_board if body.T_base_board is not None else _preset(sim, body.preset or "")
    return {"board": sim.place_board(kind, T).as_dict()}


@router.delete("/boards/{kind}", status_code=status.HTTP_204_NO_CONTENT, summary="Remove a board")
async def delete_board(_: EngineerUser, sim: SimDep, kind: BoardKindDep) -> Response:
    sim.remove_board(kind)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


# -- camera sensor ---------------------------------------------------------------------------
@router.put(
    "/camera",
    summary="Exposure, gain, noise and motion blur of the simulated camera",
    response_model=CameraOut,
)
async def update_camera(
    _: EngineerUser, sim: SimDep, cell: CellDep, body: CameraIn
) -> dict[str, Any]:
    configure = getattr(cell.camera, "configure", None)
    if cell.camera.name != "sim" or configure is None:
        raise ApiError(
            409,
            "not_simulated",
            f"the cell's camera is {cell.camera.name!r}, not the simulated one",
        )
    spec = configure(**body.model_dump(exclude_none=True))
    return {
        "exposure_s": spec.exposure_s,
        "gain": spec.gain,
        "noise_std_dn": spec.noise_std_dn,
        "motion_blur": spec.motion_blur,
    }
