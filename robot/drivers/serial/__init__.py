"""The serial controller link, in layers: transport, framing, frames, device API, driver.

``SerialDriver`` (the :class:`~robot.drivers.base.RobotDriver`, kept connected by a
:class:`~robot.drivers.serial.supervisor.LinkSupervisor`) is built on
:class:`~robot.drivers.serial.device.SerialDevice` (commands and replies), which uses
:mod:`~robot.drivers.serial.frames` (frames as dataclasses) over
:mod:`~robot.drivers.serial.framing` (lines and CRC-16) over
:class:`~robot.drivers.serial.transport.SerialLink` (pyserial-asyncio).  The emulator's
pseudo-terminal, fault injection and move table live in :mod:`.ptyport`, :mod:`.faults` and
:mod:`.movetable`.  The protocol
is specified in ``docs/serial-protocol.md``.
"""

from robot.drivers.serial.device import DeviceStats, SerialDevice
from robot.drivers.serial.driver import SerialDriver
from robot.drivers.serial.faults import FaultConfig, FaultStats
from robot.drivers.serial.frames import PROTOCOL_VERSION, FrameParser, decode, encode
from robot.drivers.serial.framing import MAX_LINE_BYTES, crc16_ccitt
from robot.drivers.serial.supervisor import LinkSupervisor
from robot.drivers.serial.transport import SerialLink

__all__ = [
    "MAX_LINE_BYTES",
    "PROTOCOL_VERSION",
    "DeviceStats",
    "FaultConfig",
    "FaultStats",
    "FrameParser",
    "LinkSupervisor",
    "SerialDevice",
    "SerialDriver",
    "SerialLink",
    "crc16_ccitt",
    "decode",
    "encode",
]
