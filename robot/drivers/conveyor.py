"""The ``ConveyorDriver`` protocol: what the cell's emergency stop needs from a conveyor.

A cell's E-STOP halts every moving machine, not only the arm.  A conveyor driver (the
simulated belt today, a PLC or a motor drive tomorrow) only has to stop at once, stay
stopped until the cell is reset, and then go back to what it was doing.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

__all__ = ["ConveyorDriver"]


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
