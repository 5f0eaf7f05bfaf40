"""Inspections as jobs: one object (:func:`start_inspection`) and continuous operation
(:func:`start_run`, :func:`stop_run`), holding the cell while it is not ready
(:func:`hold_until_ready`)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from backend.inspection import recovery
from backend.inspection.context import Context, belt_state, context
from backend.inspection.errors import NOT_TRAINED, NotReady
from backend.inspection.find import Waiting
from backend.inspection.inspect import inspect_object
from backend.inspection.options import (
    MAX_COUNT,
    InspectOptions,
    Resolve,
    apply_belt_mode,
    check_belt_mode,
    resolved,
)
from backend.inspection.pose import warm_feature_heights
from backend.inspection.waiting import PartTracker, conveyor_of
from vision.errors import Conflict, InvalidInput, NothingTrained, VisionCellError

if TYPE_CHECKING:
    from backend.runtime import CellRuntime

__all__ = ["InspectionRun", "hold_until_ready", "readiness", "start_inspection", "start_run",
           "stop_run"]  # fmt: skip

log = logging.getLogger(__name__)


@dataclass
class InspectionRun:
    """Continuous operation: inspect objects until stopped or ``count`` done."""

    options: InspectOptions
    count: int | None
    #: Reads the options again before each object (None: ``options`` throughout).
    resolve: Resolve | None = None
    done: int = 0
    ids: list[int] = field(default_factory=list)
    stop_requested: bool = False
    job: Any = None


def _check_ready(rt: CellRuntime) -> None:
    """409 at once (not in the job): e-stop, arm busy, nothing trained."""
    rt.cell.check_can_move()
    rt.jobs.check_arm_free()
    if len(rt.live_index) == 0:
        raise NothingTrained(NOT_TRAINED)


async def start_inspection(rt: CellRuntime, opts: InspectOptions) -> Any:
    """Start a job inspecting the object at the station; returns the job.  The options'
    belt mode (a recipe's) is set before the part is looked for."""
    _check_ready(rt)
    check_belt_mode(rt, opts)
    ctx = await context(rt)

    async def body(job: Any) -> dict[str, Any]:
        await apply_belt_mode(rt, opts)
        out = await inspect_object(ctx, opts, job, db_wait_s=opts.wait_s)
        assert out is not None  # only a run's wait can be stopped
        return {"inspection": out, "inspection_id": out["id"]}

    return rt.jobs.start("inspect", body, motion=True,
                         params={"policy": opts.policy, "sort": opts.sort, "camera_model": ctx.source,
                                 "recipe": opts.recipe_name})  # fmt: skip


def readiness(rt: CellRuntime) -> list[str]:
    """What keeps the cell from starting an inspection now (empty: ready): the camera
    failing, the arm's link down; the database is checked by :func:`hold_until_ready`."""
    why = []
    cam = rt.cell.camera_status()
    if not cam.ok:
        why.append(f"camera {cam.name}: {cam.error or 'no frames yet'}")
    st = rt.cell.state
    if not st.connected:
        why.append(f"robot link down{': ' + st.fault if st.fault else ''}")
    return why


async def hold_until_ready(rt: CellRuntime, job: Any, *, max_s: float | None = None) -> float:
    """Wait, without moving, until :func:`readiness` is empty and the database answers
    (backoff with jitter between checks); returns the seconds held.  A continuous run
    calls it before every object, so a fault holds the cell and the run goes on by itself
    when the fault clears."""
    from robot.backoff import Backoff

    b = Backoff(initial_s=0.1, max_s=2.0)
    t0 = time.monotonic()
    said = ""
    while True:
        why = readiness(rt)
        if not why and not await rt.database.ping():
            why.append("database unavailable")
        if not why:
            if said:
                log.info("cell ready again after %.1f s", time.monotonic() - t0)
                job.report(job.progress, "ready again: inspecting")
            return time.monotonic() - t0
        msg = "holding: " + "; ".join(why)
        if msg != said:
            log.warning("%s", msg)
            said = msg
        job.report(job.progress, msg)
        if max_s is not None and time.monotonic() - t0 >= max_s:
            raise Conflict(f"the cell is not ready after {max_s:g} s: {msg}")
        await b.sleep()


def start_run(
    rt: CellRuntime, opts: InspectOptions, count: int | None, *, resolve: Resolve | None = None
) -> InspectionRun:
    """Start continuous operation (a job); :func:`stop_run` ends it after the current object.

    ``resolve`` (a run following the active recipe): the options are read again before
    each object (its belt mode set then) and once the part is found, so a recipe selected
    between two objects applies to the next one; ``opts`` are those of the first."""
    if count is not None and (
        isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_COUNT
    ):
        raise InvalidInput(f"count must be an integer in 1..{MAX_COUNT} or null, got {count!r}")
    cur = rt.inspection.run
    if (
        cur is not None
        and cur.job is not None
        and cur.job.task is not None
        and not cur.job.task.done()
    ):
        raise Conflict("an inspection run is already going: stop it first")
    _check_ready(rt)
    check_belt_mode(rt, opts)
    run = InspectionRun(opts, count, resolve)

    async def body(job: Any) -> dict[str, Any]:
        async def read_context(progress: float) -> Context:
            def holding(m: str) -> None:
                job.report(progress, "holding: " + m)

            return await recovery.retry_database(
                "reading the calibration", lambda: context(rt), on_wait=holding
            )

        ctx = await recovery.retry_database(
            "reading the calibration", lambda: context(rt), on_wait=lambda m: job.report(0.0, m)
        )
        job.report(0.0, "triangulating the models' taught top views")
        try:
            await warm_feature_heights(ctx)
        except Exception:  # the pose triangulates on first use instead
            log.warning("could not triangulate the taught views ahead of the run", exc_info=True)
        decisions: dict[str, int] = {}
        first = True  # the context read above is the first object's
        tracker = PartTracker()
        conveyor = conveyor_of(rt)
        if conveyor is not None:  # the run indexes the belt: each part waits for its release
            await conveyor.hold_at_station(True)
        try:
            while not run.stop_requested and (count is None or run.done < count):
                await hold_until_ready(rt, job)
                run.options = await resolved(resolve, run.options)
                progress = 0.0 if count is None else run.done / count
                waiting = Waiting(report=lambda m, p=progress: job.report(p, m),
                                  stopped=lambda: run.stop_requested, forever=True)  # fmt: skip
                try:
                    await apply_belt_mode(rt, run.options)
                    if not first:  # each object's own context (calibration)
                        ctx = await read_context(progress)
                    first = False
                    out = await inspect_object(ctx, run.options, None, tracker=tracker,
                                               waiting=waiting, resolve=resolve)  # fmt: skip
                except NotReady:
                    raise
                except (VisionCellError, ValueError) as exc:  # looking for a part failed
                    why = f"{getattr(exc, 'code', 'error')}: {getattr(exc, 'detail', exc)}"
                    log.warning("looking for a part: %s", why)
                    job.report(progress, f"looking for a part failed ({why}): trying again")
                    await asyncio.sleep(1.0)
                    continue
                if out is None:  # stopped while waiting for a part
                    break
                run.done += 1
                run.ids.append(out["id"])
                decisions[out["decision"]] = decisions.get(out["decision"], 0) + 1
                job.report(0.0 if count is None else run.done / count,
                           f"{run.done} inspected: {out['decision']} {out['model'] or ''}".strip())  # fmt: skip
                # A failed inspection looks at the same part again; after any other the
                # belt brings the next (index mode: the part held at the station goes on).
                if (
                    out["decision"] != "failed"
                    and conveyor is not None
                    and belt_state(rt)[0] == "index"
                ):
                    with contextlib.suppress(Exception):
                        await conveyor.release()
        finally:
            if conveyor is not None:
                with contextlib.suppress(Exception):
                    await conveyor.hold_at_station(False)
        return {"inspected": run.done, "inspection_ids": run.ids, "decisions": decisions,
                "stopped": run.stop_requested}  # fmt: skip

    run.job = rt.jobs.start("inspection-run", body, motion=True,
                            params={"policy": opts.policy, "sort": opts.sort, "count": count,
                                    "recipe": opts.recipe_name})  # fmt: skip
    rt.inspection.run = run
    return run


def stop_run(rt: CellRuntime) -> InspectionRun:
    """Ask the run to end after the current object (:class:`Conflict` if none is going)."""
    run = rt.inspection.run
    if run is None or run.job is None or run.job.task is None or run.job.task.done():
        raise Conflict("no inspection run is going")
    run.stop_requested = True
    return run
