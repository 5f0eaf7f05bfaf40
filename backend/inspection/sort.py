"""The sort stage: the pick (or only the approach) of the inspected part, into its bin or
the reject bin (:func:`sort_part`); a failed inspection's part into the reject bin
(:func:`reject_failed`)."""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from backend.inspection.context import Context, belt_state
from backend.inspection.draft import InspectionDraft
from backend.inspection.options import InspectOptions
from backend.inspection.pose import geometry_source
from backend.inspection.recognise import UNKNOWN_MAX_HEIGHT_M
from robot.errors import Unreachable
from vision.errors import VisionCellError
from vision.pose import ObjectPose

if TYPE_CHECKING:
    from backend.runtime import CellRuntime
    from robot.cellworld import Bin

__all__ = ["MEASURED_MARGIN_M", "NO_BINS", "reject_failed", "sort_part"]

#: How far above a measured height the pick's guarded descent starts, metres: more than the
#: teach's measurement falls short of the part's top on the catalogue's parts but one
#: (``python -m benchmarks.teach_height``: 26 mm at most; a thin upright plate with no
#: features on its edge is the exception, and its approach still starts above it).
MEASURED_MARGIN_M = 0.04


#: What a result says when it should sort in a cell that has no bins.
NO_BINS = "sorting is not available: this cell has no bins"


def _no_bin(rt: CellRuntime) -> str:
    """Why no bin takes a part: the layout has no bins, or no reject bin."""
    layout = rt.layout
    if not layout.bins:
        return (f"{NO_BINS} (layout: {layout.source}; a real cell lists its bins in the "
                "layout file VISIONCELL_CELL_LAYOUT)")  # fmt: skip
    return f"no bin takes this part and the cell's layout ({layout.source}) has no reject bin"


async def reject_failed(ctx: Context, opts: InspectOptions, draft: InspectionDraft) -> None:
    """A failed inspection whose object was found on the belt (after the top view): with
    ``sort``, into the reject bin (the guarded pick of an unknown object), once."""
    found = draft.found
    if not opts.sort or found is None or draft.pick is not None or ctx.rt.cell.estopped:
        return
    if belt_state(ctx.rt)[0] == "continuous":  # gone on with the belt: left to the belt's end
        draft.pick = {"sorted": True, "ok": False,
                      "reason": "not rejected: the belt carried it on (constant speed)"}  # fmt: skip
        return
    try:
        draft.pick = await _pick_unknown(ctx, opts, draft, None, found, draft.radius)
    except (VisionCellError, ValueError) as exc:
        draft.pick = {"sorted": True, "ok": False, "reason": f"cannot reject: {exc}"}
    _note_pick(draft)


async def sort_part(ctx: Context, opts: InspectOptions, draft: InspectionDraft, pose: ObjectPose | None,
                      stored_h: float | None, radius: float, grasp: NDArray[np.float64] | None,
                      found: NDArray[np.float64], mode: str, travel0: float) -> None:  # fmt: skip
    """The pick (or the approach) of the inspected object, by what the model stores.

    A recognised part goes to its own bin: straight to an engineer's entered height and
    grasp point; by a short guarded descent from just above a height the teach measured
    (the measurement's error is taken up by the vacuum switch); by the guarded descent from
    the tallest admitted height when no height is stored (slow: the reason says to teach
    or enter it).  An unknown or failed object goes to the reject bin.  A pick that cannot
    be planned or does not hold the part says so in the inspection's reason."""
    rt = ctx.rt
    recognised = draft.decision == "recognized"
    if pose is None and ctx.uncalibrated:
        why = f"not picked: a pick {ctx.uncalibrated}"
        pick: dict[str, Any] = {"sorted": opts.sort, "ok": False}
        if opts.sort:  # where it would go: the sorting itself is planned without the pose
            b = _bin_for(rt, _part_of(rt, draft) if recognised else None)
            if b is None:
                why += f"; {_no_bin(rt)}"
            else:
                pick.update(bin=b.name, reject=bool(b.reject))
                why += f"; it would go to bin {b.name!r}"
        draft.pick = {**pick, "reason": why}
        return
    source = geometry_source(rt.live_index, draft.model) if recognised else ""
    at = found.copy()
    if mode == "continuous":
        at[1] += belt_state(rt)[2] - travel0
    if not opts.sort:
        if pose is not None:
            # Sorting off: the approach pose (above the tallest admitted object without a height).
            h_pick = UNKNOWN_MAX_HEIGHT_M if stored_h is None else stored_h
            draft.pick = await _pick(ctx, opts, draft, pose, h_pick, radius, grasp)
        else:
            draft.pick = await _pick_unknown(ctx, opts, draft, pose, at, radius)
    elif recognised and stored_h is not None and source != "measured" and pose is not None:
        draft.pick = await _pick(ctx, opts, draft, pose, stored_h, radius, grasp)
    elif recognised:
        if stored_h is not None:
            top = min(0.5, stored_h + MEASURED_MARGIN_M)
            why = (f"height {stored_h * 1e3:.0f} mm {source or 'stored'}: guarded descent from "
                   f"{MEASURED_MARGIN_M * 1e3:.0f} mm above it")  # fmt: skip
            if pose is None:
                why += "; no pose: over the footprint's centre"
        else:
            top = UNKNOWN_MAX_HEIGHT_M
            why = (f"no height stored for {draft.model}: guarded descent from "
                   f"{UNKNOWN_MAX_HEIGHT_M * 1e3:.0f} mm (teach the model again or enter its "
                   "height on the Models page to pick it directly)")  # fmt: skip
        draft.pick = await _pick_unknown(ctx, opts, draft, pose, at, radius,
                                            max_height_m=top, why=why)  # fmt: skip
    else:
        draft.pick = await _pick_unknown(ctx, opts, draft, pose, at, radius)
    _note_pick(draft)


def _note_pick(draft: InspectionDraft) -> None:
    """Say in the inspection's reason when its pick did not place the part where it belongs."""
    pick = draft.pick
    if not isinstance(pick, dict) or not pick.get("sorted") or pick.get("ok"):
        return
    where = f" into {pick['bin']}" if pick.get("bin") else ""
    draft.note(f"not sorted{where}: {pick.get('reason', 'unknown')}")


def _bin_for(rt: CellRuntime, part: str | None, named: str | None = None) -> Bin | None:
    """The layout's bin for ``part`` (``named``: the options' bin for the model, when the
    layout has one of that name); the reject bin for None or a part no bin takes."""
    if named is not None:
        b = next((b for b in rt.layout.bins if b.name == named), None)
        if b is not None:
            return b
    return rt.layout.bin_for(part)


def _part_of(rt: CellRuntime, draft: InspectionDraft) -> str | None:
    """The part the recognised model is (its ``part``, else its name)."""
    m = rt.live_index.model_of_name(draft.model) if draft.model else None
    return None if m is None else m.part


async def _pick_unknown(ctx: Context, opts: InspectOptions, draft: InspectionDraft,
                        pose: ObjectPose | None, at: NDArray[np.float64], radius: float, *,
                        max_height_m: float = UNKNOWN_MAX_HEIGHT_M,
                        why: str | None = None) -> dict[str, Any]:  # fmt: skip
    """A pick by a guarded descent over the footprint centre from ``max_height_m``
    (:func:`robot.pick.execute_search_pick_place`: the height is found by the vacuum
    switch).  With ``why`` (a recognised part; ``why`` says which height it starts from)
    into the part's own bin; without it (unknown or failed) into the reject bin.  Without
    ``sort``, left on the belt."""
    from robot.pick import execute_search_pick_place

    rt, cell = ctx.rt, ctx.rt.cell
    if not opts.sort:
        return {"sorted": False, "ok": False,
                "reason": "not picked: no pose or no stored height for this object (sorting off)"}  # fmt: skip
    part = None
    if why is not None:
        m = rt.live_index.model_of_name(draft.model) if draft.model else None
        part = None if m is None else m.part
    b = _bin_for(rt, part, opts.bin_of(draft.model) if why is not None else None)
    if b is None:
        return {"sorted": True, "ok": False, "reason": _no_bin(rt)}
    if why is not None and b.reject:
        why += f"; no bin takes part {part!r}: rejected"
    T = np.eye(4)
    if pose is not None:
        T[:3, :3] = pose.T_base_obj[:3, :3]
        T[:2, 3] = pose.T_base_obj[:2, 3]
    else:
        T[:2, 3] = at[:2]
    T[2, 3] = ctx.surface_z
    q0 = np.asarray(cell.driver.state.q, dtype=np.float64)
    try:
        with cell._arm("a pick"):  # the job holds the arm; this is its motion
            out, h = await execute_search_pick_place(
                cell.driver, T, np.asarray(b.drop_point), max_height_m=max_height_m,
                object_radius_m=radius, world=cell.world, q_return=q0,
            )  # fmt: skip
    except Unreachable as exc:
        return {"sorted": True, "ok": False, "bin": b.name, "reject": bool(b.reject),
                "reason": f"cannot pick: {exc}", "search": True, "how": why}  # fmt: skip
    return {"sorted": True, "ok": out.ok, "bin": b.name, "reject": bool(b.reject),
            "stage": out.stage, "reason": out.reason, "search": True, "found_height_m": h,
            "how": why}  # fmt: skip


async def _pick(ctx: Context, opts: InspectOptions, draft: InspectionDraft, pose: ObjectPose,
                height: float, radius: float, grasp: NDArray[np.float64] | None) -> dict[str, Any]:  # fmt: skip
    from robot.pick import execute_pick_place, plan_pick_place

    rt, cell = ctx.rt, ctx.rt.cell
    part = None
    m = rt.live_index.model_of_name(draft.model) if draft.model else None
    if m is not None:
        part = m.part
    q0 = np.asarray(cell.driver.state.q, dtype=np.float64)
    ok = draft.decision == "recognized"
    b = _bin_for(rt, part if ok else None, opts.bin_of(draft.model) if ok else None)
    drop = ctx.station + np.array([0.0, 0.0, 0.3]) if b is None else np.asarray(b.drop_point)
    try:
        plan = await asyncio.to_thread(plan_pick_place, q0, pose.T_base_obj, height, drop,
                                       object_radius_m=radius, grasp_obj=grasp, world=cell.world)  # fmt: skip
    except Unreachable as exc:
        return {"sorted": opts.sort, "ok": False, "bin": None if b is None else b.name,
                "reject": bool(b is not None and b.reject), "reason": f"cannot pick: {exc}"}  # fmt: skip
    if not opts.sort:
        approach = plan.steps[0].trajectory
        assert approach is not None  # a planned pick's first step moves
        await cell.execute(approach)
        return {
            "sorted": False,
            "ok": True,
            "stage": "approach",
            "reason": "moved to the approach pose",
        }
    if b is None:
        return {"sorted": True, "ok": False, "reason": _no_bin(rt)}
    with cell._arm("a pick"):  # the job holds the arm; this is its motion
        out = await execute_pick_place(cell.driver, plan)
    return {"sorted": True, "ok": out.ok, "bin": b.name, "reject": bool(b.reject),
            "stage": out.stage, "reason": out.reason,
            "how": f"height {height * 1e3:.0f} mm stored: planned pick to the grasp point"}  # fmt: skip
