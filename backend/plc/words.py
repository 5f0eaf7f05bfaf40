"""What a link shows its PLC (:mod:`backend.plc.handshake`): the system state, the error
codes, the decision codes, a stored inspection in the units a PLC reads and the link's
whole state at one moment (:class:`Snapshot`)."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any

from backend.db.models import Role


class SystemState(enum.IntEnum):
    """The cell's state as a PLC sees it (OPC 40100's system states where they fit)."""

    IDLE = 0
    """Trigger not enabled, nothing running."""
    READY = 1
    """A trigger would be taken now."""
    EXECUTING = 2
    """An inspection or a continuous run is going."""
    ERROR = 3
    """The last command was refused or failed (see the error code); reset clears it."""
    ESTOP = 4
    """Stopped by E-STOP (latched until reset)."""

    @property
    def label(self) -> str:
        """The name shown to the PLC and the MES."""
        return {4: "Stopped by E-STOP"}.get(int(self), self.name.capitalize())


class ErrorCode(enum.IntEnum):
    """Why the last command was refused or failed (0: none)."""

    NONE = 0
    TRIGGER_NOT_ENABLED = 1
    TRIGGER_WHILE_BUSY = 2
    RESULT_NOT_ACKNOWLEDGED = 3
    ESTOP = 4
    NOT_READY = 5
    """The cell refused: arm busy, nothing trained, camera or link down."""
    INSPECTION_FAILED = 6
    """The inspection's job failed or was cancelled before storing a result."""
    RESULTS_OVERFLOW = 7
    RECIPE_UNKNOWN = 8
    ROLE_TOO_LOW = 10
    NO_RUN = 11
    """Stop was asked with no run going."""
    BAD_REQUEST = 12
    INTERNAL = 99


#: Decision words of the result (0: no result).
DECISION_CODES = {"recognized": 1, "unknown": 2, "failed": 3}


@dataclass(frozen=True)
class LinkUser:
    """Who drives a link: a VisionCell user's name and role."""

    name: str
    role: Role


@dataclass(frozen=True)
class PlcResult:
    """One stored inspection, in the units a PLC reads."""

    inspection_id: int
    decision: str
    """``recognized``, ``unknown`` or ``failed``."""
    model: str | None
    model_id: int
    """The model's database id (0: none)."""
    score: float | None
    x_m: float | None
    """Object position in the robot base frame, metres (None: no pose)."""
    y_m: float | None
    yaw_rad: float | None
    """Rotation about the base z axis, radians in [-pi, pi)."""
    bin: int
    """1-based index of the bin in the cell's layout (0: not sorted)."""
    bin_name: str | None
    duration_s: float
    trigger: int
    """The trigger number that asked for it (0: from a continuous run)."""

    @property
    def decision_code(self) -> int:
        """:data:`DECISION_CODES` of the decision."""
        return DECISION_CODES.get(self.decision, 3)


@dataclass(frozen=True)
class Snapshot:
    """The link's whole state at one moment."""

    state: SystemState
    trigger_enabled: bool
    trigger_ready: bool
    trigger_ack: bool
    busy: bool
    results_valid: bool
    running: bool
    estop: bool
    error: ErrorCode
    error_text: str
    recipe: int
    triggers: int
    """Triggers taken so far (the last one's number)."""
    result: PlcResult | None
    """The result presented now (None before the first)."""
    queued: int
    """Results waiting behind the presented one."""
    overflows: int


def result_of(public: dict[str, Any], *, bins: list[str], trigger: int) -> PlcResult:
    """A :class:`PlcResult` from an inspection's API form (``inspection_public``)."""
    pose = public.get("pose") if isinstance(public.get("pose"), dict) else None
    x = y = yaw = None
    if pose is not None:
        pos = pose.get("position_m") or [row[3] for row in pose.get("T_base_obj", [])[:3]]
        if len(pos) >= 2 and all(math.isfinite(float(v)) for v in pos[:2]):
            x, y = float(pos[0]), float(pos[1])
        if pose.get("yaw_rad") is not None and math.isfinite(float(pose["yaw_rad"])):
            yaw = math.remainder(float(pose["yaw_rad"]), 2 * math.pi)
    outcome = public.get("pick_outcome") or {}
    bin_name = outcome.get("bin") if isinstance(outcome.get("bin"), str) else None
    return PlcResult(
        inspection_id=int(public["id"]),
        decision=str(public["decision"]),
        model=public.get("model"),
        model_id=int(public.get("model_id") or 0),
        score=None if public.get("score") is None else float(public["score"]),
        x_m=x,
        y_m=y,
        yaw_rad=yaw,
        bin=bins.index(bin_name) + 1 if bin_name in bins else 0,
        bin_name=bin_name,
        duration_s=float(public.get("duration_s") or 0.0),
        trigger=trigger,
    )
