"""E-STOP latency under faults: the REST E-STOP beside the 3D view's, in each fault condition.

One process serves the cell as ``visioncell serve`` does (uvicorn, the FastAPI app and the
:class:`~backend.runtime.CellRuntime` on one event loop, in a thread); this process's main
thread is the client.  Each sample presses the E-STOP and times it until the answer, checks
that the arm and the conveyors are latched when it comes, then resets the cell:

* **REST**: ``POST /api/robot/estop`` with a viewer's token, on a keep-alive connection;
* **3D view** (the baseline, measured in the same conditions): the coroutine the 3D view's
  E-STOP button hands to the application's loop (``Cell.estop`` through
  ``asyncio.run_coroutine_threadsafe``, as the panel's ``submit`` does), timed until done.

Conditions, one after the other, in one run:

* ``normal``;
* ``database unavailable``: every new database session hangs until the phase ends
  (:class:`benchmarks.outage.DatabaseOutage`, ``block``: a locked SQLite file, a server
  that never answers);
* ``store-retry in progress``: every session fails at once and a motion job holds the arm;
  cancelled by the E-STOP, it stores its result through the outage, retrying as an
  inspection does (``retry_database``), until the database comes back after the sample;
* ``event loop busy with an upload``: another client uploads trained views (a
  ``--upload-mp`` megapixel PNG each, decoded and described by the handler) back to back;
* ``address throttled``: the client's address sent ``signin_max_failures`` bad tokens
  first, so every other sign-in from it gets 429.

Target: p99 <= 100 ms for the REST E-STOP in each condition.  Run::

    .venv/bin/python -m benchmarks.estop [--samples 40] [--driver sim|ideal] [--json]
    .venv/bin/python -m benchmarks.estop --short [--json]   # a few samples, the ideal arm
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import math
import os
import socket
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering, before MuJoCo loads

__all__ = ["CONDITIONS", "TARGET_P99_MS", "main", "run"]

out = Console(width=150)

#: The fault conditions, in the order they are measured.
CONDITIONS = (
    "normal",
    "database unavailable",
    "store-retry in progress",
    "event loop busy with an upload",
    "address throttled",
)
#: Target of the REST E-STOP's p99 in every condition, ms.
TARGET_P99_MS = 100.0
MAX_SAMPLES = 1000
_SECRET = "estop-benchmark-secret-0123456789"
#: Bounds a hang only (a sample waits for its answer at most this long), s.
_HANG_S = 120.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _quantile(xs: list[float], q: float) -> float | None:
    """Nearest-rank quantile ``q`` in (0, 1] of ``xs`` (None when empty)."""
    if not xs:
        return None
    s = sorted(xs)
    return s[min(len(s) - 1, max(0, math.ceil(q * len(s)) - 1))]


def _summary(ms: list[float], statuses: list[int], latched: list[bool]) -> dict[str, Any]:
    counts: dict[str, int] = {}
    for code in statuses:
        counts[str(code)] = counts.get(str(code), 0) + 1

    def r(v: float | None) -> float | None:
        return None if v is None else round(v, 2)

    return {
        "n": len(ms),
        "p50_ms": r(_quantile(ms, 0.5)),
        "p99_ms": r(_quantile(ms, 0.99)),
        "max_ms": r(max(ms)) if ms else None,
        "status": counts,
        "all_latched": bool(latched) and all(latched),
    }


def _settings(tmp: Path, driver: str) -> Any:
    import cv2
    import numpy as np

    from backend.settings import Settings

    values: dict[str, Any] = {
        "database_url": f"sqlite+aiosqlite:///{tmp / 'estop.db'}",
        "var_dir": tmp / "var",
        "secret_key": _SECRET,
        "driver": driver,
        "camera": "sim" if driver == "sim" else "folder",
        "view3d_enabled": False,
        "bootstrap_operator": False,
        "sim_demo": False,
        "camera_fps": 2.0,
        "camera_idle_fps": 0.5,
        "signin_block_s": 3600.0,  # the throttled address stays blocked for the phase
        "http_port": _free_port(),
        "viser_port": _free_port(),
    }
    if driver != "sim":
        folder = tmp / "images"
        folder.mkdir(parents=True, exist_ok=True)
        rng = np.random.default_rng(0)
        for i in range(3):
            img = rng.integers(0, 255, size=(120, 160, 3), dtype=np.uint8)
            cv2.imwrite(str(folder / f"img{i}.png"), img)
        values["camera_folder"] = folder
    return Settings(**values)


async def _tokens(settings: Any) -> dict[str, str]:
    from backend.auth import create_user
    from backend.db.models import Role
    from backend.db.session import Database

    db = Database(settings.database_url)
    tokens = {}
    try:
        async with db.session() as s:
            for role in (Role.viewer, Role.engineer):
                _, tokens[role.name] = await create_user(
                    s, f"bench-{role.name}", role, settings.secret_key.get_secret_value()
                )
    finally:
        await db.dispose()
    return tokens


class _Server:
    """uvicorn with the app and its runtime on a thread of their own (as ``serve`` runs)."""

    def __init__(self, settings: Any) -> None:
        import uvicorn

        from backend.api.deps import runtime_of
        from backend.api.limits import uvicorn_options
        from backend.app import create_app

        self.app = create_app(settings)
        self._runtime_of = runtime_of
        self._sock = socket.socket()
        self._sock.bind(("127.0.0.1", 0))
        self.base = f"http://127.0.0.1:{self._sock.getsockname()[1]}"
        config = uvicorn.Config(self.app, log_level="error", lifespan="on", **uvicorn_options())
        self.server = uvicorn.Server(config)
        self.loop: asyncio.AbstractEventLoop | None = None
        self._thread = threading.Thread(target=self._main, name="uvicorn", daemon=True)

    def _main(self) -> None:
        from backend.eventloop import run

        async def serve() -> None:
            self.loop = asyncio.get_running_loop()
            await self.server.serve(sockets=[self._sock])

        run(serve())

    def start(self) -> None:
        self._thread.start()
        t0 = time.monotonic()
        while not self.server.started:
            if not self._thread.is_alive() or time.monotonic() - t0 > _HANG_S:
                raise RuntimeError("the server did not start")
            time.sleep(0.05)

    @property
    def runtime(self) -> Any:
        return self._runtime_of(self.app)

    def call(self, coro: Any) -> Any:
        """Run ``coro`` on the server's loop and wait for its result."""
        assert self.loop is not None
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(_HANG_S)

    def stop(self) -> None:
        self.server.should_exit = True
        self._thread.join(timeout=60)
        self._sock.close()


class _Belt:
    """A conveyor of the ideal cell (the simulated cell brings its own belt)."""

    name = "bench-belt"

    def __init__(self) -> None:
        self.halted = False

    async def halt(self) -> None:
        self.halted = True

    async def resume(self) -> None:
        self.halted = False


def _upload_png(megapixels: float) -> bytes:
    """A PNG of ``megapixels`` with shapes to describe (small on disk, large decoded)."""
    import cv2
    import numpy as np

    h = round(math.sqrt(megapixels * 1e6 * 3 / 4))
    w = round(h * 4 / 3)
    img = np.full((h, w, 3), 90, np.uint8)
    rng = np.random.default_rng(3)
    for _ in range(60):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        r = int(rng.integers(h // 60 + 2, h // 12 + 3))
        colour = tuple(int(c) for c in rng.integers(0, 255, 3))
        if rng.random() < 0.5:
            cv2.circle(img, (x, y), r, colour, -1)
        else:
            cv2.rectangle(img, (x - r, y - r), (x + r, y + r // 2), colour, -1)
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return buf.tobytes()


class _Uploader:
    """Uploads trained views back to back from a thread until stopped."""

    def __init__(self, base: str, token: str, png: bytes) -> None:
        import httpx

        self._client = httpx.Client(
            base_url=base, headers={"Authorization": f"Bearer {token}"}, timeout=600
        )
        r = self._client.post("/api/models", json={"name": "estop-bench-upload", "kind": "2d"})
        if r.status_code != 201:
            raise RuntimeError(f"cannot create the upload model: {r.status_code} {r.text[:200]}")
        self._path = f"/api/models/{r.json()['id']}/views"
        self._png = png
        self._stop = threading.Event()
        self.started = threading.Event()
        self.statuses: list[int] = []
        self._thread = threading.Thread(target=self._loop, name="uploader", daemon=True)

    def _loop(self) -> None:
        while not self._stop.is_set():
            self.started.set()
            try:
                r = self._client.post(
                    self._path, files=[("images", ("big.png", self._png, "image/png"))],
                    data={"viewpoints": "1"},
                )  # fmt: skip
                self.statuses.append(r.status_code)
            except Exception:  # a refused upload is a status of its own
                self.statuses.append(0)

    def start(self) -> None:
        self._thread.start()
        self.started.wait(_HANG_S)
        time.sleep(0.2)  # the first upload is in the server's hands

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=_HANG_S)
        self._client.close()


async def _holding_job(rt: Any) -> Any:
    """A motion job that holds the arm and, cancelled, stores its result through the
    database as an inspection does: retried with backoff until the database answers."""
    from sqlalchemy import text

    from backend.inspection.recovery import retry_database

    async def store() -> None:
        async with rt.database.session() as session:
            await session.execute(text("SELECT 1"))

    async def body(job: Any) -> dict[str, Any]:
        try:
            await asyncio.Event().wait()
        except asyncio.CancelledError:
            await asyncio.shield(retry_database("storing a benchmark result", store))
            raise
        return {}

    return rt.cell.jobs.start("estop-bench-store", body, motion=True)


def run(args: argparse.Namespace, progress: Callable[[str], None]) -> dict[str, Any]:
    """Measure every condition (see the module doc); the result as a JSON-able dict."""
    import httpx

    from backend.db.migrate import upgrade
    from benchmarks.outage import DatabaseOutage

    with tempfile.TemporaryDirectory(prefix="estop-bench-") as tmp:
        settings = _settings(Path(tmp), args.driver)
        upgrade(settings.database_url)
        tokens = asyncio.run(_tokens(settings))
        srv = _Server(settings)
        progress(f"starting the cell ({args.driver} arm)")
        srv.start()
        rt = srv.runtime
        if not rt.cell.conveyors:
            rt.cell.conveyors.append(_Belt())
        viewer = {"Authorization": f"Bearer {tokens['viewer']}"}
        client = httpx.Client(base_url=srv.base, timeout=_HANG_S)
        png = _upload_png(args.upload_mp)
        results: dict[str, Any] = {}
        job_box: dict[str, Any] = {}

        def latched() -> bool:
            return bool(rt.cell.driver.state.estopped) and all(c.halted for c in rt.cell.conveyors)

        def rest() -> tuple[float, int]:
            t0 = time.perf_counter()
            r = client.post("/api/robot/estop", headers=viewer)
            return (time.perf_counter() - t0) * 1e3, r.status_code

        def view3d() -> tuple[float, int]:
            t0 = time.perf_counter()
            srv.call(rt.cell.estop(by="bench-viewer", role="viewer", source="view3d"))
            return (time.perf_counter() - t0) * 1e3, 200

        def nothing() -> None:
            return None

        @contextlib.contextmanager
        def condition(name: str) -> Iterator[tuple[Callable[[], None], Callable[[], None]]]:
            """The fault of ``name`` in force; yields what to do before and after each
            sample (before the reset)."""
            if name == "normal":
                yield nothing, nothing
            elif name == "database unavailable":
                with DatabaseOutage(rt.database, mode="block"):
                    yield nothing, nothing
            elif name == "store-retry in progress":
                outage = DatabaseOutage(rt.database, mode="fail")

                def before() -> None:
                    job_box["job"] = srv.call(_holding_job(rt))

                def after() -> None:  # the cancelled job stores once the database is back
                    job = job_box.pop("job", None)
                    if job is not None:
                        with outage.paused():
                            srv.call(rt.cell.jobs.wait(job))

                with outage:
                    yield before, after
            elif name == "event loop busy with an upload":
                up = _Uploader(srv.base, tokens["engineer"], png)
                up.start()
                try:
                    yield nothing, nothing
                finally:
                    up.stop()
                    results["uploads"] = {"statuses": up.statuses}
            elif name == "address throttled":
                bad = {"Authorization": "Bearer vc_not-a-token-anyone-has"}
                for _ in range(settings.signin_max_failures):
                    client.get("/api/robot/state", headers=bad)
                blocked = client.get("/api/robot/state", headers=viewer).status_code
                if blocked != 429:
                    raise RuntimeError(f"the address is not blocked: {blocked}")
                yield nothing, nothing
            else:
                raise ValueError(f"unknown condition {name!r}")

        try:
            for name in args.conditions:
                ms: dict[str, list[float]] = {"rest": [], "view3d": []}
                st: dict[str, list[int]] = {"rest": [], "view3d": []}
                ok: dict[str, list[bool]] = {"rest": [], "view3d": []}
                with condition(name) as (before, after):
                    for i in range(args.samples):
                        for path, press in (("rest", rest), ("view3d", view3d)):
                            before()
                            t, code = press()
                            ms[path].append(t)
                            st[path].append(code)
                            ok[path].append(code == 200 and latched())
                            after()
                            srv.call(rt.cell.reset(by="bench", role="system", source="bench"))
                            time.sleep(args.gap)
                        if (i + 1) % max(1, args.samples // 4) == 0 or i + 1 == args.samples:
                            progress(f"{name}: {i + 1}/{args.samples} samples")
                results[name] = {p: _summary(ms[p], st[p], ok[p]) for p in ms}
        finally:
            client.close()
            srv.stop()
    conditions = {n: results[n] for n in args.conditions}
    return {
        "driver": args.driver,
        "samples": args.samples,
        "upload_mp": args.upload_mp,
        "target_p99_ms": TARGET_P99_MS,
        "conditions": conditions,
        "uploads": results.get("uploads", {"statuses": []}),
        "all_within_target": all(
            c["rest"]["p99_ms"] is not None and c["rest"]["p99_ms"] <= TARGET_P99_MS
            for c in conditions.values()
        ),
        "all_latched": all(c[p]["all_latched"] for c in conditions.values() for p in c),
    }


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def _print(res: dict[str, Any]) -> None:
    t = Table(
        title=f"E-STOP latency, ms ({res['driver']} arm, {res['samples']} samples per path and "
        f"condition; baseline: the 3D view's E-STOP)"
    )
    for col in ("condition", "REST p50", "REST p99", "REST max", "status", "latched",
                "3D view p50", "3D view p99", f"REST p99 <= {TARGET_P99_MS:.0f}"):  # fmt: skip
        t.add_column(col)
    for name, c in res["conditions"].items():
        r, v = c["rest"], c["view3d"]
        ok = r["p99_ms"] is not None and r["p99_ms"] <= TARGET_P99_MS
        t.add_row(
            name, _f(r["p50_ms"]), _f(r["p99_ms"]), _f(r["max_ms"]),
            " ".join(f"{k}:{n}" for k, n in r["status"].items()),
            "yes" if r["all_latched"] and v["all_latched"] else "NO",
            _f(v["p50_ms"]), _f(v["p99_ms"]), "yes" if ok else "NO",
        )  # fmt: skip
    out.print(t)
    ups = res["uploads"]["statuses"]
    if ups:
        counts: dict[int, int] = {}
        for code in ups:
            counts[code] = counts.get(code, 0) + 1
        out.print(f"uploads during the busy-loop condition ({res['upload_mp']:g} MP PNG): "
                  + ", ".join(f"{k}: {n}" for k, n in sorted(counts.items())))  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--samples", type=int, default=40,
                    help=f"E-STOPs per path and condition, 1..{MAX_SAMPLES}")  # fmt: skip
    ap.add_argument("--driver", choices=("sim", "ideal"), default="sim",
                    help="the simulated cell (MuJoCo, its belt) or the ideal arm")  # fmt: skip
    ap.add_argument("--upload-mp", type=float, default=12.0,
                    help="megapixels of the image uploaded in the busy-loop condition, 0.1..50")  # fmt: skip
    ap.add_argument("--gap", type=float, default=0.05, help="s between samples, 0..10")
    ap.add_argument("--conditions", default=",".join(CONDITIONS),
                    help="comma-separated subset of: " + ", ".join(CONDITIONS))  # fmt: skip
    ap.add_argument("--short", action="store_true",
                    help="3 samples, the ideal arm, a 1 MP upload (the test's mode)")  # fmt: skip
    ap.add_argument("--json", action="store_true", help="print the result as JSON last")
    args = ap.parse_args(argv)
    if args.short:
        args.samples, args.driver, args.upload_mp = 3, "ideal", 1.0
    if not 1 <= args.samples <= MAX_SAMPLES:
        ap.error(f"--samples must be in 1..{MAX_SAMPLES}, got {args.samples}")
    if not (math.isfinite(args.upload_mp) and 0.1 <= args.upload_mp <= 50.0):
        ap.error(f"--upload-mp must be in [0.1, 50], got {args.upload_mp}")
    if not (math.isfinite(args.gap) and 0.0 <= args.gap <= 10.0):
        ap.error(f"--gap must be in [0, 10] s, got {args.gap}")
    names = [n.strip() for n in args.conditions.split(",") if n.strip()]
    unknown = [n for n in names if n not in CONDITIONS]
    if unknown or not names:
        ap.error(f"--conditions must name some of {', '.join(CONDITIONS)}, got {unknown or names}")
    args.conditions = [n for n in CONDITIONS if n in names]  # throttled last: it stays blocked

    def progress(msg: str) -> None:
        print(f"[estop] {msg}", file=sys.stderr, flush=True)

    # every press logs a warning by design; hundreds of them would bury the progress
    logging.getLogger("backend").setLevel(logging.ERROR)

    res = run(args, progress)
    _print(res)
    if args.json:
        print(json.dumps(res), flush=True)


if __name__ == "__main__":
    main()
