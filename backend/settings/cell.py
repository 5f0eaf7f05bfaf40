"""The cell itself: its name and database, the robot driver and the camera, the paths,
the simulator and the process (log level, event loop)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, Field, field_validator

from backend.settings.checks import CELL_NAME_PATTERN


class CellFields(BaseModel):
    """Settings of the cell: database, robot, camera, paths and the simulator."""

    environment: Literal["development", "production"] = Field(
        "development", description="'production' forbids the development secret and disabling auth."
    )
    cell_name: str = Field(
        "cell-1",
        description="Name of this cell's row in the database; several cells (processes) may "
        "share one PostgreSQL database, each with its own calibrations and inspections.",
    )
    database_url: str = Field(
        "sqlite+aiosqlite:///var/visioncell.db",
        description="SQLAlchemy async URL: sqlite+aiosqlite:///FILE or postgresql+asyncpg://USER@HOST/DB.",
    )
    database_busy_timeout_s: float = Field(
        30.0,
        gt=0,
        le=300,
        description="SQLite: how long a write waits for another connection's lock, seconds.",
    )
    driver: Literal["sim", "serial", "ideal"] = Field(
        "sim",
        description="Robot driver: the MuJoCo cell, the serial controller or the ideal follower.",
    )
    camera: Literal["sim", "opencv", "folder"] = Field(
        "sim",
        description="Image source: the simulated eye-in-hand camera, OpenCV, or an image folder.",
    )
    camera_device: str = Field("0", description="OpenCV camera: V4L2 index or a video/stream URL.")
    camera_folder: Path | None = Field(
        None,
        description="Folder camera: images to replay (default: the OpenCV chessboard photos in the data directory).",
    )
    camera_replay: Literal["stream", "look"] = Field(
        "stream",
        description="Folder camera and video files: 'stream' plays the images on by "
        "themselves (looping); 'look': each look of the cell takes the next image, so a "
        "session recorded from a real cell replays through the inspection loop.",
    )
    camera_order: Literal["name", "manifest"] = Field(
        "name",
        description="Folder camera: replay the images sorted by file name, or in the order "
        "the folder's order.txt lists them (one file name per line).",
    )
    cell_layout: Path | None = Field(
        None,
        description="A real cell's layout file (TOML or JSON: the station, the belt, the "
        "sorting bins; robot.layoutfile).  Unset: a fixed station in front of the arm, no "
        "bins.  The simulated cell has its own layout.",
    )
    camera_transfer: Literal["auto", "linear", "srgb"] = Field(
        "auto",
        description="The camera's transfer curve, for the colour descriptor (color-sift) and "
        "the colour tie-break: 'srgb' for 8-bit gamma-encoded cameras, 'linear' for raw or "
        "16-bit linear ones; 'auto' chooses by camera kind (see resolved_camera_transfer).",
    )
    camera_fps: float = Field(
        10.0, gt=0, le=120, description="Acquisition rate of the camera task, frames/s."
    )
    camera_idle_fps: float = Field(
        1.0,
        gt=0,
        le=120,
        description="Acquisition rate while nobody has asked for a frame for 2 s (a rendered camera costs CPU).",
    )
    data_dir: Path = Field(Path("../shared/data"), description="Public test data (see its README).")
    var_dir: Path = Field(
        Path("var"), description="Writable directory for the SQLite file, logs and job output."
    )
    serial_port: str | None = Field(
        None, description="Serial driver: device path of the controller."
    )
    serial_baud: int = Field(115200, gt=0, description="Serial driver: baud rate.")
    time_scale: float = Field(
        1.0,
        gt=0,
        le=100,
        description="Simulated seconds per wall-clock second (sim and ideal drivers).",
    )
    state_rate_hz: float = Field(
        50.0, gt=0, le=1000, description="Robot state publishing rate, Hz."
    )
    view3d_enabled: bool = Field(True, description="Start the viser 3D view.")
    sim_demo: bool = Field(
        True,
        description="Simulator: start with a few catalogue objects on the belt, indexing at the station.",
    )
    log_level: Literal["debug", "info", "warning", "error"] = "info"
    event_loop: Literal["auto", "uvloop", "asyncio"] = Field(
        "auto",
        description="Event loop of `visioncell serve`: uvloop when it is installed (auto), "
        "required (uvloop), or the standard library's (asyncio).",
    )
    motion_log: Path | None = Field(
        None,
        description="Append every motion command, with the e-stop, link and lock state that "
        "allowed it, to this JSON-lines file (an audit; off by default).",
    )

    @field_validator("cell_name")
    @classmethod
    def _valid_cell_name(cls, v: str) -> str:
        if not CELL_NAME_PATTERN.match(v):
            raise ValueError(
                "cell_name must be a short slug: 1-40 lower-case letters, digits, '-' or '_', "
                f"starting and ending with a letter or digit, got {v!r}"
            )
        return v

    @field_validator("camera_device")
    @classmethod
    def _valid_device(cls, v: str) -> str:
        if not v.strip() or len(v) > 2048 or "\x00" in v:
            raise ValueError(
                "camera_device must be a V4L2 index ('0', '/dev/video0'), a video file or a "
                f"stream URL of at most 2048 characters, got {v[:80]!r}"
            )
        return v

    @field_validator("database_url")
    @classmethod
    def _valid_db(cls, v: str) -> str:
        if not (v.startswith("sqlite+aiosqlite://") or v.startswith("postgresql+asyncpg://")):
            raise ValueError(
                "database_url must use an async driver: 'sqlite+aiosqlite:///FILE' or "
                f"'postgresql+asyncpg://USER@HOST/DB', got {v!r}"
            )
        return v

    # -- derived paths ---------------------------------------------------------------------
    @property
    def is_sqlite(self) -> bool:
        """True for the embedded SQLite database."""
        return self.database_url.startswith("sqlite")

    def sqlite_path(self) -> Path | None:
        """File of the SQLite database, or None for in-memory/PostgreSQL."""
        if not self.is_sqlite:
            return None
        path = self.database_url.split(":///", 1)[-1]
        return None if path in ("", ":memory:") else Path(path)

    def resolved_camera_folder(self) -> Path:
        """Folder replayed by the folder camera."""
        return self.camera_folder or self.data_dir / "calibration" / "opencv-left"

    def resolved_camera_transfer(self) -> tuple[str, str]:
        """The transfer curve of ``(the colour descriptor, the colour tie-break)``.

        An explicit ``camera_transfer`` sets both.  ``auto``: the folder and OpenCV cameras
        are read as linear by both, chosen by measurement on the real illumination sets
        (``docs/readme/camera-transfer.md``: on 8-bit sRGB images the descriptor's recall
        is the same either way and the tie-break's signature tells the scenes apart as well
        or better read as linear; on linear images reading them as sRGB halves the
        signature's separation); the simulated camera renders linear values, which the
        descriptor reads as they are, while the tie-break keeps the sRGB reading its
        thresholds were measured with in the simulated cell's campaigns.
        """
        if self.camera_transfer != "auto":
            return self.camera_transfer, self.camera_transfer
        if self.camera == "sim":
            return "linear", "srgb"
        return "linear", "linear"

    def redacted_database_url(self) -> str:
        """The database URL with any password replaced by ``***``."""
        from sqlalchemy.engine import make_url

        return make_url(self.database_url).render_as_string(hide_password=True)
