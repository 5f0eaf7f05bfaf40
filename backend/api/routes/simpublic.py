"""The answers of the simulated cell's endpoints (:mod:`backend.api.routes.sim`): the belt,
the catalogue, objects and boards with their true poses, lights and the camera sensor."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

from backend.api.schemas import Page

__all__ = [
    "BoardOut",
    "BoardPublic",
    "BoardsOut",
    "CameraOut",
    "CataloguePublic",
    "ConveyorOut",
    "ConveyorReadOut",
    "ConveyorReadPublic",
    "ConveyorStatePublic",
    "LightOut",
    "ObjectOut",
    "ObjectPublic",
]


class ConveyorStatePublic(BaseModel):
    """The belt's settings and state."""

    running: bool
    speed_m_s: float = Field(description="Belt speed when running, m/s")
    mode: Literal["continuous", "index"] = Field(
        description="continuous, or index: each object stops at the station"
    )
    dwell_s: float | None = Field(
        description="Index mode: seconds an object waits at the station (None: until released)"
    )
    at_station: bool = Field(description="An object waits at the station")
    travel_m: float = Field(description="Distance the belt has moved since the start, m")
    halted: bool = Field(description="The emergency stop holds the belt (it resumes on reset)")


class ConveyorReadPublic(ConveyorStatePublic):
    """The belt's settings and state with its geometry."""

    station_s_m: float = Field(
        description="Where along the belt the station is, m from its entry (objects are "
        "placed there)"
    )
    length_m: float = Field(
        description="Belt length from entry to exit, m (objects leaving it come back at its entry)"
    )


class ConveyorOut(BaseModel):
    conveyor: ConveyorStatePublic


class ConveyorReadOut(BaseModel):
    conveyor: ConveyorReadPublic


class CataloguePublic(BaseModel):
    """A kind of object that can be put on the belt."""

    name: str = Field(description="Catalogue name (what POST /api/sim/objects takes)")
    kind: str = Field(description="wheel or part")
    trainable: bool = Field(description="False for parts that recognition must reject")
    description: str
    part: str = Field(description="The physical part (entries sharing it are its sitting bases)")
    size_m: list[float] = Field(description="Bounding box size x, y, z, m")
    height_m: float = Field(description="Top of the object above the belt, m")


class ObjectPublic(BaseModel):
    """An object on the belt with its true pose."""

    id: int
    name: str = Field(description="Catalogue name")
    T_base_obj: list[list[float]] = Field(
        description="Object frame (footprint centre on the belt, z up) in the base frame, 4x4, m"
    )
    position_m: list[float] = Field(description="Origin of the object frame in the base frame, m")
    yaw_rad: float = Field(description="Rotation about the vertical, rad")
    position_along_belt_m: float = Field(description="Distance from the belt's entry, m")
    lateral_m: float = Field(description="Offset from the belt's centre line, m")
    trainable: bool = Field(description="False for parts that recognition must reject")


class ObjectOut(BaseModel):
    object: ObjectPublic


class LightOut(BaseModel):
    name: str
    intensity: float = Field(description="Factor on the light's default intensity")


class BoardPublic(BaseModel):
    """A placed calibration board with its true pose."""

    kind: Literal["chessboard", "charuco"]
    cols: int = Field(description="Chessboard: inner corners along x; ChArUco: squares along x")
    rows: int = Field(description="Chessboard: inner corners along y; ChArUco: squares along y")
    square_m: float = Field(description="Side of one square, m")
    marker_m: float | None = Field(description="ChArUco: marker side, m (None: chessboard)")
    dictionary: str | None = Field(description="ChArUco: ArUco dictionary (None: chessboard)")
    T_base_board: list[list[float]] = Field(
        description="Board frame in the base frame, 4x4, m (z into the board)"
    )


class BoardOut(BaseModel):
    board: BoardPublic


class BoardsOut(Page[BoardPublic]):
    kinds: list[str] = Field(description="The kinds of board this cell can place")


class CameraOut(BaseModel):
    """The simulated camera's sensor settings."""

    exposure_s: float
    gain: float
    noise_std_dn: float
    motion_blur: bool
