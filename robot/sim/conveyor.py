"""The simulated belt behind the :class:`~robot.drivers.conveyor.Conveyor` protocol."""

from __future__ import annotations

from typing import TYPE_CHECKING

from robot.drivers.conveyor import BeltStatus

if TYPE_CHECKING:
    from robot.sim.engine import SimEngine

__all__ = ["SimConveyor"]


class SimConveyor:
    """The conveyor of a :class:`~robot.sim.SimEngine` as a conveyor driver."""

    name = "sim-conveyor"
    controllable = True

    def __init__(self, engine: SimEngine) -> None:
        self.engine = engine
        self._own_dwell: float | str | None = "none held"

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

    def status(self) -> BeltStatus:
        """The belt's state; ``objects`` counts the objects riding it (the simulator knows)."""
        st = self.engine.conveyor_state
        return BeltStatus(bool(st.running), bool(st.halted), str(st.mode), float(st.speed_m_s),
                          bool(st.at_station), float(st.travel_m), len(self.engine.objects()))  # fmt: skip

    async def set_running(self, running: bool) -> BeltStatus:
        """Start or stop the belt (refused while the emergency stop holds it)."""
        self.engine.configure_conveyor(running=bool(running))
        return self.status()

    def travel_at(self, t_s: float | None = None) -> float:
        """The belt's encoder now.  The simulated camera latches the encoder with each frame
        (``Frame.meta["belt_travel_m"]``), which the cell prefers; ``t_s`` is not looked up."""
        return float(self.engine.conveyor_state.travel_m)

    async def start(self, *, mode: str | None = None, speed_m_s: float | None = None) -> BeltStatus:
        """Run the belt (in ``mode`` at ``speed_m_s`` when given; refused while the emergency
        stop holds it)."""
        self.engine.configure_conveyor(running=True, mode=mode, speed_m_s=speed_m_s)
        return self.status()

    async def stop(self) -> BeltStatus:
        """Stop the belt."""
        self.engine.configure_conveyor(running=False)
        return self.status()

    async def set_mode(self, mode: str, *, speed_m_s: float) -> BeltStatus:
        """Set the belt's mode and speed, running or not."""
        self.engine.configure_conveyor(mode=mode, speed_m_s=speed_m_s)
        return self.status()

    async def release(self) -> None:
        """Index mode: let the object at the station go on."""
        self.engine.release_conveyor()

    async def hold_at_station(self, hold: bool) -> None:
        """Hold each object at the station until released (the belt's dwell kept aside),
        or give the belt its own dwell back."""
        if hold:
            if self._own_dwell == "none held":
                self._own_dwell = self.engine.conveyor_state.dwell_s
            self.engine.configure_conveyor(dwell_s=None)
        elif self._own_dwell != "none held":
            dwell, self._own_dwell = self._own_dwell, "none held"
            self.engine.configure_conveyor(dwell_s=dwell)
