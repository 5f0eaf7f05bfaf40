"""The PLC links against REST, in one run: a simulated PLC drives the cell over OPC UA and
Modbus TCP with the real clients (asyncua's and pymodbus's), REST is the baseline.

One process serves the cell as ``visioncell serve`` does (uvicorn, the app, its runtime and
the PLC links, in a thread; the OPC UA server in its child process); the main thread runs
the clients:

* **REST** (baseline): ``POST /api/inspections``, then ``GET /api/jobs/{id}`` every 2 ms
  until done (the result's row is then readable);
* **Modbus TCP**: :class:`backend.plc.simplc.ModbusPlc`: Trigger Ready, Trigger, Trigger Ack,
  Results Valid polled every 2 ms (a fast PLC scan), Results Ack;
* **OPC UA**: :class:`backend.plc.simplc.OpcUaPlc`: ``Trigger()``, Results Valid through a
  subscription (10 ms publishing interval), ``AcknowledgeResult(id)``.

Phases:

1. ``--count`` rounds of one trigger per protocol, interleaved (REST, OPC UA, Modbus), so the
   three see the same cell: trigger-to-result latency of each; every inspection id each PLC
   saw is checked to be seen once, and against the rows the cell stored (none lost, none
   duplicated).  Target: p95 overhead over REST's <= 20 ms for each protocol.
2. ``--estops`` E-STOPs pressed over REST while both PLCs watch: time until the Modbus ESTOP
   bit and the OPC UA ``EStop`` variable show it.  Target: <= 100 ms.
3. Recipe changeover (when the build has recipes): two recipes, selected in turn over OPC UA
   and Modbus between two triggers; time from the selection to the next result made with
   it.  Target: <= 1 s.

The cell is the ideal arm with a folder camera replaying a COIL-20 image (two models taught
from COIL-20 views), so the inspection itself is short and the protocols' overhead shows.

4. ``--sim-objects`` > 0: the simulated cell (MuJoCo arm, camera and belt, two demo parts
   taught at ``--teach-yaws`` yaws, 8 by default as a 3D part needs, the demo's belt
   indexing them to the station): the simulated PLC starts a continuous run of that many
   objects over Modbus (RUN bit) and then over OPC UA (``StartRun``), acknowledges each
   result, and checks it against the simulator's truth of the inspected object (the
   part's model, its x/y in the base frame).

Run::

    .venv/bin/python -m benchmarks.plc [--count 1000] [--estops 20] [--sim-objects 6] [--teach-yaws 8] [--json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

os.environ.setdefault("MUJOCO_GL", "egl")

__all__ = ["TARGETS", "main", "run"]

out = Console(width=150)
err = Console(stderr=True)

#: Targets: p95 trigger-to-result overhead over REST's (ms), E-STOP visibility (ms),
#: recipe changeover (s).
TARGETS = {"overhead_p95_ms": 20.0, "estop_ms": 100.0, "changeover_s": 1.0}
_SECRET = "plc-benchmark-secret-0123456789"
_HANG_S = 300.0
POLL_S = 0.002


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _settings(tmp: Path, data_dir: Path) -> Any:
    from backend.settings import Settings

    coil = data_dir / "recognition" / "coil20"
    cam = tmp / "camera"
    cam.mkdir()
    (cam / "0000_obj2__30.png").symlink_to(coil / "obj2__30.png")
    return Settings(
        database_url=f"sqlite+aiosqlite:///{tmp / 'bench.db'}",
        var_dir=tmp / "var",
        driver="ideal",
        camera="folder",
        camera_folder=cam,
        data_dir=data_dir,
        secret_key=_SECRET,
        view3d_enabled=False,
        bootstrap_operator=False,
        threshold_follow=False,
        http_port=_free_port(),
        viser_port=_free_port(),
        opcua_endpoint=f"opc.tcp://127.0.0.1:{_free_port()}/visioncell",
        modbus_port=_free_port(),
    )


async def _tokens(settings: Any) -> dict[str, str]:
    from backend.auth import create_user
    from backend.db.models import Role
    from backend.db.session import Database

    db = Database(settings.database_url)
    tokens = {}
    try:
        async with db.session() as s:
            for role in (Role.operator, Role.engineer):
                _, tokens[role.name] = await create_user(
                    s, f"plc-{role.name}", role, settings.secret_key.get_secret_value()
                )
    finally:
        await db.dispose()
    return tokens


def _teach(client: Any, headers: dict[str, str], coil: Path) -> None:
    for obj in (1, 2):
        r = client.post("/api/models", json={"name": f"obj{obj}", "kind": "2d", "threshold": 0.15},
                        headers=headers)  # fmt: skip
        r.raise_for_status()
        files = [coil / f"obj{obj}__{k}.png" for k in range(0, 72, 8)]
        parts = [("images", (f.name, f.read_bytes(), "image/png")) for f in files]
        r = client.post(f"/api/models/{r.json()['id']}/views", files=parts,
                        data={"viewpoints": "1"}, headers=headers)  # fmt: skip
        r.raise_for_status()


async def _rest_trigger(client: Any, headers: dict[str, str]) -> tuple[float, int]:
    t0 = time.perf_counter()
    r = await client.post("/api/inspections", json={}, headers=headers)
    r.raise_for_status()
    job_id = r.json()["job"]["id"]
    while True:
        job = (await client.get(f"/api/jobs/{job_id}", headers=headers)).json()["job"]
        if job["state"] != "running":
            break
        await asyncio.sleep(POLL_S)
    if job["state"] != "done":
        raise RuntimeError(f"REST inspection {job['state']}: {job.get('error')}")
    return time.perf_counter() - t0, int(job["result"]["inspection_id"])


async def _loop_gap_until(aw: Any, tick_s: float = 0.005) -> float:
    """Longest wait of a 5 ms tick on this (the cell's) loop while ``aw`` runs, ms: how long
    the OPC UA server's start held the cell's loop (it builds in its own process)."""
    gaps = [0.0]
    done = False

    async def ticker() -> None:
        t = time.perf_counter()
        while not done:
            await asyncio.sleep(tick_s)
            now = time.perf_counter()
            gaps.append(now - t - tick_s)
            t = now

    task = asyncio.get_running_loop().create_task(ticker())
    try:
        await aw
    finally:
        done = True
        await task
    return max(gaps) * 1e3


def _call(srv: Any, coro: Any, bound_s: float = 3600.0) -> Any:
    """Run ``coro`` on the server's loop; wait for it (teaching on a loaded machine takes
    minutes: ``bound_s`` only bounds a hang)."""
    return asyncio.run_coroutine_threadsafe(coro, srv.loop).result(bound_s)


def _q(xs: list[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, max(0, round(q * (len(s) - 1))))]


async def _phases(args: argparse.Namespace, srv: Any, tokens: dict[str, str],
                  progress: Callable[[str], None]) -> dict[str, Any]:  # fmt: skip
    import httpx

    from backend.plc.simplc import ModbusPlc, OpcUaPlc

    settings = srv.settings
    op = {"Authorization": f"Bearer {tokens['operator']}"}
    client = httpx.AsyncClient(base_url=srv.base, timeout=_HANG_S)
    modbus = ModbusPlc("127.0.0.1", settings.modbus_port, poll_s=POLL_S, bound_s=_HANG_S)
    await modbus.connect()
    opc = OpcUaPlc(settings.opcua_endpoint, user="plc-engineer", password=tokens["engineer"],
                   bound_s=_HANG_S)  # fmt: skip
    await opc.connect()
    lat: dict[str, list[float]] = {"rest": [], "opcua": [], "modbus": []}
    ids: dict[str, list[int]] = {"rest": [], "opcua": [], "modbus": []}
    try:
        await _rest_trigger(client, op)  # warm-up (the first inspection builds caches)
        first_id = None
        for i in range(args.count):
            dt, iid = await _rest_trigger(client, op)
            lat["rest"].append(dt)
            ids["rest"].append(iid)
            first_id = iid if first_id is None else first_id
            t = await opc.trigger()
            lat["opcua"].append(t.latency_s)
            ids["opcua"].append(int(t.result["inspection_id"]))
            t = await modbus.trigger()
            lat["modbus"].append(t.latency_s)
            ids["modbus"].append(int(t.result["inspection_id"]))
            if (i + 1) % max(1, args.count // 10) == 0:
                progress(f"{i + 1}/{args.count} rounds")
        # every id the PLCs saw, against the rows stored since the first round
        r = await client.get("/api/inspections", params={"limit": 1}, headers=op)
        last_id = int(r.json()["data"][0]["id"])
        stored = set(range(first_id, last_id + 1))
        seen = ids["rest"] + ids["opcua"] + ids["modbus"]
        integrity = {
            p: {"triggers": args.count, "results": len(v), "unique": len(set(v)),
                "duplicates": len(v) - len(set(v))}
            for p, v in ids.items()
        }  # fmt: skip
        integrity["all"] = {"stored": len(stored), "seen": len(seen), "lost": len(stored - set(seen)),
                            "duplicated": len(seen) - len(set(seen))}  # fmt: skip

        # E-STOP visibility
        estop: dict[str, list[float]] = {"modbus": [], "opcua": []}
        await modbus.set_bits(TRIGGER_ENABLE=True)
        for _ in range(args.estops):
            opc_seen = asyncio.Event()
            t0 = time.perf_counter()
            press = asyncio.create_task(client.post("/api/robot/estop", headers=op))
            mb_task = asyncio.create_task(modbus.wait(lambda w: "ESTOP" in w["flags"], "estop"))
            await opc.wait(lambda v: v.get("EStop") is True, "estop")
            estop["opcua"].append(opc.seen_at["EStop"] - t0)
            opc_seen.set()
            await mb_task
            estop["modbus"].append(time.perf_counter() - t0)
            (await press).raise_for_status()
            r = await client.post("/api/robot/reset", headers=op)
            r.raise_for_status()
            await opc.wait(lambda v: v.get("EStop") is False, "reset")
            await modbus.wait(lambda w: "ESTOP" not in w["flags"], "reset")
            await asyncio.sleep(0.05)
        progress("E-STOPs measured")
        changeover = await _changeover(client, tokens, opc, modbus)
    finally:
        modbus.close()
        await opc.close()
        await client.aclose()
    return {"latency_s": lat, "integrity": integrity, "estop_s": estop,
            "changeover": changeover, "ids": ids}  # fmt: skip


async def _changeover(client: Any, tokens: dict[str, str], opc: Any, modbus: Any) -> dict[str, Any]:
    """Two recipes selected in turn between triggers, over each protocol."""
    from asyncua import ua

    from backend.plc.modbus import REGISTERS

    eng = {"Authorization": f"Bearer {tokens['engineer']}"}
    numbers = []
    for k, policy in enumerate(("top-only", "two-views")):
        body = {"name": f"bench-{k}", "number": 101 + k, "policy": policy}
        r = await client.post("/api/recipes", json=body, headers=eng)
        if r.status_code >= 400:
            why = f"creating a recipe: {r.status_code} {r.text[:200]}"
            return {"available": False, "reason": why}
        numbers.append(int(r.json()["number"]))
    select: dict[str, list[float]] = {"opcua": [], "modbus": []}
    to_result: dict[str, list[float]] = {"opcua": [], "modbus": []}
    for i in range(6):
        n = numbers[i % 2]
        t0 = time.perf_counter()
        node = opc.nodes["SelectRecipe"]
        await opc.nodes["cell"].call_method(node, ua.Variant(n, ua.VariantType.UInt16))
        select["opcua"].append(time.perf_counter() - t0)
        await opc.trigger()
        to_result["opcua"].append(time.perf_counter() - t0)
        n = numbers[(i + 1) % 2]
        t0 = time.perf_counter()
        await modbus.write(REGISTERS["RECIPE_REQUEST"], n)
        await modbus.set_bits(RECIPE_SELECT=True)
        w = await modbus.read()
        select["modbus"].append(time.perf_counter() - t0)
        await modbus.set_bits(RECIPE_SELECT=False)
        if w["recipe"] != n:
            return {"available": False, "reason": f"Modbus selection refused: error {w['error']}"}
        await modbus.trigger()
        to_result["modbus"].append(time.perf_counter() - t0)
    return {"available": True, "recipes": numbers, "select_s": select,
            "select_to_result_s": to_result}  # fmt: skip


def run(args: argparse.Namespace, progress: Callable[[str], None]) -> dict[str, Any]:
    """All phases; the result as a JSON-able dict."""
    import httpx

    from backend.db.migrate import upgrade
    from backend.settings import Settings
    from benchmarks.estop import _Server

    data_dir = Path(args.data_dir or Settings().data_dir).resolve()
    coil = data_dir / "recognition" / "coil20"
    if not (coil / "obj2__30.png").is_file():
        raise SystemExit(f"COIL-20 is absent from {coil} (see the data README)")
    with tempfile.TemporaryDirectory(prefix="plc-bench-") as tmp:
        settings = _settings(Path(tmp), data_dir)
        upgrade(settings.database_url)
        tokens = asyncio.run(_tokens(settings))
        srv = _Server(settings)
        srv.settings = settings
        progress("starting the cell with its OPC UA and Modbus servers")
        t0 = time.perf_counter()
        srv.start()
        start_s = time.perf_counter() - t0
        links = srv.runtime.plc_links
        gap_ms = _call(srv, _loop_gap_until(links.opcua.wait_ready()))
        opcua_ready_s = time.perf_counter() - t0
        # the baseline: the same loop as long again with the OPC UA server up and idle
        idle_gap_ms = _call(srv, _loop_gap_until(asyncio.sleep(opcua_ready_s - start_s)))
        try:
            with httpx.Client(base_url=srv.base, timeout=_HANG_S) as c:
                _teach(c, {"Authorization": f"Bearer {tokens['engineer']}"}, coil)
            progress("taught obj1 and obj2 from COIL-20")
            res = asyncio.run(_phases(args, srv, tokens, progress))
        finally:
            srv.stop()
    lat = res["latency_s"]
    rows = []
    for p in ("rest", "opcua", "modbus"):
        ms = [v * 1e3 for v in lat[p]]
        rows.append({"protocol": p, "n": len(ms), "p50_ms": _q(ms, 0.5), "p95_ms": _q(ms, 0.95),
                     "mean_ms": statistics.fmean(ms)})  # fmt: skip
    base = rows[0]
    for r in rows:
        r["overhead_p50_ms"] = r["p50_ms"] - base["p50_ms"]
        r["overhead_p95_ms"] = r["p95_ms"] - base["p95_ms"]
    estop = {p: {"n": len(v), "p50_ms": _q([x * 1e3 for x in v], 0.5),
                 "max_ms": max(v) * 1e3 if v else None} for p, v in res["estop_s"].items()}  # fmt: skip
    return {
        "benchmark": "plc",
        "count": args.count,
        "latency": rows,
        "integrity": res["integrity"],
        "estop": estop,
        "changeover": res["changeover"],
        "startup_s": start_s,
        "opcua_ready_s": opcua_ready_s,
        "loop_gap_during_opcua_start_ms": gap_ms,
        "loop_gap_after_opcua_start_ms": idle_gap_ms,
        "nodesets_load_s": getattr(links.opcua, "load_s", None) if links else None,
        "targets": TARGETS,
    }


#: The demo parts the simulated cell's phase teaches and feeds.
SIM_PARTS = ("wheel-5spoke", "gear-housing")


def _sim_settings(tmp: Path) -> Any:
    from backend.settings import Settings

    return Settings(
        database_url=f"sqlite+aiosqlite:///{tmp / 'sim.db'}",
        var_dir=tmp / "var",
        driver="sim",
        camera="sim",
        sim_demo=False,
        time_scale=2.0,
        secret_key=_SECRET,
        view3d_enabled=False,
        bootstrap_operator=False,
        threshold_follow=False,
        http_port=_free_port(),
        viser_port=_free_port(),
        opcua_endpoint=f"opc.tcp://127.0.0.1:{_free_port()}/visioncell",
        modbus_port=_free_port(),
    )


async def _sim_runs(srv: Any, tokens: dict[str, str], n: int, ids: dict[int, str],
                    progress: Callable[[str], None]) -> list[dict[str, Any]]:  # fmt: skip
    """A run of ``n`` objects over each protocol; each result against the truth."""
    import math

    import httpx

    from backend.plc.modbus import REGISTERS
    from backend.plc.simplc import ModbusPlc, OpcUaPlc

    s = srv.settings
    op = {"Authorization": f"Bearer {tokens['operator']}"}
    checked: list[dict[str, Any]] = []
    async with httpx.AsyncClient(base_url=srv.base, timeout=_HANG_S) as client:

        async def check(proto: str, res: dict[str, Any]) -> None:
            iid = int(res["inspection_id"])
            row = (await client.get(f"/api/inspections/{iid}", headers=op)).json()
            truth = row.get("truth") or {}
            name = ids.get(int(res["model_id"]))
            err_mm = None
            if truth.get("T_base_obj") and res.get("x_m") is not None:
                T = truth["T_base_obj"]
                err_mm = math.hypot(res["x_m"] - T[0][3], res["y_m"] - T[1][3]) * 1e3
            checked.append({"protocol": proto, "inspection_id": iid, "plc_model": name,
                            "truth": truth.get("name"), "correct": name == truth.get("name"),
                            "xy_error_mm": err_mm})  # fmt: skip
            progress(f"{proto}: inspection {iid}: {name} (truth {truth.get('name')}), "
                     f"xy error {'-' if err_mm is None else f'{err_mm:.1f} mm'}")  # fmt: skip

        plc = ModbusPlc("127.0.0.1", s.modbus_port, poll_s=0.01, bound_s=_HANG_S)
        await plc.connect()
        try:
            await plc.write(REGISTERS["RUN_COUNT"], n)
            await plc.set_bits(RUN=True)
            for _ in range(n):
                w = await plc.wait(lambda w: "RESULTS_VALID" in w["flags"], "a run's result")
                await check("modbus", w)
                await plc.acknowledge()
            await plc.wait(lambda w: "RUNNING" not in w["flags"], "the run's end")
            await plc.set_bits(RUN=False)
        finally:
            plc.close()
        opc = OpcUaPlc(s.opcua_endpoint, user="plc-operator", password=tokens["operator"],
                       bound_s=_HANG_S)  # fmt: skip
        await opc.connect()
        try:
            from asyncua import ua

            await opc.call("StartRun", ua.Variant(n, ua.VariantType.UInt32))
            seen: list[int] = []
            for _ in range(n):
                await opc.wait(lambda v: v.get("ResultsValid") is True
                               and v.get("InspectionId") not in seen, "a run's result")  # fmt: skip
                res = await opc.read_result()
                seen.append(res["inspection_id"])
                await check("opcua", res)
                await opc.acknowledge(res["inspection_id"])
        finally:
            await opc.close()
    return checked


def run_sim(args: argparse.Namespace, progress: Callable[[str], None]) -> dict[str, Any]:
    """Phase 4 (see the module doc)."""
    from backend.db.migrate import upgrade
    from benchmarks.estop import _Server
    from benchmarks.inspection import _teach_all
    from robot.sim.demo import populate_demo

    with tempfile.TemporaryDirectory(prefix="plc-sim-") as tmp:
        settings = _sim_settings(Path(tmp))
        upgrade(settings.database_url)
        tokens = asyncio.run(_tokens(settings))
        srv = _Server(settings)
        srv.settings = settings
        progress("starting the simulated cell with its PLC links")
        srv.start()
        _call(srv, srv.runtime.plc_links.opcua.wait_ready())
        try:
            rt = srv.runtime
            progress(f"teaching {', '.join(SIM_PARTS)} in the simulated cell")
            from backend.recognition.teach import teach_yaws_rad

            # Each part at the yaws a 3D part needs to be recognised at any yaw on the belt.
            yaws = tuple(math.degrees(y) for y in teach_yaws_rad(args.teach_yaws))
            teach_s, _ = _call(srv, _teach_all(rt, list(SIM_PARTS), yaws))
            ids = _call(srv, _model_ids(rt))
            populate_demo(rt.sim, names=SIM_PARTS * 2)
            checked = asyncio.run(_sim_runs(srv, tokens, args.sim_objects, ids, progress))
        finally:
            srv.stop()
    errs = [c["xy_error_mm"] for c in checked if c["xy_error_mm"] is not None]
    return {
        "teach_s": teach_s,
        "results": checked,
        "correct": sum(c["correct"] for c in checked),
        "n": len(checked),
        "unique": len({c["inspection_id"] for c in checked}),
        "xy_error_mm_p50": _q(errs, 0.5) if errs else None,
        "xy_error_mm_max": max(errs) if errs else None,
    }


async def _model_ids(rt: Any) -> dict[int, str]:
    from sqlalchemy import select

    from backend.db.models import ObjectModel

    async with rt.database.session() as session:
        rows = (await session.execute(select(ObjectModel.id, ObjectModel.name))).all()
    return {int(i): str(n) for i, n in rows}


def _print(result: dict[str, Any]) -> None:
    if "latency" in result:
        _print_links(result)
    sim = result.get("sim")
    if sim:
        out.print(f"simulated cell, continuous runs over Modbus and OPC UA: {sim['correct']}/{sim['n']} "
                  f"results name the simulator's part ({sim['unique']} distinct inspections); "
                  f"x/y error to the truth p50 {sim['xy_error_mm_p50'] or float('nan'):.1f} mm, "
                  f"max {sim['xy_error_mm_max'] or float('nan'):.1f} mm")  # fmt: skip


def _print_links(result: dict[str, Any]) -> None:
    t = Table(title=f"Trigger to result, {result['count']} rounds (REST is the baseline)")
    for c in ("protocol", "n", "p50 ms", "p95 ms", "p95 overhead ms", "target"):
        t.add_column(c, justify="right")
    for r in result["latency"]:
        target = "" if r["protocol"] == "rest" else f"<= {TARGETS['overhead_p95_ms']:g}"
        t.add_row(r["protocol"], str(r["n"]), f"{r['p50_ms']:.1f}", f"{r['p95_ms']:.1f}",
                  f"{r['overhead_p95_ms']:+.1f}", target)  # fmt: skip
    out.print(t)
    t = Table(title="Results each PLC saw")
    for c in ("protocol", "triggers", "results", "unique", "duplicates"):
        t.add_column(c, justify="right")
    for p, v in result["integrity"].items():
        if p != "all":
            t.add_row(
                p, str(v["triggers"]), str(v["results"]), str(v["unique"]), str(v["duplicates"])
            )
    out.print(t)
    a = result["integrity"]["all"]
    out.print(
        f"rows stored {a['stored']}, seen {a['seen']}, lost {a['lost']}, duplicated {a['duplicated']}"
    )
    t = Table(title="E-STOP pressed over REST until the PLC sees it")
    for c in ("protocol", "n", "p50 ms", "max ms", "target"):
        t.add_column(c, justify="right")
    for p, v in result["estop"].items():
        t.add_row(
            p,
            str(v["n"]),
            f"{v['p50_ms']:.1f}",
            f"{v['max_ms']:.1f}",
            f"<= {TARGETS['estop_ms']:g}",
        )
    out.print(t)
    ch = result["changeover"]
    if ch.get("available"):
        for p, v in ch["select_to_result_s"].items():
            out.print(f"recipe changeover over {p}: selected in max {max(ch['select_s'][p]):.3f} s, "
                      f"select to the next object's result max {max(v):.2f} s "
                      f"(target <= {TARGETS['changeover_s']:g} s)")  # fmt: skip
    else:
        out.print(f"recipe changeover: not measured ({ch['reason']})")
    out.print(f"cell serving REST and Modbus {result['startup_s']:.1f} s after start, OPC UA "
              f"{result['opcua_ready_s']:.1f} s (OPC 40100 + DI nodesets loaded in "
              f"{result['nodesets_load_s'] or 0:.2f} s in the OPC UA process; the cell's loop "
              f"waited at most {result['loop_gap_during_opcua_start_ms']:.0f} ms meanwhile, "
              f"{result['loop_gap_after_opcua_start_ms']:.0f} ms as long again after it)")  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--count", type=int, default=1000, help="rounds (one trigger per protocol each)")
    p.add_argument("--estops", type=int, default=20)
    p.add_argument(
        "--sim-objects",
        type=int,
        default=6,
        help="objects of each protocol's run in the simulated cell (0: skip)",
    )
    p.add_argument(
        "--teach-yaws",
        type=int,
        default=8,
        help="teach rounds (object yaws) of each part of the simulated cell",
    )
    p.add_argument("--data-dir", type=Path, default=None)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if (
        not 0 <= args.count <= 100_000
        or not 1 <= args.estops <= 1000
        or not 0 <= args.sim_objects <= 1000
        or not 1 <= args.teach_yaws <= 16
    ):
        p.error(
            "--count must be in 0..100000, --estops in 1..1000, --sim-objects in 0..1000, "
            "--teach-yaws in 1..16"
        )
    import logging

    logging.basicConfig(level=logging.WARNING)
    progress = lambda m: err.print(f"[plc] {m}")  # noqa: E731
    result = run(args, progress) if args.count else {}
    if args.sim_objects:
        result["sim"] = run_sim(args, progress)
    _print(result)
    if args.json:
        print(json.dumps(result, default=str))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
