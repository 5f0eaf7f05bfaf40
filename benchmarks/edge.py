"""The edge under abuse: ``/api/health`` latency while one client posts 100 MB bodies
without a token and another uploads 12-megapixel images, beside the same probe unloaded.

``visioncell serve`` runs in a child process (ideal arm, folder camera, the default edge
and heavy-work settings).  A prober asks ``GET /api/health`` every ``--interval`` seconds on
a keep-alive connection of its own, first with nothing else running (the baseline), then
for the same time while

* the *unsigned* client sends ``POST /api/robot/move`` with a 100 MB JSON body and no
  token, over and over (a new connection each time, the whole body sent as fast as the
  socket takes it; the answer is read as it comes), and
* the *uploader* sends, one request after the other and in turn, ``--images`` PNGs of
  4000 x 3000 px (44 KB each, 12 MP decoded) as trained views (``POST
  /api/models/{id}/views``: refused from their headers, features are extracted from 4 MP
  at most) and as calibration samples (``POST /api/calibration/sessions/{id}/samples``:
  decoded, the board searched), ``--images`` 1600 x 1200 PNGs as trained views (decoded,
  SIFT), and a truncated JPEG.

Reported: the prober's p50/p99/max per phase, what the abusive clients got (status counts,
time to the 401), and the server's peak RSS (``VmHWM``) after each phase.  Target:
health p99 <= 100 ms under load.  Run::

    .venv/bin/python -m benchmarks.edge [--seconds 20] [--json]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from benchmarks.leanhttp import HttpError, LeanConnection

out = Console()
err = Console(stderr=True)

#: The abusive clients.
CLIENTS = ("unsigned", "uploads")
#: Target of the health probe's p99 under load, ms.
TARGET_P99_MS = 100.0
#: Size of the unsigned client's body, bytes.
BODY_BYTES = 100 * 1000 * 1000
#: Chunk the unsigned client writes at a time, bytes.
CHUNK = 256 * 1024
#: Longest wait for one answer, s (bounds a hang).
TIMEOUT_S = 120.0


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _q(xs: list[float], q: float) -> float | None:
    if not xs:
        return None
    s = sorted(xs)
    return s[min(len(s) - 1, max(0, math.ceil(q / 100 * len(s)) - 1))]


def _peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _big_png() -> bytes:
    """A 4000 x 3000 PNG of a few shapes on grey (tens of KB; 36 MB as decoded RGB)."""
    import cv2
    import numpy as np

    img = np.full((3000, 4000, 3), 120, np.uint8)
    rng = np.random.default_rng(7)
    for _ in range(40):
        x, y = (int(v) for v in rng.integers(0, 3800, 2))
        cv2.rectangle(img, (x, y % 2800), (x + 150, y % 2800 + 150), [int(c) for c in rng.integers(0, 255, 3)], -1)  # fmt: skip
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    assert ok
    return buf.tobytes()


def _truncated_jpeg() -> bytes:
    import cv2
    import numpy as np

    img = np.random.default_rng(3).integers(0, 255, (1200, 1600, 3), dtype=np.uint8)
    ok, buf = cv2.imencode(".jpg", img)
    assert ok
    return buf.tobytes()[: len(buf) // 2]


def _multipart(files: list[tuple[str, bytes]], boundary: str) -> bytes:
    parts = [
        f'--{boundary}\r\nContent-Disposition: form-data; name="images"; filename="{name}"\r\n'
        f"Content-Type: application/octet-stream\r\n\r\n".encode()
        + data
        + b"\r\n"
        for name, data in files
    ]
    return b"".join(parts) + f"--{boundary}--\r\n".encode()


async def _read_answer(reader: asyncio.StreamReader) -> tuple[int, float]:
    """(status, monotonic time the answer's head arrived)."""
    head = await reader.readuntil(b"\r\n\r\n")
    at = time.monotonic()
    status = int(head.split(b" ", 2)[1])
    length = 0
    for line in head.split(b"\r\n")[1:]:
        if line.lower().startswith(b"content-length:"):
            length = int(line.split(b":", 1)[1])
    await reader.readexactly(length)
    return status, at


async def _post(
    port: int, target: str, head: dict[str, str], body: bytes | None, body_len: int
) -> tuple[int, float]:
    """Send one POST (``body``, or ``body_len`` bytes of JSON-looking filler) and return
    (status, seconds to the answer); the whole body is sent even after an early answer."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        lines = [f"POST {target} HTTP/1.1", "Host: 127.0.0.1", f"Content-Length: {body_len}"]
        lines += [f"{k}: {v}" for k, v in head.items()]
        writer.write(("\r\n".join(lines) + "\r\n\r\n").encode())
        t0 = time.monotonic()
        answer = asyncio.ensure_future(_read_answer(reader))
        try:
            if body is not None:
                writer.write(body)
                await writer.drain()
            else:
                filler = b'{"joints": [' + b"0," * (CHUNK // 2 - 8)
                sent = 0
                while sent < body_len:
                    piece = filler[: min(CHUNK, body_len - sent)]
                    writer.write(piece)
                    sent += len(piece)
                    await writer.drain()
        except OSError:
            # the server answered early and closed after a bounded linger: the answer counts
            if not answer.done():
                answer.cancel()
                raise
        status, at = await asyncio.wait_for(answer, TIMEOUT_S)
        return status, at - t0
    finally:
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()


async def _probe(base: str, stop: asyncio.Event, interval_s: float) -> tuple[list[float], int]:
    conn = LeanConnection(base, headers={}, timeout_s=TIMEOUT_S)
    lat: list[float] = []
    errors = 0
    try:
        while not stop.is_set():
            t0 = time.perf_counter()
            try:
                status, _ = await conn.get("/api/health")
                if status != 200:
                    errors += 1
            except HttpError:
                errors += 1
            lat.append((time.perf_counter() - t0) * 1e3)
            await asyncio.sleep(max(0.0, interval_s - (time.perf_counter() - t0)))
    finally:
        await conn.close()
    return lat, errors


async def _unsigned(port: int, stop: asyncio.Event, log: dict[str, Any]) -> None:
    head = {"Content-Type": "application/json"}
    while not stop.is_set():
        try:
            status, dt = await _post(port, "/api/robot/move", head, None, BODY_BYTES)
        except (OSError, asyncio.IncompleteReadError, TimeoutError) as exc:
            log["codes"][type(exc).__name__] += 1
            continue
        log["codes"][str(status)] += 1
        log["answer_s"].append(dt)


async def _uploader(
    port: int, stop: asyncio.Event, log: dict[str, Any], token: str, target: dict, images: int
) -> None:
    """Round robin: 12-MP PNGs as trained views (refused from their headers: features are
    extracted from 4 MP at most), the same as calibration samples (decoded, board
    detection), 2-MP PNGs as trained views (decoded, SIFT), a truncated JPEG."""
    import cv2
    import numpy as np

    png = _big_png()
    small = cv2.imencode(".png", cv2.resize(cv2.imdecode(np.frombuffer(png, np.uint8), 1),
                                            (1600, 1200)))[1].tobytes()  # fmt: skip
    log["png_bytes"] = len(png)
    boundary = "edge-bench-boundary"
    views = f"/api/models/{target['model']}/views"
    samples = f"/api/calibration/sessions/{target['session']}/samples"
    kinds = [
        ("views 12 MP", views, _multipart([(f"v{k}.png", png) for k in range(images)], boundary)),
        ("samples 12 MP", samples, _multipart([(f"s{k}.png", png) for k in range(images)], boundary)),
        ("views 2 MP", views, _multipart([(f"w{k}.png", small) for k in range(images)], boundary)),
        ("truncated", views, _multipart([("cut.jpg", _truncated_jpeg())], boundary)),
    ]  # fmt: skip
    head = {
        "Authorization": f"Bearer {token}",
        "Content-Type": f"multipart/form-data; boundary={boundary}",
    }
    k = 0
    while not stop.is_set():
        kind, path, body = kinds[k % len(kinds)]
        k += 1
        try:
            status, dt = await _post(port, path, head, body, len(body))
        except (OSError, asyncio.IncompleteReadError, TimeoutError) as exc:
            log["codes"][f"{kind}: {type(exc).__name__}"] += 1
            continue
        log["codes"][f"{kind}: {status}"] += 1
        log["answer_s"].append(dt)


async def _abuse(
    port: int, seconds: float, token: str, target: dict, images: int, clients: list[str]
) -> dict:
    """The abusive ``clients`` for ``seconds`` (in a child process: their CPU is not the
    prober's); what they got."""
    stop = asyncio.Event()
    logs = {name: {"codes": Counter(), "answer_s": []} for name in clients}
    tasks = []
    if "unsigned" in logs:
        tasks.append(asyncio.create_task(_unsigned(port, stop, logs["unsigned"])))
    if "uploads" in logs:
        tasks.append(
            asyncio.create_task(_uploader(port, stop, logs["uploads"], token, target, images))
        )
    await asyncio.sleep(seconds)
    stop.set()
    for t in tasks:  # an abusive request in flight is not waited for
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    return {
        name: {
            "codes": dict(log["codes"]),
            "answer_median_s": statistics.median(log["answer_s"]) if log["answer_s"] else None,
            **({"png_bytes": log["png_bytes"]} if "png_bytes" in log else {}),
        }
        for name, log in logs.items()
    }


async def _phase(
    base: str, port: int, seconds: float, interval_s: float, load: dict | None
) -> dict[str, Any]:
    stop = asyncio.Event()
    child = None
    if load is not None:
        child = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "benchmarks.edge", "--abuse",
            json.dumps({"port": port, "seconds": seconds, **load}),
            stdout=asyncio.subprocess.PIPE,
        )  # fmt: skip
    probe = asyncio.create_task(_probe(base, stop, interval_s))
    await asyncio.sleep(seconds)
    stop.set()
    lat, errors = await probe
    res: dict[str, Any] = {
        "health": {
            "n": len(lat), "errors": errors, "p50_ms": _q(lat, 50), "p99_ms": _q(lat, 99),
            "max_ms": max(lat) if lat else None,
        },
    }  # fmt: skip
    if child is not None:
        stdout, _ = await asyncio.wait_for(child.communicate(), TIMEOUT_S)
        res.update(json.loads(stdout.decode().strip().splitlines()[-1]))
    return res


def _serve(tmp: Path) -> tuple[subprocess.Popen, int, str, Any]:
    import cv2
    import numpy as np

    from backend.auth import create_user
    from backend.db.migrate import upgrade
    from backend.db.models import Role
    from backend.db.session import Database

    images = tmp / "images"
    images.mkdir()
    cv2.imwrite(str(images / "0.png"), np.full((480, 640, 3), 90, np.uint8))
    port = _free_port()
    url = f"sqlite+aiosqlite:///{tmp / 'edge.db'}"
    secret = "bench-secret-0123456789abcdef"
    upgrade(url)

    async def token() -> str:
        db = Database(url)
        try:
            async with db.session() as s:
                _, tok = await create_user(s, "edge-bench", Role.engineer, secret)
        finally:
            await db.dispose()
        return str(tok)

    tok = asyncio.run(token())
    env = {
        **os.environ, "VISIONCELL_DATABASE_URL": url, "VISIONCELL_VAR_DIR": str(tmp / "var"),
        "VISIONCELL_HTTP_PORT": str(port), "VISIONCELL_VISER_PORT": str(_free_port()),
        "VISIONCELL_VIEW3D_ENABLED": "false", "VISIONCELL_SECRET_KEY": secret,
        "VISIONCELL_DRIVER": "ideal", "VISIONCELL_CAMERA": "folder",
        "VISIONCELL_CAMERA_FOLDER": str(images), "VISIONCELL_BOOTSTRAP_OPERATOR": "false",
        "VISIONCELL_LOG_LEVEL": "warning",
    }  # fmt: skip
    log = (tmp / "serve.log").open("w")
    proc = subprocess.Popen(
        [sys.executable, "-m", "backend.cli", "serve"],
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    return proc, port, tok, log


def run(
    seconds: float = 20.0,
    *,
    interval_s: float = 0.02,
    images: int = 3,
    clients: tuple[str, ...] = CLIENTS,
) -> dict[str, Any]:
    """Both phases against a fresh ``visioncell serve`` child (module docstring)."""
    import httpx

    if not 5 <= seconds <= 600:
        raise ValueError(f"seconds must be within 5..600, got {seconds!r}")
    if not 0.005 <= interval_s <= 1.0:
        raise ValueError(f"interval_s must be within 0.005..1, got {interval_s!r}")
    if not clients or any(c not in CLIENTS for c in clients):
        raise ValueError(f"clients must be some of {', '.join(CLIENTS)}, got {clients!r}")
    if not 1 <= images <= 5:
        raise ValueError(f"images must be within 1..5 (the 64 MP budget), got {images!r}")
    tmp = Path(tempfile.mkdtemp(prefix="bench-edge-"))
    proc, port, token, log = _serve(tmp)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 300
        while True:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"visioncell serve did not start: {tmp / 'serve.log'}")
            try:
                if httpx.get(f"{base}/api/health", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            time.sleep(0.3)
        r = httpx.post(f"{base}/api/models", json={"name": "bench-part", "kind": "2d"},
                       headers={"Authorization": f"Bearer {token}"}, timeout=TIMEOUT_S)  # fmt: skip
        r.raise_for_status()
        auth = {"Authorization": f"Bearer {token}"}
        board = {"type": "chessboard", "cols": 9, "rows": 6, "square_mm": 30}
        c = httpx.post(f"{base}/api/calibration/sessions", headers=auth, timeout=TIMEOUT_S,
                       json={"kind": "intrinsic", "board": board})  # fmt: skip
        c.raise_for_status()
        load = {"token": token, "model": r.json()["id"], "session": c.json()["session"]["id"],
                "images": images, "clients": clients}  # fmt: skip
        err.print("[edge] baseline ...")
        base_res = asyncio.run(_phase(base, port, seconds, interval_s, None))
        base_res["peak_rss_mb"] = _peak_rss_mb(proc.pid)
        err.print("[edge] under load ...")
        load_res = asyncio.run(_phase(base, port, seconds, interval_s, load))
        load_res["peak_rss_mb"] = _peak_rss_mb(proc.pid)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()
    p99 = load_res["health"]["p99_ms"]
    return {
        "seconds": seconds, "interval_s": interval_s, "images_per_upload": images,
        "body_bytes": BODY_BYTES, "clients": list(clients), "baseline": base_res, "load": load_res,
        "target_p99_ms": TARGET_P99_MS, "meets_target": p99 is not None and p99 <= TARGET_P99_MS,
    }  # fmt: skip


def _f(v: float | None, fmt: str = "{:.1f}") -> str:
    return "-" if v is None else fmt.format(v)


def _print(res: dict[str, Any]) -> None:
    t = Table(title=f"GET /api/health every {res['interval_s'] * 1e3:.0f} ms for {res['seconds']:g} s "
                    f"(target p99 <= {res['target_p99_ms']:.0f} ms under load)")  # fmt: skip
    for col in ("phase", "probes", "errors", "p50 ms", "p99 ms", "max ms", "peak RSS MB"):
        t.add_column(col, justify="right" if col != "phase" else "left")
    for name in ("baseline", "load"):
        h = res[name]["health"]
        t.add_row(
            "no load" if name == "baseline" else " + ".join(res["clients"]),
            str(h["n"]), str(h["errors"]), _f(h["p50_ms"]), _f(h["p99_ms"]), _f(h["max_ms"]),
            _f(res[name]["peak_rss_mb"], "{:.0f}"),
        )  # fmt: skip
    out.print(t)
    a = Table(title="What the abusive clients got")
    for col in ("client", "answers", "median time to answer s"):
        a.add_column(col)
    for name in CLIENTS:
        if name not in res["load"]:
            continue
        c = res["load"][name]
        a.add_row(name, ", ".join(f"{k}: {v}" for k, v in sorted(c["codes"].items())),
                  _f(c["answer_median_s"], "{:.3f}"))  # fmt: skip
    out.print(a)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="length of each phase, 5..600 s")
    ap.add_argument("--interval", type=float, default=0.02, help="s between health probes")
    ap.add_argument("--images", type=int, default=3, help="12-MP images per upload, 1..5")
    ap.add_argument("--only", choices=CLIENTS, help="run one of the abusive clients only")
    ap.add_argument("--json", action="store_true", help="print one JSON object last")
    ap.add_argument("--abuse", help=argparse.SUPPRESS)  # the child running the clients
    args = ap.parse_args(argv)
    if args.abuse:
        spec = json.loads(args.abuse)
        got = asyncio.run(_abuse(int(spec["port"]), float(spec["seconds"]), str(spec["token"]),
                                 {"model": int(spec["model"]), "session": int(spec["session"])},
                                 int(spec["images"]),
                                 [c for c in spec["clients"] if c in CLIENTS]))  # fmt: skip
        print(json.dumps(got))
        return
    res = run(args.seconds, interval_s=args.interval, images=args.images,
              clients=(args.only,) if args.only else CLIENTS)  # fmt: skip
    _print(res)
    if args.json:
        print(json.dumps(res))


if __name__ == "__main__":
    main()
