"""Bug: a request line over about 100 KB got a text/plain 400 from the HTTP parser, not the
JSON error body.  Checked against a real uvicorn server (the parser is not in TestClient)
started with the options ``visioncell serve`` uses."""

from __future__ import annotations

import contextlib
import json
import socket
from collections.abc import Iterator

import httpx
import pytest

from backend.api.limits import MAX_URL_BYTES
from backend.app import create_app
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.servers import run_uvicorn


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[tuple[str, dict[str, str]]]:
    tmp = tmp_path_factory.mktemp("long-url")
    settings = make_settings(tmp)
    migrate(settings)
    token = make_tokens(settings)["viewer"]
    with run_uvicorn(create_app(settings)) as srv:
        yield srv.base, {"Authorization": f"Bearer {token}"}


def _raw(base: str, request: bytes) -> tuple[int, dict[str, str], bytes]:
    """Send raw bytes (any length) and read the whole answer."""
    host, port = base.removeprefix("http://").split(":")
    with socket.create_connection((host, int(port)), timeout=20) as s:
        # The server may answer and close before it has read everything we send.
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):
            s.sendall(request)
        chunks = []
        while True:
            try:
                chunk = s.recv(65536)
            except ConnectionResetError:
                break
            if not chunk:
                break
            chunks.append(chunk)
    data = b"".join(chunks)
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split()[1])
    headers = {k.lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:])}
    return status, headers, body


@pytest.mark.parametrize("n", [MAX_URL_BYTES + 1, 60_000, 100_000, 200_000])
def test_long_url_is_a_json_414(server, n):
    base, hdr = server
    status, headers, body = _raw(
        base,
        b"GET /api/health?q="
        + b"a" * n
        + b" HTTP/1.1\r\nHost: x\r\n"
        + f"Authorization: {hdr['Authorization']}\r\n\r\n".encode(),
    )
    assert status == 414, body[:200]
    assert headers["content-type"] == "application/json"
    answer = json.loads(body)
    assert answer["error"] == "uri_too_long" and str(MAX_URL_BYTES) in answer["detail"]


@pytest.mark.parametrize("n", [1_000_000, 4_000_000])
def test_huge_request_line_is_json_whatever_refuses_it(server, n):
    base, _ = server
    status, headers, body = _raw(
        base, b"GET /api/health?q=" + b"a" * n + b" HTTP/1.1\r\nHost: x\r\n\r\n"
    )
    assert status in (400, 414)
    assert headers["content-type"] == "application/json"
    assert set(json.loads(body)) == {"error", "detail"}


def test_malformed_request_is_json(server):
    base, _ = server
    status, headers, body = _raw(base, b"GARBAGE\x00\x01 / HTTP/1.1\r\n\r\n")
    assert status == 400 and headers["content-type"] == "application/json"
    assert b'"bad_request"' in body


def test_normal_requests_still_work(server):
    base, hdr = server
    r = httpx.get(f"{base}/api/health?q={'a' * 1000}", timeout=20)
    assert r.status_code == 200 and r.json()["status"] == "ok"
    r = httpx.get(f"{base}/api/calibration/sessions/{2**63}", headers=hdr, timeout=20)
    assert r.status_code == 422 and r.json()["error"] == "validation_error"
