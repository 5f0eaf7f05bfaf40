"""Recognising recorded images through the product: COIL-20 trained through the REST API,
the threshold chosen by the product, queries through ``POST /api/recognition/recognise``.

Protocol (one process, a real uvicorn server on 127.0.0.1, SQLite):

1. objects 1-10 (``obj1`` .. ``obj10``) are created and their views at 10 degree spacing
   (COIL index ``k`` even: 36 per object) uploaded through ``POST /api/models/{id}/views``;
2. the product recomputes its automatic threshold by itself after the uploads (the
   threshold keeper, one coalesced ``threshold`` job); the benchmark only waits for it;
3. the untrained views of objects 1-10 (``k`` odd: known objects at new angles) and every
   view of objects 11-15 (unknown objects) are sent to the endpoint one image per request
   with ``store=true`` (decoding and storage included in its time);
4. baseline, same run, same images, same index and thresholds: the library's
   :func:`vision.recognition.recognise` on the decoded images; and every 4th query through
   the endpoint again without ``store`` (what storing the row costs).

Figures: known top-1 (the best model is the right one), false rejects (a known image not
``recognized``), false accepts (an unknown image ``recognized``), misrecognitions (a known
image recognised as another object), and the time per image of the endpoint and of the
library.  Targets: top-1 >= 99 %, false accepts <= 2 %, false rejects <= 5 %, endpoint
<= 1.5 x library.

``python -m benchmarks.recorded [--short] [--json]``; ``--short`` trains at 20 degree
spacing and subsamples the queries (what ``tests/benchmarks`` runs: it checks the run, not
the targets, which need the full protocol).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import socket
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np

from benchmarks.recognition_data import N_VIEWS, coil_folder

TRAINED = range(1, 11)
UNKNOWN = range(11, 16)
TARGETS = {"top1": 0.99, "false_accepts": 0.02, "false_rejects": 0.05, "time_ratio": 1.5}


@dataclass(frozen=True)
class Plan:
    """Which views are trained and which are queried."""

    train_step: int
    """Every ``train_step``-th COIL index is trained (2: 10 degrees)."""
    known_step: int
    """Every ``known_step``-th untrained view of objects 1-10 is queried."""
    unknown_step: int
    """Every ``unknown_step``-th view of objects 11-15 is queried."""

    def trained(self, k: int) -> bool:
        return k % self.train_step == 0

    def known_queries(self) -> list[tuple[int, int]]:
        ks = [k for k in range(N_VIEWS) if not self.trained(k)]
        return [(o, k) for o in TRAINED for k in ks[:: self.known_step]]

    def unknown_queries(self) -> list[tuple[int, int]]:
        return [(o, k) for o in UNKNOWN for k in range(0, N_VIEWS, self.unknown_step)]


FULL = Plan(train_step=2, known_step=1, unknown_step=1)
SHORT = Plan(train_step=4, known_step=9, unknown_step=24)


def _say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _progress(what: str, done: int, total: int) -> None:
    if done == total or done % max(1, total // 20) == 0:
        print(f"\r{what}: {done}/{total}", end="\n" if done == total else "", file=sys.stderr,
              flush=True)  # fmt: skip


@contextmanager
def _server(settings: Any) -> Iterator[tuple[str, Any]]:
    """The app of ``settings`` served by uvicorn on a free port, in a thread."""
    import uvicorn

    from backend.api.limits import uvicorn_options
    from backend.app import create_app
    from backend.eventloop import run

    app = create_app(settings)
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    server = uvicorn.Server(
        uvicorn.Config(app, log_level="warning", lifespan="on", **uvicorn_options())
    )
    thread = threading.Thread(target=lambda: run(server.serve(sockets=[sock])), daemon=True)
    thread.start()
    t0 = time.monotonic()
    while not server.started and thread.is_alive() and time.monotonic() - t0 < 120:
        time.sleep(0.05)
    try:
        if not server.started:
            raise RuntimeError("the server did not start")
        yield f"http://127.0.0.1:{port}", app
    finally:
        server.should_exit = True
        thread.join(timeout=60)
        sock.close()


def _png(path: Path) -> bytes:
    return path.read_bytes()


def train(client: httpx.Client, folder: Path, plan: Plan) -> dict[str, int]:
    """Create ``obj1`` .. ``obj10`` and upload their trained views; model ids by name."""
    ids = {}
    for n, o in enumerate(TRAINED, 1):
        r = client.post("/api/models", json={"name": f"obj{o}", "kind": "2d"})
        r.raise_for_status()
        mid = r.json()["id"]
        ids[f"obj{o}"] = mid
        files = [("images", (f"obj{o}__{k}.png", _png(folder / f"obj{o}__{k}.png"), "image/png"))
                 for k in range(N_VIEWS) if plan.trained(k)]  # fmt: skip
        r = client.post(f"/api/models/{mid}/views", files=files, data={"viewpoints": "1"})
        r.raise_for_status()
        _progress("uploading views (objects)", n, len(TRAINED))
    return ids


def wait_for_threshold(client: httpx.Client, timeout_s: float) -> dict[str, Any]:
    """The automatic threshold the product chose by itself (polls its status)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        s = client.get("/api/recognition/threshold").json()
        if s["state"] == "idle" and s["settings"]["chosen_by"] == "auto":
            return dict(s)
        time.sleep(0.5)
    raise TimeoutError(f"no automatic threshold after {timeout_s} s")


def _truth(o: int) -> str | None:
    return f"obj{o}" if o in TRAINED else None


def score(rows: list[tuple[str | None, dict[str, Any]]]) -> dict[str, Any]:
    """Rates from ``(truth model or None, result)`` pairs (module docstring)."""
    known = [(t, r) for t, r in rows if t is not None]
    unknown = [r for t, r in rows if t is None]
    top1 = sum(r["best_model"] == t for t, r in known)
    rejects = sum(r["decision"] != "recognized" for _t, r in known)
    wrong = sum(r["decision"] == "recognized" and r["model"] != t for t, r in known)
    accepts = sum(r["decision"] == "recognized" for r in unknown)
    return {
        "known": len(known),
        "unknown": len(unknown),
        "top1": top1 / max(len(known), 1),
        "false_rejects": rejects / max(len(known), 1),
        "misrecognised": wrong,
        "false_accepts": accepts / max(len(unknown), 1),
        "false_accept_count": accepts,
        "false_reject_count": rejects,
    }


def run(data_dir: Path, *, plan: Plan = FULL, workdir: Path | None = None) -> dict[str, Any]:
    """Run the protocol (module docstring); returns the figures."""
    from backend.api.deps import runtime_of
    from backend.auth import create_user
    from backend.db.migrate import upgrade
    from backend.db.models import Role
    from backend.db.session import Database
    from backend.recognition.thresholds import current_choice
    from backend.settings import Settings
    from vision.recognition import recognise

    folder = coil_folder(data_dir)
    tmp_ctx = tempfile.TemporaryDirectory() if workdir is None else None
    work = Path(tmp_ctx.name) if tmp_ctx is not None else workdir
    assert work is not None
    try:
        settings = Settings(
            database_url=f"sqlite+aiosqlite:///{work / 'recorded.db'}",
            var_dir=work / "var",
            driver="ideal",
            camera="folder",
            camera_folder=folder,
            view3d_enabled=False,
            bootstrap_operator=False,
            secret_key="recorded-benchmark-secret-0123456789",
            threshold_follow=True,
            threshold_quiet_s=1.0,
            data_dir=data_dir,
        )
        upgrade(settings.database_url)

        async def user() -> str:
            db = Database(settings.database_url)
            try:
                async with db.session() as s:
                    _, tok = await create_user(s, "bench", Role.engineer,
                                               settings.secret_key.get_secret_value())  # fmt: skip
                    return tok
            finally:
                await db.dispose()

        token = asyncio.run(user())
        with _server(settings) as (base, app):
            client = httpx.Client(base_url=base, headers={"Authorization": f"Bearer {token}"},
                                  timeout=300)  # fmt: skip
            t0 = time.perf_counter()
            train(client, folder, plan)
            t_upload = time.perf_counter() - t0
            _say("waiting for the product to choose its threshold")
            status = wait_for_threshold(client, 1800)
            t_threshold = time.perf_counter() - t0 - t_upload
            queries = [(o, k) for o, k in plan.known_queries() + plan.unknown_queries()]
            rows: list[tuple[str | None, dict[str, Any]]] = []
            t_endpoint: list[float] = []
            t_server: list[float] = []
            for n, (o, k) in enumerate(queries, 1):
                name = f"obj{o}__{k}.png"
                data = _png(folder / name)
                t1 = time.perf_counter()
                r = client.post("/api/recognition/recognise",
                                files=[("images", (name, data, "image/png"))],
                                data={"viewpoint": "1", "store": "true"})  # fmt: skip
                t_endpoint.append(time.perf_counter() - t1)
                r.raise_for_status()
                rows.append((_truth(o), r.json()["data"][0]))
                t_server.append(r.json()["durations"]["total"])
                _progress("recognising through the endpoint", n, len(queries))
            # The endpoint without storing (every 4th query): what storage costs.
            t_nostore: list[float] = []
            for o, k in queries[::4]:
                name = f"obj{o}__{k}.png"
                data = _png(folder / name)
                t1 = time.perf_counter()
                r = client.post("/api/recognition/recognise",
                                files=[("images", (name, data, "image/png"))],
                                data={"viewpoint": "1", "store": "false"})  # fmt: skip
                t_nostore.append(time.perf_counter() - t1)
                r.raise_for_status()
            # The library on the same images, index and thresholds, in the same process.
            rt = runtime_of(app)
            assert rt is not None

            async def choice_now() -> Any:
                db = Database(settings.database_url)
                try:
                    async with db.session() as s:
                        return await current_choice(s)
                finally:
                    await db.dispose()

            choice = asyncio.run(choice_now())
            lib_rows: list[tuple[str | None, dict[str, Any]]] = []
            t_library: list[float] = []
            for n, (o, k) in enumerate(queries, 1):
                grey = cv2.imread(str(folder / f"obj{o}__{k}.png"), cv2.IMREAD_COLOR)
                rgb = np.ascontiguousarray(grey[:, :, ::-1])
                t1 = time.perf_counter()
                with rt.live_index.reading() as index:
                    rec = recognise(index, rgb, viewpoint=1, threshold=choice)
                t_library.append(time.perf_counter() - t1)
                lib_rows.append((_truth(o), {"decision": rec.decision, "model": rec.model,
                                             "best_model": rec.best_model}))  # fmt: skip
                _progress("recognising with the library", n, len(queries))
            stored = client.get("/api/inspections", params={"limit": 1}).json()
            client.close()
    finally:
        if tmp_ctx is not None:
            tmp_ctx.cleanup()
    d = status["settings"]["detail"]
    endpoint_ms = 1e3 * statistics.median(t_endpoint)
    library_ms = 1e3 * statistics.median(t_library)
    return {
        "plan": {
            "train_step_deg": 5 * plan.train_step,
            "known_step": plan.known_step,
            "unknown_step": plan.unknown_step,
        },
        "trained_views": len(TRAINED) * sum(plan.trained(k) for k in range(N_VIEWS)),
        "threshold": status["settings"]["global_threshold"],
        "rule": d.get("rule"),
        "advice": d.get("advice", []),
        "upload_s": round(t_upload, 2),
        "threshold_s": round(t_threshold, 2),
        "threshold_runs": status["runs"],
        "threshold_superseded": status["superseded"],
        "endpoint": score(rows),
        "library": score(lib_rows),
        "endpoint_ms_per_image": round(endpoint_ms, 2),
        "library_ms_per_image": round(library_ms, 2),
        "server_ms_per_image": round(1e3 * statistics.median(t_server), 2),
        "endpoint_nostore_ms_per_image": round(1e3 * statistics.median(t_nostore), 2),
        "time_ratio": round(endpoint_ms / library_ms, 3),
        "stored_rows": stored["count"],
        "targets": TARGETS,
    }


def table(res: dict[str, Any]) -> str:
    """The figures side by side with the library baseline and the targets."""
    e, lib = res["endpoint"], res["library"]
    lines = [
        f"COIL-20: objects 1-10 trained at {res['plan']['train_step_deg']} deg spacing "
        f"({res['trained_views']} views uploaded in {res['upload_s']} s); threshold "
        f"{res['threshold']:.4f} chosen by the product in {res['threshold_s']} s "
        f"({res['threshold_runs']} recomputation(s), {res['threshold_superseded']} stopped by "
        f"a later upload): {res['rule']}",
        f"queries: {e['known']} untrained views of objects 1-10, {e['unknown']} views of 11-15",
        "",
        f"{'':28s}{'endpoint':>12s}{'library':>12s}{'target':>10s}",
        f"{'known top-1':28s}{e['top1']:>12.2%}{lib['top1']:>12.2%}{'>= 99 %':>10s}",
        f"{'false rejects':28s}{e['false_rejects']:>12.2%}{lib['false_rejects']:>12.2%}"
        f"{'<= 5 %':>10s}",
        f"{'false accepts':28s}{e['false_accepts']:>12.2%}{lib['false_accepts']:>12.2%}"
        f"{'<= 2 %':>10s}",
        f"{'misrecognised (count)':28s}{e['misrecognised']:>12d}{lib['misrecognised']:>12d}",
        f"{'time per image, ms (median)':28s}{res['endpoint_ms_per_image']:>12.1f}"
        f"{res['library_ms_per_image']:>12.1f}",
        f"{'  of which in the handler':28s}{res['server_ms_per_image']:>12.1f}",
        f"{'  without storing the row':28s}{res['endpoint_nostore_ms_per_image']:>12.1f}",
        f"{'endpoint / library':28s}{res['time_ratio']:>12.2f}{'':>12s}{'<= 1.5':>10s}",
        f"stored inspection rows: {res['stored_rows']}",
    ]
    for a in res["advice"]:
        lines.append(f"advice: {a}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", action="store_true", help="print JSON on the last line")
    p.add_argument("--short", action="store_true", help="subsampled queries (tests)")
    p.add_argument("--data-dir", type=Path, default=None, help="default: the settings'")
    args = p.parse_args(argv)
    from backend.settings import Settings

    data_dir = args.data_dir or Settings().data_dir
    if not data_dir.is_absolute():
        data_dir = (Path(__file__).resolve().parents[1] / data_dir).resolve()
    res = run(data_dir, plan=SHORT if args.short else FULL)
    print(table(res))
    if args.json:
        print(json.dumps(res))


if __name__ == "__main__":
    main()
