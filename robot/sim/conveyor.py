"""The simulated belt behind the :class:`~robot.drivers.conveyor.ConveyorDriver` protocol."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from robot.sim.engine import SimEngine

__all__ = ["SimConveyor"]


class SimConveyor:
    """The conveyor of a :class:`~robot.sim.SimEngine` as a conveyor driver."""

    name = "sim-conveyor"

    def __init__(self, engine: SimEngine) -> None:
        self.engine = engine

    @property
    def halted(self) -> bool:
        """True while the emergency stop holds the belt."""
        return self.engine.conveyor_state.halted

    async def halt(self) -> None:
        """Stop the belt at once (latched)."""
        self.engine.halt_conveyor()

    async def resume(self) -> None:
        """Let the belt run again (if it was running)."""
        self.engine.resume_conveyor()
