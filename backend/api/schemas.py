"""Request and answer shapes shared by several routers."""

from __future__ import annotations

import math

from pydantic import BaseModel, Field, field_validator


class PoseIn(BaseModel):
    """The chapter's pose (eq. 20): flange position in metres and approach direction
    ``(u, w) = (cos phi, sin phi)`` with ``phi`` the approach angle from the horizontal."""

    x: float
    y: float
    z: float
    u: float
    w: float

    @field_validator("x", "y", "z", "u", "w")
    @classmethod
    def _finite(cls, v: float) -> float:
        if not math.isfinite(v):
            raise ValueError(f"must be finite, got {v!r}")
        return v

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        return (self.x, self.y, self.z, self.u, self.w)


def check_joint_list(v: list[float]) -> list[float]:
    """Validate a list of five finite joint values (the routers' shared check)."""
    if len(v) != 5:
        raise ValueError(f"joints must have 5 values (q1..q5), got {len(v)}")
    bad = [f"q{i + 1}={x!r}" for i, x in enumerate(v) if not math.isfinite(x)]
    if bad:
        raise ValueError(f"joints must be finite, got {', '.join(bad)}")
    return v


class JointsIn(BaseModel):
    """Joint values q1..q5 in radians."""

    joints: list[float] = Field(
        description="q1..q5 in radians", examples=[[0.0, 1.5708, -1.5708, 0.0, 0.0]]
    )

    @field_validator("joints")
    @classmethod
    def _five_finite(cls, v: list[float]) -> list[float]:
        return check_joint_list(v)
