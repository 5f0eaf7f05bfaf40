"""No token or secret reaches the logs: sign-in failures, token creation, requests."""

from __future__ import annotations

import logging

import pytest

from backend.logredact import REDACTED, RedactSecrets, install_redaction, redact
from tests.utils.factories import TEST_SECRET


def test_redact_covers_tokens_links_and_bearer_values():
    text = (
        "GET /x?token=vc_abcdefghijklmnopqrstuvwxyz0123456789ABCDEFG HTTP/1.1 "
        "Authorization: Bearer whatever-secret "
        "ws /vc-link/v1.3.2.operator.1893456000.abcdefghijklmnopqrstuvwxyz0123456789ABCDEFG"
    )
    out = redact(text)
    assert "vc_abc" not in out and "whatever-secret" not in out and "v1.3.2" not in out
    assert out.count(REDACTED) >= 3


def test_records_are_rewritten_args_too():
    record = logging.LogRecord("uvicorn.access", logging.INFO, __file__, 1,
                               '%s - "%s %s"', ("1.2.3.4", "GET", "/api?token=vc_0123456789abcdef"),
                               None)  # fmt: skip
    RedactSecrets().filter(record)
    assert "vc_0123456789" not in record.getMessage()


def test_no_token_in_logs_during_sign_in_failures_creation_and_requests(client, headers, caplog):
    caplog.set_level(logging.DEBUG)
    install_redaction()
    caplog.handler.addFilter(RedactSecrets())  # as serve does on its own handlers
    bad = "vc_" + "x" * 43
    for _ in range(3):
        client.get("/api/users/me", headers={"Authorization": f"Bearer {bad}"})
    r = client.post("/api/users", json={"name": "lena", "role": "viewer"},
                    headers=headers["engineer"])  # fmt: skip
    new = r.json()["token"]
    client.get("/api/users/me", headers={"Authorization": f"Bearer {new}"})
    client.get(f"/api/health?token={new}")
    with client.websocket_connect("/api/ws") as ws:
        ws.send_json({"token": new})
        ws.receive_json()
    text = "\n".join(r.getMessage() for r in caplog.records)
    assert text  # something was logged
    for secret in (bad, new, TEST_SECRET, *[v["Authorization"][7:] for v in headers.values()]):
        assert secret not in text


@pytest.mark.e2e
def test_serve_log_has_the_banner_token_only_on_stdout(tmp_path):
    """The operator token appears once (the banner) and no request puts a token in the log."""
    import httpx

    from tests.e2e.conftest import start_server

    server = start_server(tmp_path, VISIONCELL_LOG_LEVEL="debug")
    try:
        token = server.token("logcheck", "viewer")
        httpx.get(f"{server.base}/api/users/me?token={token}",
                  headers={"Authorization": f"Bearer {token}"}, timeout=10)  # fmt: skip
        httpx.get(f"{server.base}/api/users/me", headers={"Authorization": "Bearer vc_bad_one"},
                  timeout=10)  # fmt: skip
    finally:
        server.stop()
    log = server.log.read_text()
    assert token not in log
    assert "GET /api/users/me" in log  # the access log is there, redacted
    banner_tokens = [line for line in log.splitlines() if line.strip().startswith("vc_")]
    assert len(banner_tokens) == 1  # the start-up banner, printed on purpose
