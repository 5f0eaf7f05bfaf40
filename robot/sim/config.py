"""The one configuration object of the simulated cell."""

from __future__ import annotations

from dataclasses import dataclass, field

from robot.sim.boards import BoardSpec, default_boards
from robot.sim.camera import CameraSpec
from robot.sim.controller import ControllerGains
from robot.sim.gripper import SuctionCupSpec
from robot.sim.mjcf import ArmDynamics
from robot.sim.world import WorldLayout

__all__ = ["SimConfig"]


@dataclass(frozen=True)
class SimConfig:
    """Everything that shapes one simulated cell.

    Attributes
    ----------
    timestep_s : float
        Physics step; the joint controller runs once per step (1 ms = 1 kHz).
    camera : CameraSpec
        The eye-in-hand camera (mounting, lens, sensor).
    layout : WorldLayout
        Conveyor, table and lights.
    dynamics : ArmDynamics
        Masses, drive friction and torque limits of the arm.
    gains : ControllerGains
        Joint controller.
    gripper : SuctionCupSpec
        The suction cup on the flange.
    slots_per_object : int
        How many objects of each catalogue entry can be on the belt at once.
    boards : tuple of BoardSpec
        Calibration boards that can be placed (at most one per kind).
    shadow_size : int
        Shadow map size of the shadow-casting light (the station spot).
    offsamples : int
        Multisampling of the offscreen render (0 = none; costs CPU with software GL).
    state_rate_hz : float
        How often the arm's state is published to listeners.
    belt_end : {"recycle", "remove"}
        What happens to objects that run off the end of the belt.
    seed : int
        Seeds object yaw on spawning and the camera's noise.
    """

    timestep_s: float = 0.001
    camera: CameraSpec = field(default_factory=CameraSpec)
    layout: WorldLayout = field(default_factory=WorldLayout)
    dynamics: ArmDynamics = field(default_factory=ArmDynamics)
    gains: ControllerGains = field(default_factory=ControllerGains)
    gripper: SuctionCupSpec = field(default_factory=SuctionCupSpec)
    slots_per_object: int = 3
    boards: tuple[BoardSpec, ...] = field(default_factory=default_boards)
    shadow_size: int = 1024
    offsamples: int = 0
    state_rate_hz: float = 50.0
    belt_end: str = "recycle"
    seed: int = 0

    def __post_init__(self) -> None:
        if not 1e-4 <= self.timestep_s <= 2e-3:
            raise ValueError(
                f"timestep_s must be in [0.0001, 0.002] s (controller at >= 500 Hz), got {self.timestep_s!r}"
            )
        if not 1 <= self.slots_per_object <= 20:
            raise ValueError(f"slots_per_object must be in [1, 20], got {self.slots_per_object!r}")
        kinds = [b.kind for b in self.boards]
        if len(set(kinds)) != len(kinds):
            raise ValueError(f"at most one board per kind, got {kinds}")
        if self.offsamples not in (0, 2, 4, 8):
            raise ValueError(f"offsamples must be 0, 2, 4 or 8, got {self.offsamples!r}")
        if self.belt_end not in ("recycle", "remove"):
            raise ValueError(f"belt_end must be 'recycle' or 'remove', got {self.belt_end!r}")
        if not 1.0 <= self.state_rate_hz <= 1000.0:
            raise ValueError(f"state_rate_hz must be in [1, 1000], got {self.state_rate_hz!r}")
