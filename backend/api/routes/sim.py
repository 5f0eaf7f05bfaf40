"""The simulated cell: conveyor, objects with their true poses, lights, boards, camera sensor.

Engineer role only: these endpoints change the world and reveal ground truth (true object
poses), which operators' tools must not lean on.  When the cell does not run the simulator,
every endpoint answers 409 ``not_simulated``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Any, Literal

from fastapi import APIRouter, Depends, Response, status
from pydantic import BaseModel, Field, field_validator

from backend.api.deps import CellDep, EngineerUser, SettingsDep, get_sim_or_none
from backend.api.errors import ApiError

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

    running: bool | None = Field(None, description="Run or stop the belt")
    speed_m_s: float | None = Field(None, ge=0.0, le=2.0, description="Belt speed, m/s")
    mode: Literal["continuous", "index"] | None = Field(
        None, description="continuous, or index: stop each object at the station"
    )
    dwell_s: float | None = Field(
        None, ge=0.0, le=3600.0, description="Index mode: seconds at the station"
    )


class ObjectIn(BaseModel):
    """An object to put on the belt."""

    name: str = Field(
        description="Catalogue name (GET /api/sim/catalogue)", examples=["wheel-5spoke"]
    )
    position_along_belt_m: float | None = Field(
        None, description="Distance from the belt's entry, m (default: the entry)"
    )
    lateral_m: float = Field(0.0, description="Offset from the belt's centre line, m")
    yaw_rad: float | None = Field(None, description="Rotation about the vertical (default: random)")

    @field_validator("name")
    @classmethod
    def _known(cls, v: str) -> str:
        names = _catalogue()
        if v not in names:
            raise ValueError(f"unknown catalogue name {v!r}; valid names: {', '.join(names)}")
        return v


class LightIn(BaseModel):
    intensity: float = Field(ge=0.0, le=5.0, description="Factor on the light's default intensity")


class BoardIn(BaseModel):
    """Where to place a board: a 4x4 ``T_base_board`` or a preset."""

    T_base_board: list[list[float]] | None = Field(
        None, description="Pose of the board frame in the base frame (4x4, metres)"
    )
    preset: Literal["table", "station"] | None = Field(
        None, description="table: face up on the table; station: face up on the belt at the station"
    )

    @field_validator("T_base_board")
    @classmethod
    def _shape(cls, v: list[list[float]] | None) -> list[list[float]] | None:
        if v is not None and (len(v) != 4 or any(len(row) != 4 for row in v)):
            raise ValueError("T_base_board must be a 4x4 matrix")
        if v is not None and not all(math.isfinite(x) for row in v for x in row):
            raise ValueError("T_base_board must be finite")
        return v


class CameraIn(BaseModel):
    """Sensor settings of the simulated camera; fields left out keep their value."""

    exposure_s: float | None = Field(None, gt=0.0, le=1.0)
    gain: float | None = Field(None, gt=0.0, le=16.0)
    noise_std_dn: float | None = Field(None, ge=0.0, le=50.0)
    motion_blur: bool | None = None


# -- conveyor --------------------------------------------------------------------------------
@router.get("/conveyor", summary="Belt settings and whether an object waits at the station")
async def read_conveyor(_: EngineerUser, sim: SimDep) -> dict[str, Any]:
    return {"conveyor": sim.conveyor_state.as_dict()}


@router.post("/conveyor", summary="Start/stop the belt, set its speed, mode and dwell")
async def update_conveyor(_: EngineerUser, sim: SimDep, body: ConveyorIn) -> dict[str, Any]:
    dwell: float | str | None = "keep" if "dwell_s" not in body.model_fields_set else body.dwell_s
    state = sim.configure_conveyor(
        running=body.running, speed_m_s=body.speed_m_s, mode=body.mode, dwell_s=dwell
    )
    return {"conveyor": state.as_dict()}


@router.post("/conveyor/release", summary="Index mode: let the object at the station go on")
async def create_release(_: EngineerUser, sim: SimDep) -> dict[str, Any]:
    sim.release_conveyor()
    return {"conveyor": sim.conveyor_state.as_dict()}


# -- catalogue and objects -------------------------------------------------------------------
@router.get("/catalogue", summary="Objects that can be spawned")
async def read_catalogue(_: EngineerUser, sim: SimDep) -> dict[str, Any]:
    data = [entry.summary() for entry in _catalogue().values()]
    return {"data": data, "count": len(data)}


@router.get("/objects", summary="Objects on the belt with their true poses")
async def read_objects(_: EngineerUser, sim: SimDep) -> dict[str, Any]:
    data = [o.as_dict() for o in sim.objects()]
    return {"data": data, "count": len(data)}


@router.post("/objects", status_code=status.HTTP_201_CREATED, summary="Put an object on the belt")
async def create_object(_: EngineerUser, sim: SimDep, body: ObjectIn) -> dict[str, Any]:
    obj = sim.spawn(
        body.name,
        s_m=body.position_along_belt_m or 0.0,
        lateral_m=body.lateral_m,
        yaw_rad=body.yaw_rad,
    )
    return {"object": obj.as_dict()}


@router.get("/objects/{obj_id}", summary="One object's true pose")
async def read_object(_: EngineerUser, sim: SimDep, obj_id: int) -> dict[str, Any]:
    for o in sim.objects():
        if o.id == obj_id:
            return {"object": o.as_dict()}
    raise ApiError(404, "not_found", f"no object with id {obj_id} on the belt")


@router.delete(
    "/objects/{obj_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Take an object off the belt",
)
async def delete_object(_: EngineerUser, sim: SimDep, obj_id: int) -> Response:
    if obj_id not in {o.id for o in sim.objects()}:
        raise ApiError(404, "not_found", f"no object with id {obj_id} on the belt")
    sim.remove(obj_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


# -- lights ----------------------------------------------------------------------------------
@router.get("/lights", summary="Intensity factor of each light")
async def read_lights(_: EngineerUser, sim: SimDep) -> dict[str, Any]:
    data = [{"name": k, "intensity": v} for k, v in sim.lights().items()]
    return {"data": data, "count": len(data)}


@router.put("/lights/{name}", summary="Set a light's intensity (1 = default, 0 = off)")
async def update_light(_: EngineerUser, sim: SimDep, name: str, body: LightIn) -> dict[str, Any]:
    if name not in sim.lights():
        raise ApiError(
            404, "not_found", f"no light named {name!r}; lights: {', '.join(sim.lights())}"
        )
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


@router.get("/boards", summary="Placed calibration boards with their true poses")
async def read_boards(_: EngineerUser, sim: SimDep) -> dict[str, Any]:
    data = [b.as_dict() for b in sim.boards()]
    return {"data": data, "count": len(data), "kinds": list(sim.board_kinds)}


@router.put("/boards/{kind}", summary="Place a calibration board (chessboard or charuco)")
async def update_board(_: EngineerUser, sim: SimDep, kind: str, body: BoardIn) -> dict[str, Any]:
    if kind not in sim.board_kinds:
        raise ApiError(404, "not_found", f"no {kind!r} board; boards: {', '.join(sim.board_kinds)}")
    if (body.T_base_board is None) == (body.preset is None):
        raise ApiError(422, "validation_error", "give exactly one of T_base_board and preset")
    T = body.T_base_board if body.T_base_board is not None else _preset(sim, body.preset or "")
    return {"board": sim.place_board(kind, T).as_dict()}


@router.delete("/boards/{kind}", status_code=status.HTTP_204_NO_CONTENT, summary="Remove a board")
async def delete_board(_: EngineerUser, sim: SimDep, kind: str) -> Response:
    if kind not in sim.board_kinds:
        raise ApiError(404, "not_found", f"no {kind!r} board; boards: {', '.join(sim.board_kinds)}")
    sim.remove_board(kind)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


# -- camera sensor ---------------------------------------------------------------------------
@router.put("/camera", summary="Exposure, gain, noise and motion blur of the simulated camera")
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
