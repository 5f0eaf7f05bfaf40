"""Build the robot driver, the camera and the cell's world that the settings ask for.

With ``driver="sim"`` or ``camera="sim"`` one :class:`robot.sim.SimEngine` (one per process)
backs both: the simulated arm and the eye-in-hand camera on its flange.  A simulated camera
with another driver draws the arm where that driver reports it.

The cell's world comes with them (:func:`make_world`): the conveyor and the layout (station,
belt, bins) are the simulator's when it runs; otherwise a fixed station
(:class:`robot.drivers.conveyor.FixedStation`) and the layout file of
``VISIONCELL_CELL_LAYOUT`` (or the default station without bins).  Only the simulator knows
the truth (where its objects are), for evaluations.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from backend.settings import Settings
from robot.cellworld import CellLayout, TruthSource
from robot.drivers.base import RobotDriver
from robot.drivers.conveyor import Conveyor, FixedStation
from vision.camera import PinholeCamera
from vision.sources import Camera

if TYPE_CHECKING:
    from robot.sim import SimEngine

__all__ = [
    "CellWorld",
    "Hardware",
    "NominalCamera",
    "make_camera",
    "make_driver",
    "make_hardware",
    "make_sim_engine",
    "make_world",
]


@dataclass(frozen=True)
class NominalCamera:
    """The camera model and mounting a cell uses without an active calibration, when its
    camera comes with exact ones (the simulator's, by construction)."""

    camera: PinholeCamera
    T_ee_cam: NDArray[np.float64]
    label: str


@dataclass(frozen=True)
class CellWorld:
    """The cell around the arm: its conveyor, its layout and, in the simulator, the truth."""

    conveyor: Conveyor
    layout: CellLayout
    truth: TruthSource | None = None
    nominal: NominalCamera | None = None


@dataclass(frozen=True)
class Hardware:
    """The driver, the camera, the cell's world and, when simulated, the engine behind them.

    ``world`` defaults to the one :func:`make_world` builds for ``sim`` and no layout file."""

    driver: RobotDriver
    camera: Camera
    sim: SimEngine | None = None
    world: CellWorld | None = None

    def cell_world(self) -> CellWorld:
        """``world``, or the default for ``sim``."""
        return self.world if self.world is not None else make_world(None, self.sim)


def headless_mujoco() -> None:
    """Render MuJoCo headless (EGL) unless ``MUJOCO_GL`` says otherwise. MuJoCo chooses its
    OpenGL back end when it is imported, so call this before importing ``robot.sim``."""
    os.environ.setdefault("MUJOCO_GL", "egl")


def make_sim_engine(settings: Settings) -> SimEngine:
    """The simulated cell for ``settings`` (demo objects on the belt if ``sim_demo``)."""
    headless_mujoco()
    from robot.sim import SimConfig, SimEngine, populate_demo

    engine = SimEngine(
        SimConfig(state_rate_hz=settings.state_rate_hz), time_scale=settings.time_scale
    )
    if settings.sim_demo:
        populate_demo(engine)
    return engine


def make_driver(settings: Settings, sim: SimEngine | None = None) -> RobotDriver:
    """The :class:`RobotDriver` named by ``settings.driver``."""
    if settings.driver == "ideal":
        from robot.drivers.ideal import IdealDriver

        return IdealDriver(rate_hz=settings.state_rate_hz, time_scale=settings.time_scale)
    if settings.driver == "serial":
        from robot.drivers.serial import SerialDriver

        assert settings.serial_port is not None  # the settings validator guarantees it
        return SerialDriver(
            settings.serial_port, baud=settings.serial_baud, state_rate_hz=settings.state_rate_hz
        )
    if settings.driver == "sim":
        from robot.sim import SimDriver

        return SimDriver(sim if sim is not None else make_sim_engine(settings))
    raise ValueError(f"driver {settings.driver!r} is not available in this build")


def make_camera(
    settings: Settings, sim: SimEngine | None = None, driver: RobotDriver | None = None
) -> Camera:
    """The :class:`Camera` named by ``settings.camera``."""
    if settings.camera == "folder":
        from vision.sources import ImageFolderCamera

        return ImageFolderCamera(
            settings.resolved_camera_folder(),
            loop=True,
            order=settings.camera_order,
            step=settings.camera_replay == "look",
        )
    if settings.camera == "sim":
        from robot.sim import SimCamera

        engine = sim if sim is not None else make_sim_engine(settings)
        follow = None if driver is None or settings.driver == "sim" else (lambda: driver.state)
        return SimCamera(engine, arm_state=follow)
    if settings.camera == "opencv":
        from vision.opencv_camera import OpenCVCamera, classify_source

        kind, _ = classify_source(settings.camera_device)
        # A video file is replayed in a loop (a demo or a recorded run; with camera_replay
        # "look" one frame per look of the cell); devices and streams reconnect on their own,
        # and the cell's camera supervisor re-opens them after that.
        step = settings.camera_replay == "look"
        if step and kind != "file":
            raise ValueError(
                f"camera_replay='look' needs a video file, {settings.camera_device!r} is a {kind}"
            )
        return OpenCVCamera(
            settings.camera_device, fps=settings.camera_fps, loop=kind == "file", step=step
        )
    raise ValueError(f"camera {settings.camera!r} is not available in this build")


def make_world(settings: Settings | None, sim: SimEngine | None = None) -> CellWorld:
    """The conveyor, the layout and the truth of the cell: the simulator's when ``sim``, else
    a fixed station with the layout file of ``settings.cell_layout`` (the default station
    without bins when unset)."""
    if sim is not None:
        from robot.sim import SimConveyor
        from robot.sim.layout import SimObjectTruth, cell_layout

        cam = sim.config.camera
        nominal = NominalCamera(cam.pinhole, np.asarray(cam.T_ee_cam, dtype=np.float64),
                                "simulator nominal")  # fmt: skip
        return CellWorld(SimConveyor(sim), cell_layout(sim.config.layout), SimObjectTruth(sim),
                         nominal)  # fmt: skip
    path = None if settings is None else settings.cell_layout
    if path is None:
        return CellWorld(FixedStation(), CellLayout())
    from robot.layoutfile import load_layout

    return CellWorld(FixedStation(), load_layout(path))


def make_hardware(settings: Settings) -> Hardware:
    """Driver, camera and the cell's world for ``settings``, sharing one simulation engine
    where both are simulated."""
    sim = make_sim_engine(settings) if "sim" in (settings.driver, settings.camera) else None
    driver = make_driver(settings, sim)
    return Hardware(driver, make_camera(settings, sim, driver), sim, make_world(settings, sim))
