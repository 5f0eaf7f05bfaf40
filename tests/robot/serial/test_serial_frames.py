import pytest

from robot.drivers.serial import frames as fr
from robot.errors import ProtocolError

Q = (0.0, 1.570796, -1.570796, -0.5, 3.1)
QD = (0.1, -0.2, 0.0, 1.25, -3.0)
SNAP = fr.ArmSnapshot(1234, Q, QD, True, False, 7, "RUNNING", "")
OUT = fr.MoveOutcome(7, "DONE", 1.25, Q, 1e-6, "done fine")

FRAMES = [
    fr.Hello(1, "0A1B2C3D"),
    fr.Ping(2),
    fr.GetState(3),
    fr.GetLimits(4),
    fr.SetRate(5, 100.0),
    fr.MoveJoints(6, 9, Q, duration_s=2.5),
    fr.MoveJoints(7, 10, Q, speed=0.5),
    fr.TrajBegin(8, 11, 300),
    fr.TrajPoint(9, 11, 299, 2.99, Q, QD),
    fr.Run(10, 11),
    fr.QueryMove(11, 11),
    fr.Stop(12),
    fr.EStop(13),
    fr.Reset(14),
    fr.Ack(15, "PING", ("42",)),
    fr.Nak(16, "BUSY", "move 3 is executing"),
    fr.StateEvent(17, SNAP),
    fr.DoneEvent(18, OUT),
]


@pytest.mark.parametrize("frame", FRAMES, ids=lambda f: type(f).__name__)
def test_every_frame_round_trips(frame):
    wire = fr.encode(frame)
    assert wire.endswith(b"\n") and len(wire) <= fr.MAX_LINE_BYTES + 1
    assert fr.decode(wire[:-1]) == frame


@pytest.mark.parametrize(
    "payload",
    [
        SNAP,
        fr.ArmSnapshot(5, Q, QD, False, True, 0, "NONE", "servo 3 overheated"),
        OUT,
        fr.HelloInfo(1, "DEADBEEF", True, 64, 8, 10000, 50.0, "emu"),
        fr.LimitsInfo(Q, Q, QD),
    ],
    ids=lambda p: type(p).__name__,
)
def test_payloads_round_trip(payload):
    assert type(payload).from_args(payload.to_args()) == payload


def test_numbers_use_six_decimals_and_no_negative_zero():
    assert fr.fmt(-0.0) == "0" and fr.fmt(-1e-9) == "0"
    assert fr.fmt(1.5707963267948966) == "1.570796"
    assert fr.fmt(2.0) == "2"


def test_nak_detail_is_made_safe_and_codes_are_checked():
    n = fr.Nak(3, "LIMIT", "q2 * 2\tout\nof range")
    assert n.detail == "q2 # 2 out of range"
    assert fr.decode(fr.encode(n)[:-1]) == n
    with pytest.raises(ValueError, match="code"):
        fr.Nak(3, "NOPE")


@pytest.mark.parametrize(
    ("body", "seq"),
    [
        ("C 5 JUMP", 5),
        ("C 6 MOVE 1 0 0 0 0 0 X 1", 6),
        ("C 7 TP 1 2 0 0 0 0 0", 7),
        ("C 8 RATE nan", 8),
        ("C 9 HELLO 0a1b2c3d 1", 9),
        ("A 10 ping", None),
        ("E 11 ST 1 2", None),
        ("Q 12 PING", None),
        ("C x PING", None),
        ("C  13 PING", None),
    ],
)
def test_grammar_errors_raise_protocol_error_with_the_command_seq(body, seq):
    with pytest.raises(ProtocolError) as err:
        fr.decode_body(body)
    assert err.value.seq == seq


def test_move_needs_exactly_one_of_duration_and_speed():
    with pytest.raises(ValueError, match="exactly one"):
        fr.encode(fr.MoveJoints(1, 1, Q))


def test_every_nak_code_is_documented():
    from pathlib import Path

    doc = (Path(__file__).parents[3] / "docs" / "serial-protocol.md").read_text()
    for code in fr.NAK_CODES:
        assert f"`{code}`" in doc, code
    for status in fr.MOVE_STATUSES:
        assert f"`{status}`" in doc, status


def test_example_exchanges_in_the_protocol_document_are_valid_frames():
    import re
    from pathlib import Path

    doc = (Path(__file__).parents[3] / "docs" / "serial-protocol.md").read_text()
    lines = re.findall(r"^[<>] ([CANE] \d+ [^*\n]*\*[0-9A-F]{4})", doc, flags=re.MULTILINE)
    assert len(lines) > 30
    for line in lines:
        frame = fr.decode(line.encode())
        assert fr.encode(frame) == line.encode() + b"\n", line
