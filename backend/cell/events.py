"""The cell's typed event bus: what happened, as small frozen dataclasses.

Publishers (the job manager, the arm-state publisher, the camera supervisor, calibration
and, next, inspection runs) call :meth:`EventBus.publish` on the event loop's thread.
Subscribers are either callbacks (:meth:`EventBus.add_listener`, called at once, must not
block) or async iterators (:meth:`EventBus.subscribe`) with a bounded queue that drops the
oldest event when a slow reader falls behind, so no subscriber can make memory grow.

The WebSocket (``backend.api.routes.live``), the 3D view and logs subscribe.  There is one
bus per cell (no module-global registry).

Events
------
- :class:`JobState`: a job started or ended (its public form included).
- :class:`JobProgress`: a running job reported progress.
- :class:`ArmState`: the arm's state (published at a bounded rate, and at once when
  ``connected``, ``estopped`` or ``fault`` change).
- :class:`CameraStatus`: the camera's health changed (``ok`` or ``error``).
- :class:`CellStopped`: the cell-wide emergency stop was pressed or reset.
- :class:`CalibrationView`: an automatic calibration run cleared its views or stored one.
- :class:`InspectionDone`: an inspection ended and its result was stored.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from backend.jobs import Job
    from robot.drivers.base import RobotState

__all__ = [
    "ArmState",
    "CalibrationView",
    "CameraStatus",
    "CellEvent",
    "CellStopped",
    "EventBus",
    "InspectionDone",
    "JobProgress",
    "JobState",
    "Subscription",
]

log = logging.getLogger(__name__)

#: Largest queue of one async subscriber (older events are dropped beyond it).
MAX_QUEUE = 1000


@dataclass(frozen=True)
class CellEvent:
    """Base of every event on the bus."""

    stamp_s: float = field(default_factory=time.monotonic, kw_only=True)
    """``time.monotonic()`` when the event was made."""


@dataclass(frozen=True)
class JobState(CellEvent):
    """A job started (``state == "running"``) or ended (done, failed, cancelled)."""

    job_id: str
    """The job's id."""
    kind: str
    """What the job does (``move``, ``auto_calibrate``, ...)."""
    state: str
    """``running``, ``done``, ``failed`` or ``cancelled``."""
    job: dict[str, Any]
    """``Job.public()`` at that moment (the WebSocket sends it as is)."""

    @classmethod
    def of(cls, job: Job) -> JobState:
        """The event for ``job`` as it is now."""
        return cls(job.id, job.kind, job.state.value, job.public())


@dataclass(frozen=True)
class JobProgress(CellEvent):
    """A running job reported progress."""

    job_id: str
    """The job's id."""
    kind: str
    """What the job does."""
    progress: float
    """Fraction done, in [0, 1]."""
    message: str
    """What it is doing now."""
    job: dict[str, Any]
    """``Job.public()`` at that moment."""

    @classmethod
    def of(cls, job: Job) -> JobProgress:
        """The event for ``job`` as it is now."""
        return cls(job.id, job.kind, job.progress, job.message, job.public())


@dataclass(frozen=True)
class ArmState(CellEvent):
    """The arm's state and the cell's default speed."""

    state: RobotState
    """The driver's latest state."""
    speed: float
    """The cell's default speed fraction, (0, 1]."""


@dataclass(frozen=True)
class CameraStatus(CellEvent):
    """What the console shows about the image source."""

    name: str
    """The camera's name (``sim``, ``folder``, ``opencv``)."""
    ok: bool
    """True while frames arrive and the last attempt did not fail."""
    frames: int
    """Frames acquired since start."""
    fps: float
    """Smoothed acquisition rate, frames/s."""
    error: str
    """The last failure (``Type: message``), empty when healthy."""
    retries: int = 0
    """Failed attempts in the current outage (0 when healthy)."""

    def as_dict(self) -> dict[str, Any]:
        """JSON form (the camera status of the API)."""
        return {
            "name": self.name,
            "ok": self.ok,
            "frames": self.frames,
            "fps": self.fps,
            "error": self.error,
            "retries": self.retries,
        }


@dataclass(frozen=True)
class CellStopped(CellEvent):
    """The cell-wide emergency stop was pressed (``active``) or reset (not ``active``)."""

    active: bool
    """True after E-STOP, False after reset."""
    conveyors: tuple[str, ...] = ()
    """Names of the conveyors halted or resumed with the arm."""
    by: str = "system"
    """Who pressed it: a user's name, or ``system``."""
    role: str = "system"
    """That user's role name (``system`` for the cell itself)."""
    source: str = "cell"
    """Where it was pressed: ``rest``, ``ws``, ``view3d``, ``cli`` (through REST), ``cell``."""
    arm_latched: bool = True
    """Whether the arm's driver confirmed the stop (or the reset)."""
    jobs: tuple[str, ...] = ()
    """Ids of the motion jobs the stop cancelled."""


@dataclass(frozen=True, eq=False)  # holds an array: compared by identity
class CalibrationView(CellEvent):
    """An automatic calibration run started (``cleared``) or stored one view."""

    cleared: bool
    """True when a run starts: forget the previous run's views."""
    T_base_cam: NDArray[np.float64] | None = None
    """Pose of the camera of the stored view (4x4, metres); None when ``cleared``."""
    board_found: bool = False
    """Whether the board was detected in that view."""


@dataclass(frozen=True)
class InspectionDone(CellEvent):
    """An inspection ended (WebSocket ``{"type": "inspection", ...}``)."""

    inspection_id: int
    decision: str
    model: str | None
    reason: str
    score: float | None
    viewpoints: tuple[int, ...]
    T_base_obj: tuple[tuple[float, ...], ...] | None
    T_base_cams: tuple[tuple[tuple[float, ...], ...], ...]
    pick: dict[str, Any] | None = None
    #: The recipe the inspection ran under (id, name; None: none).
    recipe_id: int | None = None
    recipe: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "id": self.inspection_id,
            "decision": self.decision,
            "model": self.model,
            "reason": self.reason,
            "score": self.score,
            "viewpoints": list(self.viewpoints),
            "T_base_obj": None if self.T_base_obj is None else [list(r) for r in self.T_base_obj],
            "T_base_cams": [[list(r) for r in T] for T in self.T_base_cams],
            "pick": self.pick,
            "recipe_id": self.recipe_id,
            "recipe": self.recipe,
        }


E = TypeVar("E", bound=CellEvent)


class Subscription(AsyncIterator[CellEvent]):
    """An async iterator over the bus's events of some types; close it when done.

    Holds at most ``maxsize`` events; when full the oldest is dropped (``dropped`` counts
    them).
    """

    def __init__(self, bus: EventBus, types: tuple[type[CellEvent], ...], maxsize: int) -> None:
        self._bus = bus
        self.types = types
        self._queue: asyncio.Queue[CellEvent] = asyncio.Queue(maxsize=maxsize)
        self.dropped = 0

    def _offer(self, event: CellEvent) -> None:
        if self.types and not isinstance(event, self.types):
            return
        if self._queue.full():
            with contextlib.suppress(asyncio.QueueEmpty):
                self._queue.get_nowait()
            self.dropped += 1
        self._queue.put_nowait(event)

    def __aiter__(self) -> Subscription:
        return self

    async def __anext__(self) -> CellEvent:
        return await self._queue.get()

    async def get(self, *, timeout_s: float | None = None) -> CellEvent | None:
        """The next event, or None after ``timeout_s``."""
        if timeout_s is None:
            return await self._queue.get()
        try:
            return await asyncio.wait_for(self._queue.get(), max(0.0, timeout_s))
        except TimeoutError:
            return None

    def close(self) -> None:
        """Stop receiving events."""
        self._bus._subs.discard(self)

    def __enter__(self) -> Subscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class EventBus:
    """Publish/subscribe of :class:`CellEvent` within one cell (event-loop thread only)."""

    def __init__(self) -> None:
        self._subs: set[Subscription] = set()
        self._listeners: list[tuple[tuple[type[CellEvent], ...], Callable[[Any], None]]] = []
        self.published = 0

    def publish(self, event: CellEvent) -> None:
        """Hand ``event`` to every listener and subscription (never raises for theirs)."""
        if not isinstance(event, CellEvent):
            raise TypeError(f"events must be CellEvent dataclasses, got {type(event).__name__}")
        self.published += 1
        for types, fn in list(self._listeners):
            if types and not isinstance(event, types):
                continue
            try:
                fn(event)
            except Exception:  # one broken listener must not break the publisher
                log.exception("event listener %r failed on %s", fn, type(event).__name__)
        for sub in list(self._subs):
            sub._offer(event)

    def add_listener(self, fn: Callable[[E], None], *types: type[E]) -> Callable[[], None]:
        """Call ``fn(event)`` for events of ``types`` (all when none); returns the remover."""
        entry = (tuple(types), fn)
        self._listeners.append(entry)

        def remove() -> None:
            if entry in self._listeners:
                self._listeners.remove(entry)

        return remove

    def subscribe(self, *types: type[CellEvent], maxsize: int = 256) -> Subscription:
        """An async iterator over events of ``types`` (all when none)."""
        if not 1 <= int(maxsize) <= MAX_QUEUE:
            raise ValueError(f"maxsize must be in [1, {MAX_QUEUE}], got {maxsize!r}")
        sub = Subscription(self, tuple(types), int(maxsize))
        self._subs.add(sub)
        return sub

    @property
    def subscriber_count(self) -> int:
        """Async subscriptions open now."""
        return len(self._subs)
