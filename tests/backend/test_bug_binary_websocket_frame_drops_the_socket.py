"""``/api/ws`` speaks JSON text: a binary first frame is closed with 1003 (unsupported data)
and a reason, never an unhandled error that drops the socket without a close code; binary
frames after the sign-in are ignored and the stream goes on."""

from __future__ import annotations

import json
import logging


def test_a_binary_first_frame_is_closed_with_1003(client, caplog) -> None:
    caplog.set_level(logging.ERROR)
    with client.websocket_connect("/api/ws") as ws:
        ws.send_bytes(json.dumps({"token": "vc_x"}).encode())
        msg = ws.receive()
        assert msg["type"] == "websocket.close", msg
        assert msg["code"] == 1003 and "text frame" in msg["reason"], msg
    assert not [r for r in caplog.records if "KeyError" in r.getMessage()]


def test_binary_frames_after_the_sign_in_are_ignored(client, tokens, headers) -> None:
    with client.websocket_connect("/api/ws") as ws:
        ws.send_json({"token": tokens["viewer"]})
        assert ws.receive_json()["type"] == "hello"
        ws.send_bytes(b"\x00\x01")
        ws.send_text("not json")
        kinds = {ws.receive_json()["type"] for _ in range(2)}
        assert kinds == {"state", "camera"}
        # Still streaming after the stray frames: a job started now is reported.
        q = client.get("/api/robot/state", headers=headers["viewer"]).json()["state"]["q"]
        r = client.post("/api/robot/move", json={"joints": q, "speed": 1.0},
                        headers=headers["operator"])  # fmt: skip
        assert r.status_code == 202, r.text
        for _ in range(200):
            msg = ws.receive_json()
            if msg["type"] == "job":
                break
        assert msg["type"] == "job" and msg["job"]["kind"] == "move", msg
