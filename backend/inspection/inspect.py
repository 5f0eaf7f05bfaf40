"""One inspection (:func:`inspect_object`): find the part, then recognise, pose and sort it
(:mod:`backend.inspection.stages`), and record the result (:mod:`backend.inspection.record`).

Durations per stage (seconds of wall time, :class:`~backend.inspection.stopwatch.Stopwatch`):
``wait`` (for the part to lie still), ``move``, ``settle``, ``acquire`` (as the cell times
its looks), ``plan``, ``segment``, ``features`` and ``match`` (recognition, the match as it
times its verification), ``decide``, ``pose``, ``pick``.  The row's ``duration_s`` is the
inspection's wall time, from its start (the search's, or the moment its part came after a
wait) to its end.
"""

from __future__ import annotations

import asyncio
import logging
from datetime import timedelta
from typing import Any

from backend.db.types import utcnow
from backend.inspection import record, recovery
from backend.inspection.context import Context, read_plan
from backend.inspection.draft import InspectionDraft
from backend.inspection.find import Found, Waiting, find_part, look_whole
from backend.inspection.options import InspectOptions, Resolve, resolved
from backend.inspection.sort import reject_failed
from backend.inspection.stages import run_stages
from backend.inspection.stopwatch import Stopwatch
from backend.reports.scenes import SceneRecorder
from vision.errors import VisionCellError

__all__ = ["inspect_object"]

log = logging.getLogger(__name__)


async def inspect_object(ctx: Context, opts: InspectOptions, job: Any = None, *,
                         tracker: Any = None, waiting: Waiting | None = None,
                         db_wait_s: float | None = None, resolve: Resolve | None = None,
                         watch: Stopwatch | None = None) -> dict[str, Any] | None:  # fmt: skip
    """Inspect the next part at the station and store the result (module docstring).

    First the part is found (:func:`~backend.inspection.find.find_part`): waiting for it is
    not an inspection, so it stores nothing -- :class:`~backend.inspection.errors.NoObject`
    when none comes within ``opts.wait_s``, None when ``waiting.stopped()`` ends the wait (a
    run asked to stop), and a cancellation while waiting leaves no row.  ``tracker``
    (continuous operation, index mode): the part inspected last is not taken again
    (:class:`~backend.inspection.waiting.PartTracker`).

    Returns the stored inspection's public form; its ``duration_s`` is the wall time from
    the inspection's start (the part found at once: the search's start; else the moment it
    came) to its end.  Cut short (cancel: e-stop or stop), the complete ``failed`` row is
    stored with the reason before the cancellation goes on.

    Faults: an in-progress marker is committed once the part is found (waiting,
    without moving, up to ``db_wait_s`` -- None: until cancelled -- while the database is
    unavailable); any failure inside becomes a ``failed`` row with its reason; the row is
    stored with retries until the database takes it, in the transaction that removes the
    marker.

    ``resolve`` (a run following a recipe): the options are read again once the part is
    found, so a recipe selected while the run waited applies to this part.  ``watch``: the
    stopwatch the stages are timed on (default: a new one on the monotonic clock).
    """
    cell = ctx.rt.cell
    report = (lambda f, m: job.report(f, m)) if job is not None else (lambda f, m: None)
    if waiting is None:
        waiting = Waiting(report=lambda m: report(0.05, m))
    plan = await recovery.retry_database(
        "reading the calibration", lambda: read_plan(ctx), max_wait_s=db_wait_s,
        on_wait=lambda m: report(0.0, "holding: " + m),
    )  # fmt: skip
    watch = watch or Stopwatch()
    report(0.05, "looking for a part at the station")
    if plan.bg is None:
        found: Found | None = await look_whole(ctx, opts, plan.top.q, watch)
    else:
        found = await find_part(ctx, opts, plan.top.q, plan.bg, watch, tracker=tracker,
                                waiting=waiting)  # fmt: skip
    if found is None:
        return None
    opts = await resolved(resolve, opts)
    started = utcnow() - timedelta(seconds=watch.clock() - found.t_start)
    draft = InspectionDraft(u_m=found.u_m, watch=watch,
                            scene=SceneRecorder(getattr(ctx.rt.view3d, "server", None)))  # fmt: skip
    db = ctx.rt.database
    # The durable marker goes in before the inspection moves the arm past the top view (a
    # database outage holds here: no motion); the result's transaction removes it.
    marker = await recovery.retry_database(
        "starting an inspection", lambda: recovery.begin(db, ctx.rt.cell_id, opts.policy),
        max_wait_s=db_wait_s, on_wait=lambda m: report(0.05, "holding: " + m),
    )  # fmt: skip
    try:
        await run_stages(ctx, opts, plan, found, draft, report)
    except asyncio.CancelledError:
        why = "emergency stop" if cell.estopped else "stopped"
        draft.fail(f"{why} during {draft.stage or 'the inspection'}")
        await asyncio.shield(
            record.store(ctx, opts, draft, started, marker=marker, t_start=found.t_start)
        )
        raise
    except (VisionCellError, ValueError) as exc:
        draft.fail(f"{getattr(exc, 'code', 'error')}: {getattr(exc, 'detail', str(exc))}")
        await reject_failed(ctx, opts, draft)
    except Exception as exc:  # never a lost inspection: the cause goes into a failed row
        if recovery.is_database_error(exc):
            draft.fail(f"database_unavailable: during {draft.stage or 'the start'}: "
                       f"{type(exc).__name__}: {str(exc)[:300]}")  # fmt: skip
        else:
            log.exception("inspection failed unexpectedly")
            draft.fail(f"internal_error: {type(exc).__name__}: {str(exc)[:300]}")
    out = await record.store(ctx, opts, draft, started, marker=marker, t_start=found.t_start)
    if tracker is not None and out["decision"] != "failed":
        tracker.inspected(found.u_m, found.mask)
    return out
