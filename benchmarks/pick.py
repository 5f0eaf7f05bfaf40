"""Pick and sort in the simulator, and the viewpoint planner across the belt.

Picks: every catalogue entry (the twelve trainable ones into their part's bin, the two
untrained ones into the reject bin) is spawned at the station at a random yaw (index mode,
belt stopped), planned with :func:`robot.pick.plan_pick_place` (the flange's roll chosen to
turn the camera away from the part over an off-centre grasp point) and executed with
:class:`robot.sim.SimDriver`; the simulator's truth says which bin it landed in.  The height
and grasp point given to the planner are what a model stores (``height_m``, ``grasp_obj``:
the part's drawing, as an engineer enters it); for the untrained parts the planner gets
only the footprint (centre and half-width, what the top view gives) and finds the height
with a guarded descent (:func:`robot.pick.execute_search_pick_place`), as the cell does.  Also
measured, from the simulator's truth (evaluation only): the smallest distance between the
tool's collision capsules (camera, cup tube) and the part's own surface during the approach
and the descent (negative would be a collision the planner did not see).  Two conditions in the same run: the planner given the true pose (the baseline)
and the true pose perturbed by up to ``--error-mm`` in position and ``--error-deg`` in yaw
(what pose estimation leaves).  Figures: picks landing in their part's bin, planning time
(wall, median), cycle time (simulated seconds of motion, median), largest joint tracking
error while a part was on the cup.

Viewpoints: :func:`robot.viewpoints.plan_viewpoints` over a grid of object
positions across the belt (the true camera mounting), the share of views reached nominally,
replaced, or unreachable, the median planning time and the largest deviation.

Run ``python -m benchmarks.pick [--json] [--repeats N] [--error-mm MM] [--error-deg DEG]``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import statistics
import sys
import time

import numpy as np
from rich.console import Console
from rich.table import Table

from robot.errors import Unreachable
from robot.pick import execute_pick_place, execute_search_pick_place, plan_pick_place
from robot.sim import CATALOGUE, SimDriver, SimEngine, suction_point
from robot.sim.camera import DEFAULT_T_EE_CAM
from robot.sim.obstacles import collision_world
from robot.viewpoints import plan_viewpoints

out = Console()
err = Console(stderr=True)


#: What the cell assumes of an object it cannot name: the tallest the station admits (m);
#: its half-width is the top view's footprint (here the drawing's, plus 1 cm).
UNKNOWN_MAX_HEIGHT_M = 0.25


async def _recover(driver: SimDriver, engine: SimEngine, ok: bool) -> None:
    """After a miss: suction off and the arm back to ``q_ready`` for the next pick."""
    if ok:
        return
    from robot.trajectory import plan_joint_move

    await driver.grip(False)
    q = np.asarray(driver.state.q, dtype=np.float64)
    await driver.move(plan_joint_move(q, engine.arm_model.q_ready, speed=0.3))


def _tool_clearance(engine: SimEngine, name: str, T_obj: np.ndarray, trajs: list) -> float:
    """Smallest distance (m) from the tool capsules to the part's mesh vertices (truth)
    along ``trajs`` (approach and descent), every few samples."""
    from robot.collision import DEFAULT_TOOL_CAPSULES
    from robot.kinematics import T_base_ee

    verts = np.concatenate(
        [np.asarray(p.mesh.vertices, float) for p in CATALOGUE[name].geometry().pieces]
    )
    v = verts @ T_obj[:3, :3].T + T_obj[:3, 3]
    best = math.inf
    for traj in trajs:
        for q in traj.q[:: max(1, len(traj.q) // 40)]:
            T = T_base_ee(q, engine.arm_model)
            for cap in DEFAULT_TOOL_CAPSULES:
                a = T[:3, :3] @ np.asarray(cap.a_ee) + T[:3, 3]
                b = T[:3, :3] @ np.asarray(cap.b_ee) + T[:3, 3]
                ab = b - a
                t = np.clip(((v - a) @ ab) / float(ab @ ab), 0.0, 1.0)
                d = np.linalg.norm(v - (a + t[:, None] * ab), axis=1) - cap.radius_m
                best = min(best, float(d.min()))
    return best


def _bin_for(engine: SimEngine, name: str) -> str:
    entry = CATALOGUE[name]
    for b in engine.config.layout.bins:
        if (b.reject and not entry.trainable) or entry.base_of in b.parts:
            return b.name
    raise KeyError(name)


async def _picks(repeats: int, error_mm: float, error_deg: float, seed: int) -> list[dict]:
    engine = SimEngine()
    engine.set_joints(engine.arm_model.q_ready)
    engine.configure_conveyor(mode="index", running=False)
    world = collision_world(engine.config.layout)
    driver = SimDriver(engine, time_scale=50.0)
    await driver.connect()
    rng = np.random.default_rng(seed)
    names = list(CATALOGUE)
    rows: list[dict] = []
    spec = engine.config.layout.conveyor
    try:
        total = 2 * repeats * len(names)
        for cond, emm, edeg in (("true pose", 0.0, 0.0), ("pose error", error_mm, error_deg)):
            for _ in range(repeats):
                for name in names:
                    truth = engine.spawn(
                        name, s_m=spec.station_s_m, yaw_rad=float(rng.uniform(-math.pi, math.pi))
                    )
                    T = truth.T_base_obj.copy()
                    d = rng.normal(size=2)
                    T[:2, 3] += emm * 1e-3 * rng.uniform() * d / np.linalg.norm(d)
                    a = math.radians(rng.uniform(-edeg, edeg))
                    c, s = math.cos(a), math.sin(a)
                    T[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ T[:3, :3]
                    b = CATALOGUE[name].geometry().bounds
                    bin_name = _bin_for(engine, name)
                    trained = CATALOGUE[name].trainable
                    # A model's stored grasp point (its drawing, entered); unknown: top centre.
                    grasp = suction_point(name) if trained else None
                    t0 = time.perf_counter()
                    if not trained:  # unknown: footprint centre only, a guarded descent
                        drop = engine.config.layout.bin(bin_name).drop_point
                        try:
                            outcome, found_h = await execute_search_pick_place(
                                driver, T, drop, max_height_m=UNKNOWN_MAX_HEIGHT_M,
                                object_radius_m=float(np.abs(b[:, :2]).max()) + 0.01,
                                world=world,
                                q_return=engine.arm_model.q_ready,
                            )  # fmt: skip
                            reason = outcome.reason
                        except Unreachable as exc:
                            outcome, found_h, reason = None, None, str(exc)
                        ok = outcome is not None and outcome.ok
                        rows.append({"condition": cond, "name": name,
                                     "ok": ok and truth.id in engine.bins()[bin_name],
                                     "plan_s": None, "cycle_s": None if outcome is None else
                                     sum(m.duration_s for m in outcome.moves),
                                     "held_err_rad": None, "tool_gap_m": None,
                                     "stage": "search" if outcome is None else outcome.stage,
                                     "reason": reason, "found_height_m": found_h})  # fmt: skip
                        await _recover(driver, engine, ok)
                        err.print(f"[{len(rows)}/{total}] {cond}: {name} ok={rows[-1]['ok']}")
                        continue
                    try:
                        plan = plan_pick_place(
                            driver.state.q,
                            T,
                            float(b[1, 2]),
                            engine.config.layout.bin(bin_name).drop_point,
                            object_radius_m=float(np.abs(b[:, :2]).max()),
                            grasp_obj=grasp,
                            world=world,
                        )
                    except Unreachable as exc:
                        rows.append({"condition": cond, "name": name, "ok": False,
                                     "plan_s": time.perf_counter() - t0, "cycle_s": None,
                                     "held_err_rad": None, "tool_gap_m": None,
                                     "stage": "planning", "reason": str(exc)})  # fmt: skip
                        engine.clear_objects()
                        await _recover(driver, engine, False)
                        err.print(f"[{len(rows)}/{total}] {cond}: {name} not planned: {exc}")
                        continue
                    t_plan = time.perf_counter() - t0
                    outcome = await execute_pick_place(driver, plan)
                    held = outcome.moves[2:5]  # lift, transfer, lower: a part on the cup
                    gap = _tool_clearance(
                        engine, name, truth.T_base_obj, [st.trajectory for st in plan.steps[:2]]
                    )
                    rows.append(
                        {
                            "condition": cond,
                            "name": name,
                            "ok": outcome.ok and truth.id in engine.bins()[bin_name],
                            "plan_s": t_plan,
                            "cycle_s": sum(m.duration_s for m in outcome.moves),
                            "held_err_rad": max(
                                (m.max_tracking_error_rad for m in held), default=0.0
                            ),
                            "tool_gap_m": gap,
                            "stage": outcome.stage,
                            "reason": outcome.reason,
                        }
                    )
                    await _recover(driver, engine, outcome.ok)
                    engine.clear_objects()
                    err.print(f"[{len(rows)}/{total}] {cond}: {name} ok={rows[-1]['ok']}")
    finally:
        await driver.close()
        engine.stop()
    return rows


def _viewpoints() -> dict:
    world = collision_world()
    counts = {"nominal": 0, "replaced": 0, "unreachable": 0}
    times, devs = [], []
    for lateral in np.linspace(-0.2, 0.2, 5):
        for y in np.linspace(-0.6, 0.6, 7):
            t0 = time.perf_counter()
            for view in ("top", "inner", "outer"):
                try:
                    plan = plan_viewpoints(
                        (0.8 + lateral, y, 0.45),
                        T_ee_cam=DEFAULT_T_EE_CAM,
                        object_height_m=0.1,
                        world=world,
                        views=(view,),
                    )
                except Unreachable:
                    counts["unreachable"] += 1
                    continue
                v = plan.views[0]
                counts["nominal" if v.reached_nominal else "replaced"] += 1
                devs.append(v.deviation_deg)
            times.append(time.perf_counter() - t0)
    return {
        "objects": len(times),
        **counts,
        "plan_ms_median": 1e3 * statistics.median(times),
        "max_deviation_deg": max(devs),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object last")
    ap.add_argument("--repeats", type=int, default=1, help="passes over the catalogue (1-20)")
    ap.add_argument("--error-mm", type=float, default=5.0, help="position error bound, mm")
    ap.add_argument("--error-deg", type=float, default=1.0, help="yaw error bound, degrees")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if not 1 <= args.repeats <= 20:
        ap.error(f"--repeats must be in [1, 20], got {args.repeats}")
    if not (0.0 <= args.error_mm <= 20.0 and 0.0 <= args.error_deg <= 10.0):
        ap.error(
            f"--error-mm in [0, 20] and --error-deg in [0, 10], got {args.error_mm}, {args.error_deg}"
        )
    rows = asyncio.run(_picks(args.repeats, args.error_mm, args.error_deg, args.seed))
    vp = _viewpoints()
    table = Table(title="Pick and sort (simulator, station, index mode)")
    for col in (
        "condition",
        "picks",
        "right bin",
        "plan s (median)",
        "cycle s (median)",
        "max err held, mrad",
        "min tool-part gap, mm",
    ):
        table.add_column(col, justify="right")
    summary = {}
    for cond in ("true pose", "pose error"):
        r = [x for x in rows if x["condition"] == cond]
        s = {
            "picks": len(r),
            "right_bin": sum(x["ok"] for x in r),
            "plan_s_median": statistics.median(
                [x["plan_s"] for x in r if x["plan_s"] is not None] or [math.nan]
            ),
            "cycle_s_median": statistics.median(
                [x["cycle_s"] for x in r if x["cycle_s"] is not None] or [math.nan]
            ),
            "max_held_tracking_error_mrad": 1e3
            * max((x["held_err_rad"] for x in r if x["held_err_rad"] is not None), default=0.0),
            "min_tool_gap_mm": 1e3
            * min((x["tool_gap_m"] for x in r if x["tool_gap_m"] is not None), default=math.nan),
            "misses": [f"{x['name']}: {x['stage']}: {x['reason']}" for x in r if not x["ok"]],
        }
        summary[cond] = s
        table.add_row(
            cond,
            str(s["picks"]),
            f"{s['right_bin']} ({100 * s['right_bin'] / s['picks']:.0f} %)",
            f"{s['plan_s_median']:.2f}",
            f"{s['cycle_s_median']:.1f}",
            f"{s['max_held_tracking_error_mrad']:.2f}",
            f"{s['min_tool_gap_mm']:.0f}",
        )
    out.print(table)
    for cond, s in summary.items():
        for m in s["misses"]:
            out.print(f"miss ({cond}): {m}")
    vt = Table(title="Viewpoints across the belt (true camera mounting)")
    for col in (
        "objects",
        "views nominal",
        "replaced",
        "unreachable",
        "plan ms / object",
        "max deviation deg",
    ):
        vt.add_column(col, justify="right")
    vt.add_row(
        str(vp["objects"]),
        str(vp["nominal"]),
        str(vp["replaced"]),
        str(vp["unreachable"]),
        f"{vp['plan_ms_median']:.0f}",
        f"{vp['max_deviation_deg']:.1f}",
    )
    out.print(vt)
    if args.json:
        print(json.dumps({"picks": summary, "viewpoints": vp}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
