"""The record stage: one place that makes the stored record and the live event from an
inspection's draft (:func:`record_of`, :func:`event_of`), stores the one and publishes the
other (:func:`store`), and answers with the stored form without reading it back."""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any

from backend.cell.events import InspectionDone
from backend.db.types import utcnow
from backend.inspection import recovery, results
from backend.inspection.draft import InspectionDraft
from backend.inspection.options import InspectOptions

__all__ = ["event_of", "record_of", "store"]


def record_of(opts: InspectOptions, draft: InspectionDraft, started: datetime,
              duration: float | None) -> results.InspectionRecord:  # fmt: skip
    """The stored record of ``draft``: started at ``started``, ``duration`` seconds long
    (None: the sum of its stages; it ends now)."""
    # One clock read for the end: the stored end is the start plus the duration, so the two
    # agree even when the thread is preempted between reading two clocks.
    finished = utcnow() if duration is None else started + timedelta(seconds=duration)
    return results.InspectionRecord(
        started_at=started, finished_at=finished, decision=draft.decision, reason=draft.reason,
        policy=opts.policy, model_id=draft.model_id, model_name=draft.model, score=draft.score,
        viewpoints=tuple(draft.viewpoints), scores=draft.scores, pose=draft.pose,
        durations=draft.watch.durations, pick=draft.pick, truth=draft.truth,
        views=tuple(draft.views), duration_s=duration, recipe_id=opts.recipe_id,
        recipe_name=opts.recipe_name,
    )  # fmt: skip


def event_of(iid: int, rec: results.InspectionRecord, draft: InspectionDraft) -> InspectionDone:
    """The live event of the record ``rec`` stored as ``iid`` (with the draft's camera poses)."""
    pose = rec.pose
    return InspectionDone(
        iid, rec.decision, rec.model_name, rec.reason, rec.score, rec.viewpoints,
        None if pose is None else tuple(tuple(r) for r in pose["T_base_obj"]),
        tuple(tuple(tuple(float(v) for v in r) for r in T) for T in draft.cams), rec.pick,
        rec.recipe_id, rec.recipe_name,
    )  # fmt: skip


async def store(ctx: Any, opts: InspectOptions, draft: InspectionDraft, started: datetime, *,
                marker: int | None = None, t_start: float | None = None) -> dict[str, Any]:  # fmt: skip
    """Store the draft (retrying until the database takes it, in the transaction that
    removes the in-progress ``marker``), publish its :class:`InspectionDone` and return the
    stored inspection's public form.  ``t_start`` (on the draft's stopwatch clock): when the
    inspection began, for its duration (None: the sum of its stages)."""
    rt = ctx.rt
    duration = None if t_start is None else max(0.0, draft.watch.clock() - t_start)
    rec = record_of(opts, draft, started, duration)
    scene = await draft.scene.finish() if draft.scene is not None else None
    retention = rt.settings.image_retention
    iid = await recovery.retry_database(
        "storing an inspection",
        lambda: results.store(
            rt.database, rt.cell_id, rec, retention=retention, scene=scene, marker_id=marker
        ),
    )
    rt.bus.publish(event_of(iid, rec, draft))
    return results.stored_public(iid, rt.cell_id, rec, retention=retention)
