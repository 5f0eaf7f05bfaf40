"""Property tests: the parser survives any byte stream and accepts only checksummed frames."""

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robot.drivers.serial import frames as fr
from robot.drivers.serial.framing import LineReader, crc16_ccitt

SETTINGS = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])

angles = st.floats(-3.0, 3.0, allow_nan=False)
vec = st.tuples(angles, angles, angles, angles, angles).map(
    lambda v: tuple(float(fr.fmt(x)) for x in v)
)
seq = st.integers(0, 2**31 - 1)
valid_frames = st.one_of(
    st.builds(fr.Ping, seq),
    st.builds(fr.Run, seq, st.integers(0, 10**6)),
    st.builds(fr.TrajBegin, seq, st.integers(0, 10**6), st.integers(1, 10**4)),
    st.builds(
        fr.TrajPoint,
        seq,
        st.integers(0, 10**6),
        st.integers(0, 10**4),
        st.floats(0, 100).map(lambda t: float(fr.fmt(t))),
        vec,
        vec,
    ),
    st.builds(fr.Nak, seq, st.sampled_from(sorted(fr.NAK_CODES)), st.text(max_size=30)),
    st.builds(fr.Ack, seq, st.sampled_from(["PING", "STOP"]), st.just(("1",))),
)


def _checksum_ok(line: bytes) -> bool:
    line = line[:-1] if line.endswith(b"\r") else line
    body, digits = line[:-5], line[-4:]
    return line[-5:-4] == b"*" and digits == b"%04X" % crc16_ccitt(body)


@SETTINGS
@given(st.binary(max_size=2000), st.lists(st.integers(1, 64), max_size=20))
def test_random_bytes_never_crash_and_never_yield_unchecked_frames(data, cuts):
    parser = fr.FrameParser()
    lines = LineReader()
    got, seen_lines, i = [], [], 0
    for n in [*cuts, len(data)]:  # arbitrary chunking
        chunk, i = data[i : i + n], i + n
        got += parser.feed(chunk)
        seen_lines += lines.feed(chunk)
    accepted = [ln for ln in seen_lines if _try(ln)]
    assert len(got) == len(accepted)
    assert all(_checksum_ok(ln) for ln in accepted)
    assert parser.accepted + parser.rejected == len(seen_lines)


def _try(line: bytes) -> bool:
    try:
        fr.decode(line)
    except fr.ProtocolError:
        return False
    return True


@SETTINGS
@given(st.lists(st.tuples(valid_frames, st.binary(max_size=80)), min_size=1, max_size=8), st.data())
def test_valid_frames_survive_garbage_between_them(items, data):
    stream = bytearray()
    for frame, garbage in items:
        stream += garbage.replace(b"\n", b"") + b"\n"  # noise ended by a LF, then a frame
        stream += fr.encode(frame)
    parser = fr.FrameParser()
    cut = data.draw(st.integers(0, len(stream)))
    got = parser.feed(bytes(stream[:cut])) + parser.feed(bytes(stream[cut:]))
    expected = [frame for frame, _ in items]
    it = iter(got)
    assert all(any(g == e for g in it) for e in expected)  # every frame, in order


@SETTINGS
@given(valid_frames, st.data())
def test_any_single_byte_change_of_a_frame_is_rejected(frame, data):
    wire = fr.encode(frame)
    pos = data.draw(st.integers(0, len(wire) - 2))  # any byte but the terminating LF
    new = data.draw(st.integers(0, 255).filter(lambda b: b != wire[pos]))
    mutated = wire[:pos] + bytes([new]) + wire[pos + 1 :]
    assert fr.FrameParser().feed(mutated) == []


@SETTINGS
@given(valid_frames)
def test_valid_frames_decode_to_themselves(frame):
    assert fr.FrameParser().feed(fr.encode(frame)) == [frame]
