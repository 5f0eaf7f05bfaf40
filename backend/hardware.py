"""Build the robot driver and the camera that the settings ask for."""

from __future__ import annotations

from backend.settings import Settings
from robot.drivers.base import RobotDriver
from vision.sources import Camera

__all__ = ["make_camera", "make_driver"]


def make_driver(settings: Settings) -> RobotDriver:
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
    raise ValueError(f"driver {settings.driver!r} is not available in this build")


def make_camera(settings: Settings) -> Camera:
    """The :class:`Camera` named by ``settings.camera``."""
    if settings.camera == "folder":
        from vision.sources import ImageFolderCamera

        return ImageFolderCamera(settings.resolved_camera_folder(), loop=True)
    raise ValueError(f"camera {settings.camera!r} is not available in this build")
