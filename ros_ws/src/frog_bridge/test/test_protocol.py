"""The serial codec both ways: exact lines, lenient relay parsing, typed errors, fuzz."""

import math

import numpy as np
import pytest

from frog_bridge.core.limbs import primitive_pairs
from frog_common.primitives import PRIMITIVE_NAMES
from frog_bridge.core.protocol import (
    Blank, DecodeError, Emergency, ErrorKind, Heat, LineFramer, Quaternion, RelayText, SetPulse,
    decode_command, decode_relay_line, encode_emergency, encode_heat, encode_quaternion,
    encode_set_pulse)

# Written out by hand from the bit table [FR, FL, BL, BR] and the authors' executor
# (front line lists FR before FL, rear line BL before BR; a pair with no bit sends nothing).
EXPECTED_LINES = {
    "A": [b"h 1 0\n"], "B": [b"h 1 0\n", b"h 2 3\n"], "C": [b"h 0\n", b"h 2 3\n"],
    "D": [b"h 1\n", b"h 2 3\n"], "E": [b"h 0\n", b"h 2\n"], "F": [b"h 1\n", b"h 3\n"],
    "G": [b"h 0\n"], "H": [b"h 1\n"], "I": [],
}


@pytest.mark.parametrize("name", list(PRIMITIVE_NAMES))
def test_primitive_lines_match_the_authors_executor(name):
    front, rear = primitive_pairs(PRIMITIVE_NAMES.index(name))
    lines = [encode_heat(p) for p in (front, rear) if p]
    assert lines == EXPECTED_LINES[name]


def test_primitive_id_out_of_range():
    with pytest.raises(ValueError, match="out of range 0-8"):
        primitive_pairs(9)


def test_host_lines_round_trip_and_authors_spacing():
    assert encode_set_pulse(80) == b"p 80\n"
    assert decode_command(b"p 80\n") == SetPulse(80)
    for limbs in [(0,), (1, 0), (2, 3), (0, 1, 2, 3), (3,)]:
        assert decode_command(encode_heat(limbs)) == Heat(limbs)
    assert decode_command(b"h  2 3\n") == Heat((2, 3))      # the authors' rear line
    assert decode_command(b"\n") == Blank()
    with pytest.raises(ValueError):
        encode_heat([])
    with pytest.raises(ValueError):
        encode_heat([1, 1])
    with pytest.raises(ValueError):
        encode_set_pulse(0)


@pytest.mark.parametrize("raw,kind", [
    (b"h\n", ErrorKind.BAD_ARGUMENT), (b"h 4\n", ErrorKind.BAD_ARGUMENT),
    (b"h 1 1\n", ErrorKind.BAD_ARGUMENT), (b"h 10\n", ErrorKind.BAD_ARGUMENT),
    (b"p\n", ErrorKind.BAD_ARGUMENT), (b"p 0\n", ErrorKind.BAD_ARGUMENT),
    (b"p -5\n", ErrorKind.BAD_ARGUMENT), (b"p 80.5\n", ErrorKind.BAD_ARGUMENT),
    (b"x 1\n", ErrorKind.UNKNOWN_COMMAND), (b"\xff\xfe h 1\n", ErrorKind.NOT_TEXT),
])
def test_bad_host_lines_are_typed_errors(raw, kind):
    r = decode_command(raw)
    assert isinstance(r, DecodeError) and r.kind is kind, r


def _yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2))


def test_quaternion_lines_lenient_and_ordered():
    yaw = 0.7
    w, z = math.cos(yaw / 2), math.sin(yaw / 2)
    for order in ("wxyz", "xyzw"):
        q = decode_relay_line(encode_quaternion(w, 0.0, 0.0, z, order), order)
        assert isinstance(q, Quaternion)
        assert _yaw(q) == pytest.approx(yaw, abs=2e-4)
    # lenient number formats and separators
    for raw in (b"Central: Q 1 0 0 0\r\n", b"Central: Q: 1.0, 0, 0, 0\n",
                b"Central: Q1;0;0;0", b"Central: Q  +1.000e0\t-0.0 .0 0.\r\n"):
        q = decode_relay_line(raw)
        assert isinstance(q, Quaternion) and q.w == pytest.approx(1.0), raw
    # normalised within the tolerance, refused beyond it
    q = decode_relay_line(b"Central: Q 1.05 0 0 0")
    assert isinstance(q, Quaternion) and q.w == pytest.approx(1.0) and q.norm == pytest.approx(1.05)
    for raw in (b"Central: Q 2 0 0 0", b"Central: Q 0 0 0 0", b"Central: Q 1 0 0",
                b"Central: Q 1 0 0 0 0", b"Central: Q nan 0 0 0", b"Central: Q 1 0 0 0x",
                b"Central: Q inf 0 0 0", b"Central: Q 1e999 0 0 0"):
        r = decode_relay_line(raw)
        assert isinstance(r, DecodeError) and r.kind is ErrorKind.BAD_QUATERNION, raw


def test_emergency_and_other_lines():
    assert decode_relay_line(encode_emergency()) == Emergency("Central: EMERGENCY")
    assert isinstance(decode_relay_line(b"Central: EMERGENCY overcurrent FL\r\n"), Emergency)
    # index 9 decides, as in the authors' code: a shorter prefix is not an emergency
    assert decode_relay_line(b"Cent: EMERGENCY") == RelayText("Cent: EMERGENCY", True)
    assert decode_relay_line(b"Central: hello") == RelayText("Central: hello", True)
    assert decode_relay_line(b"Scanning...") == RelayText("Scanning...", False)
    assert decode_relay_line(b"") == RelayText("", False)
    assert decode_relay_line(b"\x80abc").kind is ErrorKind.NOT_TEXT


def test_framer_partial_and_long_lines():
    f = LineFramer(max_line_bytes=20)
    assert f.feed(b"Central: Q") == []
    assert f.pending == 10
    assert f.feed(b" 1 0 0 0\r\nCen") == [b"Central: Q 1 0 0 0\r"]
    out = f.feed(b"x" * 50 + b"\nok\n")
    assert isinstance(out[0], DecodeError) and out[0].kind is ErrorKind.TOO_LONG
    assert out[1:] == [b"ok"]
    # an over-long line spread over many feeds yields one error and nothing of its tail
    out = []
    for _ in range(10):
        out += f.feed(b"y" * 1000)
    out += f.feed(b"tail\nnext\n")
    assert [type(o) for o in out] == [DecodeError, bytes] and out[1] == b"next"
    f.feed(b"partial")
    f.reset()
    assert f.feed(b"fresh\n") == [b"fresh"]


def _random_line(rng):
    kind = rng.integers(6)
    if kind == 0:                                   # binary, any bytes but newline
        b = rng.integers(0, 256, rng.integers(1, 200), dtype=np.uint8).tobytes()
        return b.replace(b"\n", b"")
    if kind == 1:                                   # non-UTF-8 behind a valid prefix
        return b"Central: Q " + bytes([0xC3, 0x28, 0xFF]) + b" 1 0 0"
    if kind == 2:                                   # 10 kB line
        return bytes(rng.integers(32, 127, 10_000, dtype=np.uint8))
    if kind == 3:                                   # printable noise with the prefix
        return b"Central: " + bytes(rng.integers(32, 127, rng.integers(0, 60), dtype=np.uint8))
    if kind == 4:                                   # numbers that almost look like a Q line
        return ("Central: Q " + " ".join(str(x) for x in rng.normal(size=rng.integers(0, 7)))).encode()
    return b"h " + bytes(rng.integers(0, 256, rng.integers(0, 8), dtype=np.uint8)).replace(b"\n", b"")


def test_fuzz_10000_lines_never_raise_and_keep_valid_lines():
    rng = np.random.default_rng(1234)
    framer = LineFramer(max_line_bytes=256)
    stream = bytearray()
    valid = []
    for i in range(10_000):
        stream += _random_line(rng) + b"\n"
        if i % 50 == 0:                              # a known-good line now and then
            yaw = float(rng.uniform(-math.pi, math.pi))
            valid.append(yaw)
            stream += encode_quaternion(math.cos(yaw / 2), 0, 0, math.sin(yaw / 2))
    got_yaws, kinds = [], set()
    pos = 0
    while pos < len(stream):                          # random chunking: partial lines
        n = int(rng.integers(1, 4096))
        for item in framer.feed(bytes(stream[pos:pos + n])):
            if isinstance(item, DecodeError):
                kinds.add(item.kind)
                continue
            for decode in (decode_relay_line, decode_command):
                r = decode(item)
                assert isinstance(r, (Quaternion, Emergency, RelayText, DecodeError, SetPulse,
                                      Heat, Blank)), r
                if isinstance(r, DecodeError):
                    kinds.add(r.kind)
                    str(r)                          # printable
            r = decode_relay_line(item)
            if isinstance(r, Quaternion) and item.endswith(b"\r") and len(item) < 60:
                got_yaws.append(_yaw(r))
        pos += n
    # every known-good line came through intact and in order (random lines rarely parse)
    it = iter(got_yaws)
    assert all(any(abs(y - g) < 2e-4 for g in it) for y in valid)
    assert {ErrorKind.NOT_TEXT, ErrorKind.TOO_LONG, ErrorKind.BAD_QUATERNION} <= kinds
