"""The demo cell of ``make run``: a few catalogue objects on a belt indexing at the station."""

from __future__ import annotations

from robot.sim.engine import SimEngine
from robot.sim.truth import ObjectTruth

__all__ = ["DEMO_OBJECTS", "populate_demo"]

#: What the demo belt carries, from the station upstream.
DEMO_OBJECTS = (
    "wheel-5spoke",
    "wheel-7spoke-curved",
    "gear-housing",
    "wheel-5spoke-redband",
    "bracket-upright",
    "wheel-steel",
)


def populate_demo(
    engine: SimEngine,
    *,
    names: tuple[str, ...] = DEMO_OBJECTS,
    spacing_m: float = 0.42,
    speed_m_s: float = 0.08,
    dwell_s: float = 4.0,
) -> list[ObjectTruth]:
    """Spawn ``names`` every ``spacing_m`` upstream of the station (the first at it), and run
    the belt in index mode, objects recycled at the end (section 4.1: an assembly line at
    constant speed carrying car wheels)."""
    spec = engine.config.layout.conveyor
    if spacing_m * len(names) > spec.length_m:
        raise ValueError(
            f"{len(names)} objects every {spacing_m} m do not fit on a {spec.length_m:g} m belt"
        )
    out = []
    for k, name in enumerate(names):
        s = (spec.station_s_m - k * spacing_m) % spec.length_m
        out.append(engine.spawn(name, s_m=s))
    engine.configure_conveyor(running=True, speed_m_s=speed_m_s, mode="index", dwell_s=dwell_s)
    return out
