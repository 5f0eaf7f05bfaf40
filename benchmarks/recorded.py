"""Recognising recorded images through the product: COIL-20 trained through the REST API,
the threshold chosen by the product, queries through ``POST /api/recognition/recognise`` and
through a recorded cell's inspection run.

Protocol (one process, real uvicorn servers on 127.0.0.1, one SQLite database):

1. objects 1-10 (``obj1`` .. ``obj10``) are created and their views at 10 degree spacing
   (COIL index ``k`` even: 36 per object) uploaded through ``POST /api/models/{id}/views``;
2. the product recomputes its automatic threshold by itself after the uploads (the
   threshold keeper, one coalesced ``threshold`` job); the benchmark only waits for it;
3. the untrained views of objects 1-10 (``k`` odd: known objects at new angles) and every
   view of objects 11-15 (unknown objects) are sent to the endpoint one image per request
   with ``store=true`` (decoding and storage included in its time);
4. baseline, same run, same images, same index and thresholds: the library's
   :func:`vision.recognition.recognise` on the decoded images, timed image by image next
   to the endpoint; every 4th image also goes through the endpoint without ``store`` (what
   storing the row costs).  The calls on one image take turns at going first, so that the
   load of a shared machine and a cold image fall on each alike.  ``--rounds N`` repeats the timed pass and
   quotes the median of the rounds' ratios (every round must give the same answers);
4b. the way users send a folder (``visioncell recognise FOLDER --store``): the same queries
   in requests of the CLI's batch size (8 images), built and posted by the CLI's own code,
   timed next to the library on the same images, batch by batch, taking turns at going
   first; their answers must be the one-image answers.  The time target applies to this
   pass (the table and the JSON give both passes, labelled);
5. a recorded cell: a second server on the same database with the ideal driver and the
   folder camera replaying the same queries, shuffled, one image per look in the order of
   the recording's ``order.txt``; one ``POST /api/inspection/run`` (policy ``top-only``)
   inspects them all, and every stored row is read back over REST and scored.

Figures: known top-1 (the best model is the right one), false rejects (a known image not
``recognized``), false accepts (an unknown image ``recognized``), misrecognitions (a known
image recognised as another object), and the time per image of the endpoint and of the
library, with the machine's load average.  Targets: top-1 >= 99 %, false accepts <= 2 %,
false rejects <= 5 % (endpoint and recorded cell), endpoint <= 1.5 x library the way the
CLI sends a folder (one image per request is measured and shown too).

``python -m benchmarks.recorded [--short] [--rounds N] [--no-cell] [--json]``; ``--short``
trains at 20 degree spacing and subsamples the queries (what ``tests/benchmarks`` runs: it
checks the run, not the targets, which need the full protocol).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
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

from backend.cli.recognise import BATCH as CLI_RECOGNISE_BATCH
from benchmarks.recognition_data import N_VIEWS, coil_folder

TRAINED = range(1, 11)
UNKNOWN = range(11, 16)
TARGETS = {"top1": 0.99, "false_accepts": 0.02, "false_rejects": 0.05, "time_ratio": 1.5}
#: Images per request of the timed pass made the CLI's way: ``visioncell recognise``'s own.
CLI_BATCH = CLI_RECOGNISE_BATCH


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


def _recognise_once(
    client: httpx.Client, folder: Path, name: str, *, store: bool
) -> tuple[float, dict[str, Any]]:
    """One image through the endpoint: the client's wall time and the answer."""
    data = _png(folder / name)
    t1 = time.perf_counter()
    r = client.post("/api/recognition/recognise", files=[("images", (name, data, "image/png"))],
                    data={"viewpoint": "1", "store": "true" if store else "false"})  # fmt: skip
    t = time.perf_counter() - t1
    r.raise_for_status()
    return t, dict(r.json())


def _key(res: dict[str, Any]) -> tuple[Any, ...]:
    """What must not change between rounds: the decision, the model and every score."""
    return (res["decision"], res["model"], res["best_model"],
            tuple((s["model"], s["score"]) for s in res["scores"]))  # fmt: skip


def time_round(client: httpx.Client, folder: Path, queries: list[tuple[int, int]], library: Any,
               *, round_no: int) -> dict[str, Any]:  # fmt: skip
    """One timed pass over ``queries``: per image the endpoint (``store=true``) and the
    library, and every 4th image the endpoint without storing, taking turns at going first."""
    rows: list[tuple[str | None, dict[str, Any]]] = []
    lib_rows: list[tuple[str | None, dict[str, Any]]] = []
    t: dict[str, list[float]] = {k: [] for k in ("endpoint", "library", "nostore", "handler",
                                                 "store")}  # fmt: skip
    for n, (o, k) in enumerate(queries, 1):
        name = f"obj{o}__{k}.png"
        bgr = cv2.imread(str(folder / name), cv2.IMREAD_COLOR)
        if bgr is None:
            raise FileNotFoundError(f"cannot read {folder / name}")
        rgb = np.ascontiguousarray(bgr[:, :, ::-1])
        # Which call comes first (a cold image for it) rotates from image to image.
        steps = ["endpoint", "library"] + (["nostore"] if n % 4 == 0 else [])
        turn = (n // 4 + round_no) % len(steps) if n % 4 == 0 else (n + round_no) % 2
        for step in steps[turn:] + steps[:turn]:
            if step == "endpoint":
                dt, body = _recognise_once(client, folder, name, store=True)
                t["endpoint"].append(dt)
                t["handler"].append(body["durations"]["total"])
                t["store"].append(body["durations"]["store"])
                rows.append((_truth(o), body["data"][0]))
            elif step == "nostore":
                t["nostore"].append(_recognise_once(client, folder, name, store=False)[0])
            else:
                t1 = time.perf_counter()
                rec = library(rgb)
                t["library"].append(time.perf_counter() - t1)
                lib_rows.append((_truth(o), {"decision": rec.decision, "model": rec.model,
                                             "best_model": rec.best_model}))  # fmt: skip
        _progress(f"round {round_no + 1}: endpoint and library", n, len(queries))
    ms = {k: round(1e3 * statistics.median(v), 2) for k, v in t.items()}
    return {"rows": rows, "lib_rows": lib_rows, "ms": ms,
            "time_ratio": round(ms["endpoint"] / ms["library"], 3)}  # fmt: skip


def time_batches(base: str, token: str, folder: Path, queries: list[tuple[int, int]],
                 library: Any, *, round_no: int, batch: int) -> dict[str, Any]:  # fmt: skip
    """One timed pass over ``queries`` the way ``visioncell recognise FOLDER --store`` sends
    them: ``batch`` images per request, built and posted by the CLI's own code, next to the
    library on the same images (taking turns at going first, batch by batch)."""
    from backend.cli.recognise import _send

    url = base + "/api/recognition/recognise"
    fields = {"viewpoint": "1", "store": "true"}
    results: dict[str, dict[str, Any]] = {}
    t: dict[str, list[float]] = {"cli": [], "library": []}
    for n, start in enumerate(range(0, len(queries), batch)):
        part = queries[start : start + batch]
        paths = [folder / f"obj{o}__{k}.png" for o, k in part]
        images = []
        for p in paths:
            bgr = cv2.imread(str(p), cv2.IMREAD_COLOR)
            if bgr is None:
                raise FileNotFoundError(f"cannot read {p}")
            images.append(np.ascontiguousarray(bgr[:, :, ::-1]))
        for step in ["cli", "library"] if (n + round_no) % 2 == 0 else ["library", "cli"]:
            t1 = time.perf_counter()
            if step == "cli":
                got = _send(url, token, paths, fields)
            else:
                for rgb in images:
                    library(rgb)
            t[step].append((time.perf_counter() - t1) / len(part))
        if len(got) != len(part) or any("error" in r for r in got):
            raise RuntimeError(f"a batch was refused: {[r.get('error') for r in got]}")
        results.update((r["name"], r) for r in got)
        _progress(f"round {round_no + 1}: {batch} images per request (the CLI's way)",
                  min(start + batch, len(queries)), len(queries))  # fmt: skip
    ms = {k: round(1e3 * statistics.median(v), 2) for k, v in t.items()}
    return {"results": results, "ms": ms, "time_ratio": round(ms["cli"] / ms["library"], 3)}


def recorded_cell(settings: Any, token: str, folder: Path, work: Path,
                  queries: list[tuple[int, int]], expected: dict[str, tuple[Any, ...]]) -> dict[str, Any]:  # fmt: skip
    """Part 5 of the protocol: a cell on the same database replaying ``queries`` (shuffled)
    from its folder camera, one image per look, through one inspection run over REST."""
    from backend.settings import Settings

    sequence = list(queries)
    random.Random(32).shuffle(sequence)
    recording = work / "recording"
    recording.mkdir()
    names = []
    for i, (o, k) in enumerate(sequence):
        # Names whose sorted order is not the recording's: the order file states it.
        name = f"obj{o}__{k}_shot{i:04d}.png"
        (recording / name).symlink_to(folder / f"obj{o}__{k}.png")
        names.append(name)
    (recording / "order.txt").write_text("# the recorded top views\n" + "\n".join(names) + "\n")
    cell = Settings(**{**settings.model_dump(), "camera_folder": recording,
                       "camera_replay": "look", "camera_order": "manifest"})  # fmt: skip
    with _server(cell) as (base, _app):
        client = httpx.Client(base_url=base, headers={"Authorization": f"Bearer {token}"},
                              timeout=300)  # fmt: skip
        status = wait_for_threshold(client, 600)
        t0 = time.perf_counter()
        r = client.post("/api/inspection/run", json={"policy": "top-only", "count": len(sequence)})
        r.raise_for_status()
        job_id = r.json()["job"]["id"]
        while True:
            job = client.get(f"/api/jobs/{job_id}").json()["job"]
            if job["state"] != "running":
                break
            _progress("recorded cell: inspecting", round(job["progress"] * len(sequence)),
                      len(sequence))  # fmt: skip
            time.sleep(1.0)
        t_run = time.perf_counter() - t0
        if job["state"] != "done":
            raise RuntimeError(f"the inspection run ended {job['state']}: {job}")
        ids = job["result"]["inspection_ids"]
        stored = []
        for n, iid in enumerate(ids, 1):
            r = client.get(f"/api/inspections/{iid}")
            r.raise_for_status()
            stored.append(r.json())
            _progress("recorded cell: reading the stored rows", n, len(ids))
        threshold = status["settings"]["global_threshold"]
        client.close()
    if len(stored) != len(sequence):
        raise RuntimeError(f"{len(stored)} rows stored for a recording of {len(sequence)}")
    rows = []
    agree = 0
    for (o, k), row in zip(sequence, stored, strict=True):
        scores = row["scores"] or {}
        best = max(scores, key=lambda m: (scores[m], m)) if scores else None
        rows.append((_truth(o), {"decision": row["decision"], "model": row["model"],
                                 "best_model": best}))  # fmt: skip
        agree += (row["decision"], row["model"]) == expected[f"obj{o}__{k}.png"][:2]
    cycle = [float(r["duration_s"]) for r in stored if r["duration_s"] is not None]
    return {
        "inspections": len(stored),
        "threshold": threshold,
        "run_s": round(t_run, 1),
        "cycle_ms_median": round(1e3 * statistics.median(cycle), 1) if cycle else None,
        "same_as_endpoint": agree,
        "failed": sum(r["decision"] == "failed" for r in stored),
        **score(rows),
    }


def run(data_dir: Path, *, plan: Plan = FULL, workdir: Path | None = None, rounds: int = 1,
        cell: bool = True) -> dict[str, Any]:  # fmt: skip
    """Run the protocol (module docstring); returns the figures."""
    from backend.api.deps import runtime_of
    from backend.auth import create_user
    from backend.db.migrate import upgrade
    from backend.db.models import Role
    from backend.db.session import Database
    from backend.recognition.thresholds import current_choice
    from backend.settings import Settings
    from vision.recognition import recognise

    if isinstance(rounds, bool) or not isinstance(rounds, int) or not 1 <= rounds <= 20:
        raise ValueError(f"rounds must be an integer in 1..20, got {rounds!r}")
    folder = coil_folder(data_dir)
    tmp_ctx = tempfile.TemporaryDirectory() if workdir is None else None
    work = Path(tmp_ctx.name) if tmp_ctx is not None else workdir
    assert work is not None
    load = [round(x, 2) for x in os.getloadavg()]
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
        queries = [(o, k) for o, k in plan.known_queries() + plan.unknown_queries()]
        with _server(settings) as (base, app):
            client = httpx.Client(base_url=base, headers={"Authorization": f"Bearer {token}"},
                                  timeout=300)  # fmt: skip
            t0 = time.perf_counter()
            train(client, folder, plan)
            t_upload = time.perf_counter() - t0
            _say("waiting for the product to choose its threshold")
            status = wait_for_threshold(client, 1800)
            t_threshold = time.perf_counter() - t0 - t_upload
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

            def library(rgb: np.ndarray) -> Any:
                with rt.live_index.reading() as index:
                    return recognise(index, rgb, viewpoint=1, threshold=choice)

            passes, batched = [], []
            for r in range(rounds):
                passes.append(time_round(client, folder, queries, library, round_no=r))
                batched.append(time_batches(base, token, folder, queries, library, round_no=r,
                                            batch=CLI_BATCH))  # fmt: skip
            stored = client.get("/api/inspections", params={"limit": 1}).json()
            client.close()
        first = passes[0]
        expected = {f"obj{o}__{k}.png": _key(res)
                    for (o, k), (_t, res) in zip(queries, first["rows"], strict=True)}  # fmt: skip
        same = all(
            _key(res) == expected[f"obj{o}__{k}.png"]
            for p in passes[1:]
            for (o, k), (_t, res) in zip(queries, p["rows"], strict=True)
        )
        # The batched answers are the one-image answers: a request's images are independent.
        batched_same = all(
            _key(b["results"][name]) == key for b in batched for name, key in expected.items()
        )
        cell_res = recorded_cell(settings, token, folder, work, queries, expected) if cell else None
        load_after = [round(x, 2) for x in os.getloadavg()]
    finally:
        if tmp_ctx is not None:
            tmp_ctx.cleanup()
    d = status["settings"]["detail"]
    ratios = [p["time_ratio"] for p in passes]
    per_round = {k: [p["ms"][k] for p in passes] for k in first["ms"]}
    med = {k: round(statistics.median(v), 2) for k, v in per_round.items()}
    cli_ratios = [b["time_ratio"] for b in batched]
    cli_per_round = {k: [b["ms"][k] for b in batched] for k in batched[0]["ms"]}
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
        "endpoint": score(first["rows"]),
        "library": score(first["lib_rows"]),
        "rounds": rounds,
        "rounds_identical": same,
        "endpoint_ms_per_image": med["endpoint"],
        "library_ms_per_image": med["library"],
        "server_ms_per_image": med["handler"],
        "store_ms_per_image": med["store"],
        "endpoint_nostore_ms_per_image": med["nostore"],
        "time_ratio": round(statistics.median(ratios), 3),
        "time_ratios": ratios,
        "ms_per_round": per_round,
        "cli_batch": CLI_BATCH,
        "cli_ms_per_image": round(statistics.median(cli_per_round["cli"]), 2),
        "cli_library_ms_per_image": round(statistics.median(cli_per_round["library"]), 2),
        "cli_time_ratio": round(statistics.median(cli_ratios), 3),
        "cli_time_ratios": cli_ratios,
        "cli_ms_per_round": cli_per_round,
        "cli_answers_identical": batched_same,
        "time_target_applies_to": "cli",
        "stored_rows": stored["count"],
        "recorded_cell": cell_res,
        "load_average": {"before": load, "after": load_after, "cpus": os.cpu_count()},
        "targets": TARGETS,
    }


def table(res: dict[str, Any]) -> str:
    """The figures side by side with the library baseline and the targets."""
    e, lib, c = res["endpoint"], res["library"], res["recorded_cell"]
    la = res["load_average"]
    lines = [
        f"COIL-20: objects 1-10 trained at {res['plan']['train_step_deg']} deg spacing "
        f"({res['trained_views']} views uploaded in {res['upload_s']} s); threshold "
        f"{res['threshold']:.4f} chosen by the product in {res['threshold_s']} s "
        f"({res['threshold_runs']} recomputation(s), {res['threshold_superseded']} stopped by "
        f"a later upload): {res['rule']}",
        f"queries: {e['known']} untrained views of objects 1-10, {e['unknown']} views of 11-15"
        f"; {res['rounds']} timed round(s), answers identical in every round: "
        f"{res['rounds_identical']}",
        f"load average {la['before'][0]:.1f} at the start, {la['after'][0]:.1f} at the end, "
        f"{la['cpus']} CPUs",
        "",
        f"{'':28s}{'endpoint':>12s}{'library':>12s}{'rec. cell':>12s}{'target':>10s}",
    ]
    cell = c or {}

    def row(label: str, key: str, target: str) -> str:
        cv = f"{cell[key]:>12.2%}" if c else f"{'-':>12s}"
        return f"{label:28s}{e[key]:>12.2%}{lib[key]:>12.2%}{cv}{target:>10s}"

    lines += [
        row("known top-1", "top1", ">= 99 %"),
        row("false rejects", "false_rejects", "<= 5 %"),
        row("false accepts", "false_accepts", "<= 2 %"),
        f"{'misrecognised (count)':28s}{e['misrecognised']:>12d}{lib['misrecognised']:>12d}"
        + (f"{c['misrecognised']:>12d}" if c else ""),
        f"{'time per image, ms (median)':28s}{res['endpoint_ms_per_image']:>12.1f}"
        f"{res['library_ms_per_image']:>12.1f}",
        f"{'  of which in the handler':28s}{res['server_ms_per_image']:>12.1f}",
        f"{'  of which storing the row':28s}{res['store_ms_per_image']:>12.1f}",
        f"{'  without storing the row':28s}{res['endpoint_nostore_ms_per_image']:>12.1f}",
        f"{'endpoint / library':28s}{res['time_ratio']:>12.2f}{'':>34s}"
        f"   (one image per request; rounds: {', '.join(f'{r:.2f}' for r in res['time_ratios'])})",
        f"the CLI's way ({res['cli_batch']} images per request, stored; answers as one by one: "
        f"{res['cli_answers_identical']}):",
        f"{'  time per image, ms (median)':28s}{res['cli_ms_per_image']:>12.1f}"
        f"{res['cli_library_ms_per_image']:>12.1f}",
        f"{'  CLI / library':28s}{res['cli_time_ratio']:>12.2f}{'':>24s}{'<= 1.5':>10s}"
        f"   (rounds: {', '.join(f'{r:.2f}' for r in res['cli_time_ratios'])})",
        f"stored inspection rows (uploads, one per image per pass): {res['stored_rows']}",
    ]
    if c:
        lines.append(
            f"recorded cell: {c['inspections']} inspections in one run of {c['run_s']} s "
            f"(cycle {c['cycle_ms_median']} ms median), {c['failed']} failed; the same "
            f"decision and model as the endpoint for {c['same_as_endpoint']} of them"
        )
    for a in res["advice"]:
        lines.append(f"advice: {a}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", action="store_true", help="print JSON on the last line")
    p.add_argument("--short", action="store_true", help="subsampled queries (tests)")
    p.add_argument("--rounds", type=int, default=1, help="timed passes (1-20; median ratio)")
    p.add_argument("--no-cell", action="store_true", help="leave out the recorded cell's run")
    p.add_argument("--data-dir", type=Path, default=None, help="default: the settings'")
    args = p.parse_args(argv)
    from backend.settings import Settings

    data_dir = args.data_dir or Settings().data_dir
    if not data_dir.is_absolute():
        data_dir = (Path(__file__).resolve().parents[1] / data_dir).resolve()
    res = run(data_dir, plan=SHORT if args.short else FULL, rounds=args.rounds,
              cell=not args.no_cell)  # fmt: skip
    print(table(res))
    if args.json:
        print(json.dumps(res))


if __name__ == "__main__":
    main()
