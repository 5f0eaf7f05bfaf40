"""The PLC links' settings are bounded and validated, and off by default; the Modbus words
round-trip through the encoder and the simulated PLC's decoder."""

from __future__ import annotations

import math

import pytest
from pydantic import ValidationError

from backend.plc.handshake import ErrorCode, PlcResult, Snapshot, SystemState
from backend.plc.modbus import N_REGISTERS, STATUS_AT, STATUS_BITS, decode_result, encode
from backend.settings import Settings


def test_links_are_off_by_default() -> None:
    s = Settings()
    assert s.opcua_endpoint is None and s.modbus_port is None
    assert s.modbus_host == "127.0.0.1" and s.modbus_role == "operator"
    assert s.opcua_anonymous == "off"


@pytest.mark.parametrize(
    "endpoint",
    ["http://127.0.0.1:4840", "opc.tcp://127.0.0.1", "opc.tcp://127.0.0.1:0",
     "opc.tcp://127.0.0.1:65536", "opc.tcp://plc.example.com:4840", "opc.tcp://127.0.0.1:4840/a b",
     "opc.tcp://127.0.0.1:4840/" + "x" * 300, "opc.tcp://127.0.0.1:4840/\x00"],
)  # fmt: skip
def test_bad_opcua_endpoints_are_refused(endpoint: str) -> None:
    with pytest.raises(ValidationError, match="opcua_endpoint"):
        Settings(opcua_endpoint=endpoint)


def test_good_opcua_endpoints() -> None:
    for url in ("opc.tcp://127.0.0.1:4840/visioncell", "opc.tcp://localhost:48400",
                "opc.tcp://[::1]:4840"):  # fmt: skip
        assert Settings(opcua_endpoint=url).opcua_endpoint == url


@pytest.mark.parametrize(
    "field, value",
    [("modbus_port", 0), ("modbus_port", 70000), ("modbus_host", "plc.example.com"),
     ("modbus_role", "admin"), ("plc_result_queue", 0), ("plc_result_queue", 1001),
     ("opcua_anonymous", "read-write")],
)  # fmt: skip
def test_bad_link_settings_are_refused(field: str, value: object) -> None:
    with pytest.raises(ValidationError, match=field):
        Settings(**{field: value})


def test_certificate_sign_in_needs_an_encrypting_policy(tmp_path) -> None:
    with pytest.raises(ValidationError, match="opcua_user_certificates"):
        Settings(opcua_user_certificates=tmp_path, opcua_security="none")
    assert Settings(opcua_user_certificates=tmp_path).opcua_security == "both"


def test_a_link_off_loopback_needs_a_private_secret() -> None:
    with pytest.raises(ValidationError, match="SECRET_KEY"):
        Settings(modbus_port=5020, modbus_host="0.0.0.0")
    with pytest.raises(ValidationError, match="SECRET_KEY"):
        Settings(opcua_endpoint="opc.tcp://10.1.2.3:4840")
    s = Settings(
        modbus_port=5020, modbus_host="0.0.0.0", secret_key="a-private-secret-of-the-plant"
    )
    assert s.modbus_host == "0.0.0.0"


def _snap(result: PlcResult | None) -> Snapshot:
    return Snapshot(state=SystemState.READY, trigger_enabled=True, trigger_ready=False,
                    trigger_ack=True, busy=False, results_valid=result is not None, running=False,
                    estop=False, error=ErrorCode.RESULT_NOT_ACKNOWLEDGED, error_text="",
                    recipe=7, triggers=70000, result=result, queued=2, overflows=0)  # fmt: skip


def test_modbus_words_round_trip() -> None:
    res = PlcResult(inspection_id=123456789, decision="recognized", model="obj2", model_id=2,
                    score=0.4567, x_m=0.81234, y_m=-0.10001, yaw_rad=math.radians(-179.5),
                    bin=3, bin_name="b", duration_s=1.2345, trigger=65537)  # fmt: skip
    words = encode(_snap(res))
    assert len(words) == N_REGISTERS - STATUS_AT and all(0 <= w <= 0xFFFF for w in words)
    d = decode_result(words)
    assert d["inspection_id"] == 123456789 and d["decision"] == 1 and d["model_id"] == 2
    assert d["x_m"] == pytest.approx(0.81234, abs=1e-7) and d["y_m"] == pytest.approx(
        -0.10001, abs=1e-7
    )
    assert math.degrees(d["yaw_rad"]) == pytest.approx(-179.5, abs=0.01)
    assert (d["score"] == 0.457 and d["duration_s"] == 1.234) or d["duration_s"] == 1.235
    assert d["triggers"] == 70000 % 65536 and d["result_trigger"] == 1 and d["queued"] == 2
    assert d["error"] == ErrorCode.RESULT_NOT_ACKNOWLEDGED and d["recipe"] == 7
    flags = {k for k, b in STATUS_BITS.items() if d["status"] >> b & 1}
    assert flags == {"ONLINE", "TRIGGER_ACK", "RESULTS_VALID", "ERROR", "TRIGGER_ENABLED"}


def test_modbus_words_without_a_pose_or_result() -> None:
    res = PlcResult(inspection_id=5, decision="unknown", model=None, model_id=0, score=None,
                    x_m=None, y_m=None, yaw_rad=None, bin=0, bin_name=None, duration_s=99.0,
                    trigger=0)  # fmt: skip
    d = decode_result(encode(_snap(res)))
    assert d["x_m"] is None and d["y_m"] is None and d["yaw_rad"] is None
    assert d["decision"] == 2 and d["duration_s"] == 65.535  # saturates
    d = decode_result(encode(_snap(None)))
    assert d["inspection_id"] == 0 and d["decision"] == 0 and d["x_m"] is None
