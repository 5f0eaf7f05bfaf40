"""The trigger and result handshake a line's PLC drives, independent of the protocol.

One :class:`Handshake` per link (the OPC UA server has one, the Modbus TCP server another),
in the style of the vision sensors' PLC handshakes (Cognex In-Sight, Keyence, Matrox):

- **Trigger Enable** (set by the PLC) arms the link; **Trigger Ready** says a trigger would
  be taken now: enabled, not busy, no continuous run, no E-STOP, no result waiting for
  its acknowledgement.
- A **Trigger** starts one inspection of the object at the station with the active
  recipe's options; the link answers with **Trigger Ack** and **Busy**.  A trigger that
  cannot be taken is refused with an **error code** (:class:`ErrorCode`): not enabled,
  while busy, a result not acknowledged, E-STOP, the cell not ready, a role too low.
- When the inspection is stored, its result words are presented and **Results Valid**
  goes high.  The PLC reads them and **acknowledges** (``ack``); the next queued result
  (a continuous run can store several before the PLC reads one) is presented by
  :meth:`Handshake.present_next`.  Results are queued up to ``max_queue``; beyond, the
  oldest is kept and the new one counted as overflow (error code ``RESULTS_OVERFLOW``):
  the PLC has lost nothing it was shown, and it is told that it fell behind.
- The cell's E-STOP reaches the link through the event bus (:class:`CellStopped`) the
  moment it is latched: no polling, no database.

Every change calls the listeners (:meth:`Handshake.add_listener`) with a
:class:`Snapshot`, on the event loop, synchronously: a protocol server copies it into its
registers or variables there and then.  The words themselves (states, codes, the result
and the snapshot) are in :mod:`backend.plc.words`, re-exported here.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import deque
from collections.abc import Callable
from typing import Any

from backend.cell.events import CellStopped, InspectionDone, JobState
from backend.db.models import Role
from backend.inspection import service
from backend.plc import recipes
from backend.plc.words import (
    DECISION_CODES,
    ErrorCode,
    LinkUser,
    PlcResult,
    Snapshot,
    SystemState,
    result_of,
)
from vision.errors import NotFound, VisionCellError

__all__ = [
    "DECISION_CODES",
    "ErrorCode",
    "Handshake",
    "LinkUser",
    "PlcResult",
    "Snapshot",
    "SystemState",
]

log = logging.getLogger(__name__)

#: Most results a link holds for its PLC by default.
DEFAULT_QUEUE = 32


class Handshake:
    """The handshake of one link over one cell runtime (see the module docstring).

    Parameters
    ----------
    rt : CellRuntime
        The running cell.
    name : str
        The link's name for logs (``opcua``, ``modbus``).
    max_queue : int
        Most results held for the PLC (1..1000).
    """

    def __init__(self, rt: Any, *, name: str, max_queue: int = DEFAULT_QUEUE) -> None:
        if (
            isinstance(max_queue, bool)
            or not isinstance(max_queue, int)
            or not 1 <= max_queue <= 1000
        ):
            raise ValueError(f"max_queue must be an integer in 1..1000, got {max_queue!r}")
        self.rt = rt
        self.name = name
        self.max_queue = max_queue
        self._listeners: list[Callable[[Snapshot], None]] = []
        self._removers: list[Callable[[], None]] = []
        self._tasks: set[asyncio.Task[Any]] = set()
        self._queue: deque[PlcResult] = deque()
        self._presented: PlcResult | None = None
        self._valid = False
        self._enabled = False
        self._ack = False
        self._busy = False
        self._estop = False
        self._error = ErrorCode.NONE
        self._error_text = ""
        self._recipe = 0
        self._triggers = 0
        self._overflows = 0
        self._run: Any = None
        self._seen: set[int] = set()
        self._ack_held = False
        self.snapshot = self._make()

    # -- life cycle --------------------------------------------------------------------------
    async def start(self) -> None:
        """Follow the cell's E-STOP, runs and active recipe."""
        bus = self.rt.bus
        self._removers.append(bus.add_listener(self._on_stop, CellStopped))
        self._removers.append(bus.add_listener(self._on_done, InspectionDone))
        self._removers.append(bus.add_listener(self._on_job, JobState))
        self._estop = bool(self.rt.cell.estopped)
        with contextlib.suppress(Exception):
            self._recipe = await recipes.active_number(self.rt)
        self._changed()

    async def stop(self) -> None:
        """Stop following the cell; cancel this link's pending work."""
        for remove in self._removers:
            remove()
        self._removers.clear()
        for task in list(self._tasks):
            task.cancel()
        for task in list(self._tasks):
            with contextlib.suppress(BaseException):
                await task

    def add_listener(self, fn: Callable[[Snapshot], None]) -> None:
        """Call ``fn(snapshot)`` after every change (on the event loop; must not block)."""
        self._listeners.append(fn)
        fn(self.snapshot)

    # -- state -------------------------------------------------------------------------------
    def _running(self) -> bool:
        run = self._run
        return (
            run is not None
            and run.job is not None
            and run.job.task is not None
            and not run.job.task.done()
            and run.job.state.value == "running"
        )

    def _make(self) -> Snapshot:
        running = self._running()
        pending = self._valid or bool(self._queue)
        ready = self._enabled and not (self._busy or running or self._estop or pending)
        if self._estop:
            state = SystemState.ESTOP
        elif self._busy or running:
            state = SystemState.EXECUTING
        elif self._error is not ErrorCode.NONE:
            state = SystemState.ERROR
        elif ready:
            state = SystemState.READY
        else:
            state = SystemState.IDLE
        return Snapshot(
            state=state, trigger_enabled=self._enabled, trigger_ready=ready,
            trigger_ack=self._ack, busy=self._busy or running, results_valid=self._valid,
            running=running, estop=self._estop, error=self._error, error_text=self._error_text,
            recipe=self._recipe, triggers=self._triggers,
            result=self._presented if self._valid or self._presented else None,
            queued=len(self._queue), overflows=self._overflows,
        )  # fmt: skip

    def _changed(self) -> None:
        self.snapshot = self._make()
        for fn in list(self._listeners):
            try:
                fn(self.snapshot)
            except Exception:
                log.exception("PLC link %s: a listener failed", self.name)

    def _fail(self, code: ErrorCode, text: str) -> bool:
        """Set the error code and text (a refusal); returns False."""
        self._error, self._error_text = code, text[:200]
        log.info("PLC link %s: %s (%s)", self.name, code.name, text)
        self._changed()
        return False

    def _spawn(self, coro: Any) -> None:
        task = asyncio.get_running_loop().create_task(coro, name=f"plc-{self.name}")
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    @staticmethod
    def _allowed(user: LinkUser, role: Role) -> bool:
        return int(user.role) >= int(role)

    # -- commands ----------------------------------------------------------------------------
    def set_trigger_enable(self, enabled: bool) -> None:
        """The PLC's Trigger Enable."""
        self._enabled = bool(enabled)
        self._changed()

    async def trigger(self, user: LinkUser) -> bool:
        """Start one inspection; False (and the error code set) when refused."""
        if not self._allowed(user, Role.operator):
            return self._fail(
                ErrorCode.ROLE_TOO_LOW, f"{user.name} ({user.role.name}) may not trigger"
            )
        if self._estop:
            return self._fail(ErrorCode.ESTOP, "stopped by E-STOP")
        if not self._enabled:
            return self._fail(ErrorCode.TRIGGER_NOT_ENABLED, "trigger enable is off")
        if self._busy or self._running():
            return self._fail(ErrorCode.TRIGGER_WHILE_BUSY, "an inspection is going")
        if self._valid or self._queue:
            return self._fail(
                ErrorCode.RESULT_NOT_ACKNOWLEDGED, "the last result is not acknowledged"
            )
        self._busy = True
        self._triggers += 1
        number = self._triggers
        try:
            opts = await recipes.options(self.rt)
            job = await service.start_inspection(self.rt, opts)
        except VisionCellError as exc:
            self._busy = False
            return self._fail(ErrorCode.NOT_READY, f"{exc.code}: {exc}")
        except Exception as exc:  # never take the link down with the cell's error
            log.exception("PLC link %s: trigger failed", self.name)
            self._busy = False
            return self._fail(ErrorCode.INTERNAL, repr(exc))
        self._ack = True
        self._error, self._error_text = ErrorCode.NONE, ""
        self._changed()
        self._spawn(self._finish(job, number))
        return True

    def clear_trigger(self) -> None:
        """The PLC dropped its Trigger: Trigger Ack follows it down."""
        if self._ack:
            self._ack = False
            self._changed()

    async def _finish(self, job: Any, number: int) -> None:
        await self.rt.jobs.wait(job)
        self._busy = False
        result = job.result if isinstance(job.result, dict) else None
        if job.state.value == "done" and result is not None and "inspection" in result:
            self._offer(result_of(result["inspection"], bins=self._bins(), trigger=number))
            return
        err = (job.error or {}).get("detail") or job.state.value
        code = ErrorCode.ESTOP if self._estop else ErrorCode.INSPECTION_FAILED
        self._fail(code, f"inspection {job.state.value}: {err}")

    def _bins(self) -> list[str]:
        sim = getattr(self.rt, "sim", None)
        return [] if sim is None else [b.name for b in sim.config.layout.bins]

    async def _follow_recipe(self) -> None:
        """Read the active recipe's number again (the console or another link may have
        selected one): after each result, off the result's path."""
        with contextlib.suppress(Exception):
            number = await recipes.active_number(self.rt)
            if number != self._recipe:
                self._recipe = number
                self._changed()

    def _offer(self, res: PlcResult) -> None:
        if res.inspection_id in self._seen:  # one inspection is offered once
            return
        self._seen.add(res.inspection_id)
        if len(self._seen) > 100_000:
            self._seen = {res.inspection_id}
        if not self._valid and not self._queue and not self._ack_held:
            self._presented, self._valid = res, True
        elif len(self._queue) >= self.max_queue:
            self._overflows += 1
            self._error = ErrorCode.RESULTS_OVERFLOW
            self._error_text = f"{self._overflows} results dropped: acknowledge faster"
        else:
            self._queue.append(res)
        self._changed()
        self._spawn(self._follow_recipe())

    def acknowledge(self, inspection_id: int | None = None) -> bool:
        """The PLC took the presented result (``inspection_id``: only if it is that one).

        Results Valid drops; :meth:`present_next` shows the next queued result.
        """
        if not self._valid or self._presented is None:
            return False
        if inspection_id is not None and inspection_id != self._presented.inspection_id:
            return False
        self._valid = False
        self._ack_held = True
        self._changed()
        return True

    def present_next(self) -> None:
        """The PLC dropped its Results Ack: present the next queued result, if any."""
        self._ack_held = False
        if not self._valid and self._queue:
            self._presented, self._valid = self._queue.popleft(), True
        self._changed()

    async def start_run(self, user: LinkUser, count: int | None) -> bool:
        """Start continuous operation with the active recipe (``count`` objects, None: until
        stopped); its results are queued for the PLC."""
        if not self._allowed(user, Role.operator):
            return self._fail(
                ErrorCode.ROLE_TOO_LOW, f"{user.name} ({user.role.name}) may not start a run"
            )
        if self._estop:
            return self._fail(ErrorCode.ESTOP, "stopped by E-STOP")
        if self._busy or self._running():
            return self._fail(ErrorCode.TRIGGER_WHILE_BUSY, "an inspection is going")
        try:
            opts = await recipes.options(self.rt)
            resolve = recipes.resolver(self.rt)  # a recipe selected mid-run: the next object
            kw = {} if resolve is None else {"resolve": resolve}
            self._run = service.start_run(self.rt, opts, count, **kw)
        except VisionCellError as exc:
            return self._fail(ErrorCode.NOT_READY, f"{exc.code}: {exc}")
        # the job's end event goes out before its task is done: the state follows the task
        self._run.job.task.add_done_callback(lambda _t: self._changed())
        self._error, self._error_text = ErrorCode.NONE, ""
        self._changed()
        return True

    def stop_run(self, user: LinkUser) -> bool:
        """End the run after the current object."""
        if not self._allowed(user, Role.operator):
            return self._fail(
                ErrorCode.ROLE_TOO_LOW, f"{user.name} ({user.role.name}) may not stop a run"
            )
        if not self._running():
            return self._fail(ErrorCode.NO_RUN, "no run started by this link is going")
        with contextlib.suppress(VisionCellError):
            service.stop_run(self.rt)
        self._changed()
        return True

    async def select_recipe(self, user: LinkUser, number: int) -> bool:
        """Make recipe ``number`` the active one (a line changeover: operators, as over REST;
        only engineers create or change recipes, and not over the PLC links)."""
        if not self._allowed(user, Role.operator):
            return self._fail(
                ErrorCode.ROLE_TOO_LOW, f"{user.name} ({user.role.name}) may not select recipes"
            )
        try:
            self._recipe = await recipes.select(self.rt, number, user=user, link=self.name)
        except VisionCellError as exc:
            code = ErrorCode.RECIPE_UNKNOWN if isinstance(exc, NotFound) else ErrorCode.BAD_REQUEST
            return self._fail(code, f"{exc.code}: {exc}")
        self._error, self._error_text = ErrorCode.NONE, ""
        self._changed()
        return True

    async def reset(self, user: LinkUser) -> bool:
        """Clear the error code and, when latched, the cell's E-STOP (operators)."""
        if not self._allowed(user, Role.operator):
            return self._fail(
                ErrorCode.ROLE_TOO_LOW, f"{user.name} ({user.role.name}) may not reset"
            )
        if self._estop or self.rt.cell.estopped:
            try:
                await self.rt.cell.reset(by=user.name, role=user.role.name, source=self.name)
            except Exception as exc:
                return self._fail(ErrorCode.ESTOP, f"the E-STOP could not be reset: {exc}")
        self._error, self._error_text = ErrorCode.NONE, ""
        self._changed()
        return True

    # -- the cell's events -------------------------------------------------------------------
    def _on_stop(self, ev: CellStopped) -> None:
        self._estop = bool(ev.active)
        self._changed()

    def _on_done(self, ev: Any) -> None:
        if not self._running():
            return  # a trigger's result comes from its job, with the trigger's number
        iid = int(ev.inspection_id)
        self._spawn(self._read_and_offer(iid))

    async def _read_and_offer(self, iid: int) -> None:
        from backend.inspection import results

        async with self.rt.database.session() as session:
            public = results.inspection_public(await results.get_inspection(session, iid))
        self._offer(result_of(public, bins=self._bins(), trigger=0))

    def _on_job(self, ev: JobState) -> None:
        run = self._run
        if run is not None and run.job is not None and ev.job_id == run.job.id:
            self._changed()  # a run ended (or began): busy and state follow
