"""The console's WebSocket and ``visioncell estop`` stop the cell during a database outage
too: an open socket's ``{"type": "estop"}`` latches at once and every socket gets the
``estop`` message; the socket survives the outage (its token re-check cannot reach the
database), and a token seen valid may open one meanwhile; the CLI's E-STOP (through REST)
latches on a real server whose database hangs."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient
from typer.testing import CliRunner

from backend.api.deps import runtime_of
from backend.api.routes import live
from backend.app import create_app
from backend.cli import app as cli_app
from benchmarks.outage import DatabaseOutage
from tests.utils.servers import run_uvicorn

#: Messages read at most while waiting for one (bounds a hang only).
MAX_MESSAGES = 500


def _until_estop(ws: Any) -> dict[str, Any]:
    for _ in range(MAX_MESSAGES):
        msg = ws.receive_json()
        if msg["type"] == "estop":
            return msg
    raise AssertionError("no estop message")


def test_websocket_estop_during_an_outage(settings, tokens, monkeypatch):
    monkeypatch.setattr(live, "RECHECK_S", 0.0)  # re-check the token on every turn
    with TestClient(create_app(settings)) as c:
        rt = runtime_of(c.app)
        with c.websocket_connect("/api/ws") as ws, c.websocket_connect("/api/ws") as other:
            for sock, role in ((ws, "viewer"), (other, "engineer")):
                sock.send_json({"token": tokens[role]})
                assert sock.receive_json()["type"] == "hello"
            with DatabaseOutage(rt.database, mode="fail") as outage:
                ws.send_text("x" * (live.MAX_CLIENT_MESSAGE + 1))  # ignored
                ws.send_json({"type": "something else"})  # ignored
                ws.send_json({"type": "estop"})
                for sock in (ws, other):
                    msg = _until_estop(sock)
                    assert msg["active"] is True and msg["arm_latched"] is True
                    assert msg["by"] == "test-viewer" and msg["source"] == "ws"
                assert rt.cell.driver.state.estopped
                assert outage.hit >= 1  # the re-checks and the audit writer met the outage
                # a token seen valid still opens a socket while the database is away
                with c.websocket_connect("/api/ws") as late:
                    late.send_json({"token": tokens["operator"]})
                    assert late.receive_json()["type"] == "hello"
                with c.websocket_connect("/api/ws") as unknown:
                    unknown.send_json({"token": "vc_never-seen"})
                    closed = unknown.receive()
                    assert closed["type"] == "websocket.close" and closed["code"] == 1013


def test_cli_estop_during_a_hanging_database(settings, tokens):
    runner = CliRunner()
    with run_uvicorn(create_app(settings)) as srv:
        rt = runtime_of(srv.app)
        with DatabaseOutage(rt.database, mode="block"):
            res = runner.invoke(
                cli_app,
                ["estop", "--url", srv.base, "--token", tokens["viewer"], "--timeout", "30"],
            )
            assert res.exit_code == 0, res.output
            assert "E-STOP latched: estopped=True" in res.output
            assert rt.cell.driver.state.estopped
        bad = runner.invoke(cli_app, ["estop", "--url", srv.base, "--token", "vc_wrong"])
        assert bad.exit_code == 1 and "HTTP 401" in bad.output
        for args in (["--timeout", "0"], ["--timeout", "nan"], ["--url", "ftp://x"]):
            res = runner.invoke(cli_app, ["estop", "--token", "vc_x", *args])
            assert res.exit_code == 2, (args, res.output)
