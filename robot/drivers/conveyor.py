"""Conveyor protocols: what the cell's emergency stop and its inspections need from a belt.

A cell's E-STOP halts every moving machine, not only the arm.  A :class:`ConveyorDriver` (the
simulated belt, a PLC or a motor drive) only has to stop at once, stay stopped until the
cell is reset, and then go back to what it was doing.  A :class:`ControlledConveyor` also
reports its state (:class:`BeltStatus`) and can be started, stopped and indexed by the cell:
a run waiting for a part shows it and the operator starts it.

A :class:`Conveyor` is what the inspection reads and drives: its mode and speed, its
encoder travel at an exposure, start (at a mode and speed), stop and release.  Every cell
has one, built by the same factory as the robot driver (``backend.hardware``): the
simulated belt (:class:`robot.sim.SimConveyor`), or on a cell without a belt the cell can
drive a :class:`FixedStation`, which never moves and refuses to start with a reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from robot.errors import RobotError

__all__ = [
    "CONVEYOR_MODES",
    "BeltStatus",
    "ControlledConveyor",
    "Conveyor",
    "ConveyorDriver",
    "FixedStation",
]

#: ``continuous``: the belt runs at its speed; ``index``: it stops each part at the station.
CONVEYOR_MODES = ("continuous", "index")


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


@runtime_checkable
class Conveyor(ControlledConveyor, Protocol):
    """The cell's conveyor as its inspections use it (module docstring)."""

    controllable: bool
    """Whether the cell can start, stop, jog and index it (False: a fixed station)."""

    def travel_at(self, t_s: float | None = None) -> float:
        """Its encoder, metres travelled since start-up, at the monotonic time ``t_s`` of an
        exposure when it keeps a record of it, else now (``None``: now)."""

    async def start(self, *, mode: str | None = None, speed_m_s: float | None = None) -> BeltStatus:
        """Run it (in ``mode`` at ``speed_m_s`` when given); a
        :class:`~robot.errors.RobotError` (409) while the emergency stop holds it or when it
        cannot run at all."""

    async def stop(self) -> BeltStatus:
        """Stop it (the encoder then stands)."""

    async def set_mode(self, mode: str, *, speed_m_s: float) -> BeltStatus:
        """Set its mode (:data:`CONVEYOR_MODES`) and speed, running or not."""


class FixedStation:
    """A station without a belt the cell can drive: parts are put there and taken away by
    hand (or by a line the cell does not control).  Its mode is ``index`` (a part stays at
    the station while it is inspected), it never moves (travel 0), it cannot count parts,
    and starting it is refused with the reason."""

    name = "fixed-station"
    controllable = False

    def __init__(self) -> None:
        self._halted = False

    @property
    def halted(self) -> bool:
        """True between :meth:`halt` and :meth:`resume` (nothing moves either way)."""
        return self._halted

    async def halt(self) -> None:
        """Emergency stop: nothing to stop; noted until :meth:`resume`."""
        self._halted = True

    async def resume(self) -> None:
        """After the cell's reset."""
        self._halted = False

    def status(self) -> BeltStatus:
        """Stopped, ``index``, speed 0, travel 0, parts not counted."""
        return BeltStatus(running=False, halted=self._halted, mode="index", speed_m_s=0.0,
                          holding=False, travel_m=0.0, objects=None)  # fmt: skip

    def travel_at(self, t_s: float | None = None) -> float:
        """Always 0: a fixed station does not move."""
        return 0.0

    async def set_running(self, running: bool) -> BeltStatus:
        """Stopping is a no-op; starting is refused (there is no belt)."""
        if running:
            await self.start()
        return self.status()

    async def start(self, *, mode: str | None = None, speed_m_s: float | None = None) -> BeltStatus:
        """Refused: the station has no belt the cell can run."""
        raise RobotError(
            "this cell's station is fixed: there is no belt the cell can run "
            "(put parts at the station by hand, or describe the belt's controller)"
        )

    async def stop(self) -> BeltStatus:
        """Nothing moves: the status as it is."""
        return self.status()

    async def set_mode(self, mode: str, *, speed_m_s: float) -> BeltStatus:
        """Only ``index`` at speed 0 (what it is); anything else is refused."""
        if mode != "index" or speed_m_s != 0.0:
            raise RobotError(f"this cell's station is fixed: it cannot run {mode!r} at "
                             f"{speed_m_s!r} m/s")  # fmt: skip
        return self.status()

    async def release(self) -> None:
        """Nothing is held: the part is taken away by hand."""

    async def hold_at_station(self, hold: bool) -> None:
        """Nothing to hold: a part put at the station stays there."""
