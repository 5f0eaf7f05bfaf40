import pytest

from robot.drivers.serial.framing import MAX_LINE_BYTES, LineReader, crc16_ccitt, seal, unseal
from robot.errors import ProtocolError


def test_crc16_ccitt_false_check_value():
    # The catalogue check value of CRC-16/CCITT-FALSE (CRC-16/IBM-3740) for "123456789".
    assert crc16_ccitt(b"123456789") == 0x29B1
    assert crc16_ccitt(b"") == 0xFFFF


def test_seal_then_unseal_round_trip_and_crlf():
    wire = seal("C 1 PING")
    assert wire == b"C 1 PING*%04X\n" % crc16_ccitt(b"C 1 PING")
    assert unseal(wire[:-1]) == "C 1 PING"
    assert unseal(wire[:-1] + b"\r") == "C 1 PING"


@pytest.mark.parametrize("body", ["", "C 1 *PING", "C 1 P\tING", "C 1 PÏNG", "x" * MAX_LINE_BYTES])
def test_seal_refuses_bodies_that_could_not_travel(body):
    with pytest.raises(ValueError, match="body"):
        seal(body)


@pytest.mark.parametrize(
    ("line", "why"),
    [
        (b"C 1 PING", "trailer"),
        (b"C 1 PING*29b1", "upper-case hex"),
        (b"C 1 PING*0000", "mismatch"),
        (b"C 1 P\x00NG*0000", "printable"),
        (b"*", "trailer"),
    ],
)
def test_unseal_rejects_bad_lines(line, why):
    with pytest.raises(ProtocolError, match=why):
        unseal(line)


def test_lowercase_checksum_of_a_valid_frame_is_rejected():
    wire = seal("A 12 PING 3")
    crc = wire[-5:-1]
    if crc.upper() != crc.lower():
        with pytest.raises(ProtocolError):
            unseal(wire[:-5] + crc.lower())


def test_line_reader_joins_partial_lines_and_drops_empty_ones():
    r = LineReader()
    assert r.feed(b"C 1 PI") == []
    assert r.feed(b"NG*ABCD\n\n\r\nC 2") == [b"C 1 PING*ABCD"]
    assert r.feed(b" STOP*0000\r\n") == [b"C 2 STOP*0000\r"]


def test_line_reader_discards_overlong_lines_and_recovers():
    r = LineReader(max_line_bytes=16)
    assert r.feed(b"x" * 40) == []  # no LF yet: dropped, not buffered
    assert r.overlong == 1
    assert r.feed(b"y" * 40 + b"\nok line\n") == [b"ok line"]
    assert r.feed(b"z" * 17 + b"\nshort\n") == [b"short"]
    assert r.overlong == 2
