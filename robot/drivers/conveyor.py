"""The ``ConveyorDriver`` protocol: what the cell's emergency stop needs from a conveyor.

A cell's E-STOP halts every moving machine, not only the arm.  A conveyor driver (the
simulated belt today, a PLC or a motor drive tomorrow) only has to stop at once, stay
stopped until the cell is reset, and then go back to what it was doing.  A
:class:`ControlledConveyor` also reports its state (:class:`BeltStatus`) and can be started,
stopped and indexed by the cell: a run waiting for a part shows it and the operator starts it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

__all__ = ["BeltStatus", "ControlledConveyor", "ConveyorDriver"]


@runtime_checkable
class ConveyorDriver(Protocol):
    """A conveyor under the cell's emergency stop."""

    name: str

    @property
    def halted(self) -> bool:
        """True between :meth:`halt` and :meth:`resume`."""

    async def halt(self) -> None:
        """Emergency stop: the belt stands still at once; starting it is refused until
        :meth:`resume`."""

    async def resume(self) -> None:
        """After the cell's reset: the belt runs again if it was running before :meth:`halt`."""


@dataclass(frozen=True)
class BeltStatus:
    """What the operator and a waiting run need to know about a belt."""

    running: bool
    """The belt runs (commanded to, and not held by the emergency stop)."""
    halted: bool
    """The emergency stop holds it."""
    mode: str
    """``continuous``, or ``index``: it stops each object at the station."""
    speed_m_s: float
    """Its speed when it runs, m/s."""
    holding: bool
    """Index mode: it holds an object at the station now."""
    travel_m: float
    """Its encoder: metres travelled since start-up."""
    objects: int | None
    """Objects on it, when the conveyor can count them (None: it cannot)."""

    def as_dict(self) -> dict[str, object]:
        return {"running": self.running, "halted": self.halted, "mode": self.mode,
                "speed_m_s": self.speed_m_s, "holding": self.holding,
                "travel_m": self.travel_m, "objects": self.objects}  # fmt: skip


@runtime_checkable
class ControlledConveyor(ConveyorDriver, Protocol):
    """A conveyor the cell can read, start, stop and index (the simulated belt, a PLC's)."""

    def status(self) -> BeltStatus:
        """Its state now."""

    async def set_running(self, running: bool) -> BeltStatus:
        """Start or stop it; starting it while the emergency stop holds it raises a
        :class:`~robot.errors.RobotError` (409)."""

    async def release(self) -> None:
        """Index mode: let the object held at the station go on."""

    async def hold_at_station(self, hold: bool) -> None:
        """Index mode: hold each object at the station until :meth:`release` (``True``), or
        go back to the belt's own dwell (``False``)."""
