"""A request without a valid token was read and parsed before its 401 (a 100 MB JSON body
held the loop for seconds; random bytes got 400, not 401), and no body had a size limit.

Each request here is driven at the ASGI level with a body that is counted as the app reads
it, often one that never ends: the answer has to come without reading it.
"""

from __future__ import annotations

import itertools
import os
import socket

import httpx
import pytest
from fastapi.testclient import TestClient

from backend.api.edge import BodyGuard
from backend.app import create_app
from backend.settings import Settings
from tests.utils.asgi import exchange
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.servers import run_uvicorn

CHUNK = 64 * 1024
MOVE = "/api/robot/move"


def endless(chunk: bytes = b"x" * CHUNK) -> itertools.repeat[bytes]:
    """A body that never ends."""
    return itertools.repeat(chunk)


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("edge")
    settings = make_settings(tmp)
    migrate(settings)
    tokens = make_tokens(settings)
    app = create_app(settings)
    with TestClient(app) as client:
        yield app, client, tokens


def run(served, method, path, **kw):
    app, client, _ = served
    return client.portal.call(lambda: exchange(app, method, path, **kw))


def bearer(served, role: str) -> dict[str, str]:
    return {"authorization": f"Bearer {served[2][role]}"}


def assert_json_error(ex, status: int, code: str) -> None:
    assert ex.status == status, (ex.status, ex.body)
    assert ex.headers["content-type"] == "application/json"
    body = ex.json()
    assert set(body) == {"error", "detail"} and body["error"] == code, body


@pytest.mark.parametrize(
    "headers",
    [
        {"content-type": "application/json", "content-length": str(100 << 20)},
        {"content-type": "application/json", "transfer-encoding": "chunked"},
        # random bytes, no type: was 400 (a body parse error) before the token was looked at
        {"content-length": str(200 << 20)},
    ],
    ids=["100MB-json", "chunked", "200MB-random"],
)
def test_no_token_is_401_before_a_byte_of_the_body_is_read(served, headers):
    ex = run(served, "POST", MOVE, headers=headers, chunks=endless(os.urandom(CHUNK)))
    assert_json_error(ex, 401, "unauthorized")
    assert ex.headers["www-authenticate"] == "Bearer"
    assert ex.reads == 0 and ex.bytes_read == 0


def test_a_bad_token_is_401_and_a_weaker_role_403_before_the_body(served):
    bad = {"authorization": "Bearer vc_not-a-token", "content-type": "application/json",
           "transfer-encoding": "chunked"}  # fmt: skip
    ex = run(served, "POST", MOVE, headers=bad, chunks=endless())
    assert_json_error(ex, 401, "unauthorized")
    assert ex.bytes_read == 0
    viewer = {**bearer(served, "viewer"), "content-type": "application/json",
              "transfer-encoding": "chunked"}  # fmt: skip
    ex = run(served, "POST", MOVE, headers=viewer, chunks=endless())
    assert_json_error(ex, 403, "forbidden")
    assert ex.bytes_read == 0


def test_an_upload_without_a_token_is_401_before_the_body(served):
    headers = {"content-type": "multipart/form-data; boundary=xyz", "content-length": str(40 << 20)}
    ex = run(served, "POST", "/api/models/1/views", headers=headers, chunks=endless())
    assert_json_error(ex, 401, "unauthorized")
    assert ex.bytes_read == 0


def test_a_declared_length_over_the_limit_is_413_before_the_body(served):
    headers = {**bearer(served, "operator"), "content-type": "application/json",
               "content-length": str((1 << 20) + 1)}  # fmt: skip
    ex = run(served, "POST", MOVE, headers=headers, chunks=endless())
    assert_json_error(ex, 413, "too_large")
    assert "1048576 bytes" in ex.json()["detail"]
    assert ex.bytes_read == 0


def test_a_streamed_body_is_cut_at_the_limit(served):
    headers = {**bearer(served, "operator"), "content-type": "application/json",
               "transfer-encoding": "chunked"}  # fmt: skip
    ex = run(served, "POST", MOVE, headers=headers, chunks=endless())
    assert_json_error(ex, 413, "too_large")
    # read up to the limit and one chunk more, never the rest
    assert (1 << 20) < ex.bytes_read <= (1 << 20) + CHUNK


def test_a_content_length_that_lies_is_refused(served):
    # declares 100 bytes, sends more: refused once the count passes the declared length
    headers = {**bearer(served, "operator"), "content-type": "application/json",
               "content-length": "100"}  # fmt: skip
    ex = run(served, "POST", MOVE, headers=headers, chunks=endless(b"x" * 60))
    assert_json_error(ex, 400, "bad_request")
    assert "Content-Length" in ex.json()["detail"] and ex.bytes_read == 120
    # a length that is not a number, or two that differ
    for bad in ("12abc", "-5"):
        ex = run(served, "POST", MOVE, headers={**headers, "content-length": bad},
                 chunks=[b"{}"])  # fmt: skip
        assert_json_error(ex, 400, "bad_request")
        assert ex.bytes_read == 0


def test_an_upload_route_takes_more_than_a_json_route(served):
    body = (
        b'--xyz\r\nContent-Disposition: form-data; name="images"; filename="a.png"\r\n'
        b"Content-Type: image/png\r\n\r\n" + b"x" * (2 << 20) + b"\r\n--xyz--\r\n"
    )
    headers = {**bearer(served, "engineer"), "content-type": "multipart/form-data; boundary=xyz",
               "content-length": str(len(body))}  # fmt: skip
    # over 2 MiB is over the JSON limit but within the upload limit: the whole body is
    # read (its file is no image: 415), not refused for its size
    ex = run(served, "POST", "/api/models/1/views", headers=headers,
             chunks=[body[i : i + CHUNK] for i in range(0, len(body), CHUNK)])  # fmt: skip
    assert_json_error(ex, 415, "unsupported_media_type")
    assert ex.bytes_read == len(body)
    over = {**headers, "content-length": str((64 << 20) + 1)}
    ex = run(served, "POST", "/api/models/1/views", headers=over, chunks=endless())
    assert_json_error(ex, 413, "too_large")
    assert ex.bytes_read == 0


def test_a_valid_small_body_still_works_and_signs_in_once(served, monkeypatch):
    from backend.api import deps

    calls = []
    real = deps.RoleCheck.sign_in

    async def counting(self, *a, **kw):
        calls.append(self.role)
        return await real(self, *a, **kw)

    monkeypatch.setattr(deps.RoleCheck, "sign_in", counting)
    _, client, _ = served
    r = client.post(MOVE, json={"joints": [0, 1.2, -1.5, 0, 0], "speed": 0.5},
                    headers=bearer(served, "operator"))  # fmt: skip
    assert r.status_code in (200, 202), r.text
    assert len(calls) == 1  # before the body only; the dependency reused that user


def test_routes_without_a_body_keep_their_path(served):
    # E-STOP takes no body: no sign-in ahead, and a body sent anyway is never read
    headers = {**bearer(served, "viewer"), "content-length": str(10 << 20)}
    ex = run(served, "POST", "/api/robot/estop", headers=headers, chunks=endless())
    assert ex.status == 200, ex.body
    assert ex.bytes_read == 0
    _, client, _ = served
    assert client.post("/api/robot/reset", headers=bearer(served, "operator")).status_code == 200
    assert client.get("/api/health").status_code == 200


def test_every_body_route_is_planned(served):
    app = served[0]
    guard = app.middleware_stack
    while guard is not None and not isinstance(guard, BodyGuard):
        guard = getattr(guard, "app", None)
    assert guard is not None
    plan = guard.plan("POST", MOVE)
    assert plan.reads_body and plan.check is not None and plan.limit == 1 << 20
    upload = guard.plan("POST", "/api/calibration/sessions/3/samples")
    assert upload.reads_body and upload.limit == 64 << 20 and upload.kind == "upload"
    assert not guard.plan("POST", "/api/robot/estop").reads_body
    assert not guard.plan("GET", "/api/health").reads_body


@pytest.mark.parametrize(
    ("name", "value"),
    [("max_json_body_bytes", 100), ("max_json_body_bytes", 1 << 30),
     ("max_upload_body_bytes", 10), ("max_request_pixels", 0), ("heavy_workers", 0),
     ("max_analysed_pixels", 10),
     ("heavy_jobs", 1000), ("heavy_admit_wait_s", float("inf")), ("heavy_admit_wait_s", -1)],
)  # fmt: skip
def test_the_edge_settings_are_bounded(name, value):
    with pytest.raises(ValueError, match=name):
        Settings(**{name: value})


def test_a_real_server_answers_401_before_the_body_arrives(tmp_path):
    """Over a socket to uvicorn: the head of a 100 MB POST without a token is answered at
    once, while the client has sent none of its body; the rest is then dropped unparsed
    and the connection closes (a bounded linger), and the server keeps answering."""
    settings = make_settings(tmp_path)
    migrate(settings)
    with run_uvicorn(create_app(settings)) as srv:
        port = int(srv.base.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port), timeout=60) as sock:
            sock.sendall(
                b"POST /api/robot/move HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                b"Content-Length: 100000000\r\n\r\n" + b'{"joints": [' + b"0," * 1000
            )
            answer = b""
            while b"\r\n\r\n" not in answer:
                piece = sock.recv(65536)
                assert piece, "closed before answering"
                answer += piece
            assert answer.startswith(b"HTTP/1.1 401 ")
            # the server drops what follows and ends the connection: recv sees the FIN
            while piece:
                piece = sock.recv(65536)
        assert httpx.get(f"{srv.base}/api/health", timeout=60).status_code == 200


def test_the_413_is_documented_on_every_route_that_takes_a_body(served):
    spec = served[0].openapi()
    ops = [(p, m, op) for p, item in spec["paths"].items() for m, op in item.items()]
    with_body = [(p, m, op) for p, m, op in ops if "requestBody" in op]
    assert len(with_body) >= 20
    for path, method, op in with_body:
        assert "413" in op["responses"] and "401" in op["responses"], (method, path)
    assert "413" in spec["paths"]["/api/models/{model_id}/views"]["post"]["responses"]
    assert (
        "67108864 bytes"
        in (
            spec["paths"]["/api/models/{model_id}/views"]["post"]["responses"]["413"]["description"]
        )
    )
    assert "413" not in spec["paths"]["/api/robot/estop"]["post"]["responses"]
