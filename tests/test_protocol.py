"""Protocol 1 (docs/protocol.md): every frame's bytes against the doc's tables, built by hand at the doc's
offsets (never with the codec's own layouts), the CRC, every malformed kind refused, round trips."""

from __future__ import annotations

import math
import struct
import zlib

import pytest

from twin.parameters import Parameters
from twin.wire import protocol as p


def _frame(kind: int, length: int, seq: int, session: int, fields: list[tuple[int, str, object]]) -> bytes:
    """A frame written field by field at the offsets the doc's tables give (pads stay zero)."""
    buf = bytearray(length)
    buf[0:4] = b"\x42\x42\x54\x57"
    buf[4] = 1
    buf[5] = kind
    struct.pack_into("<H", buf, 6, length)
    struct.pack_into("<I", buf, 8, seq)
    struct.pack_into("<I", buf, 12, session)
    for offset, fmt, value in fields:
        if isinstance(value, tuple):
            struct.pack_into("<" + fmt, buf, offset, *value)
        else:
            struct.pack_into("<" + fmt, buf, offset, value)
    struct.pack_into("<I", buf, length - 4, zlib.crc32(bytes(buf[: length - 4])))
    return bytes(buf)


@pytest.mark.quick
def test_crc_is_crc32_iso_hdlc() -> None:
    assert zlib.crc32(b"123456789") == 0xCBF43926


def test_hello_bytes() -> None:
    want = _frame(1, 56, 0, 0, [(16, "B", 2), (20, "32s", b"c-client")])
    assert p.encode(p.Hello(role=2, client="c-client"), 0) == want
    assert p.decode(want) == p.Hello(role=2, client="c-client")


def test_hello_reply_port_bytes() -> None:
    """The reply port is the u16 at offset 18 (once pad: a HELLO written before carries 0 there)."""
    want = _frame(1, 56, 0, 0, [(16, "B", 1), (18, "H", 25001), (20, "32s", b"simulink")])
    assert p.encode(p.Hello(role=1, client="simulink", reply_port=25001), 0) == want
    assert p.decode(want) == p.Hello(role=1, client="simulink", reply_port=25001)
    assert p.decode(_frame(1, 56, 0, 0, [(16, "B", 1)])).reply_port == 0  # type: ignore[union-attr]


def test_refused_flag_is_bit_5() -> None:
    assert p.FLAG_REFUSED == 0x20
    assert not p.FLAG_REFUSED & (p.FLAG_HELD | p.FLAG_BALL_LOST | p.FLAG_WATCHDOG | p.FLAG_LATE | p.FLAG_LAST)


@pytest.mark.quick
def test_sample_bytes() -> None:
    fields: list[tuple[int, str, object]] = [
        (16, "d", -0.04),
        (24, "d", 1.25),
        (32, "d", -3.5),
        (40, "I", p.FLAG_HELD | p.FLAG_LAST),
        (44, "I", 6),
    ]
    want = _frame(3, 56, 7, 0xDEADBEEF, fields)
    msg = p.Sample(seq=7, time_s=-0.04, ball_v=1.25, angle_v=-3.5, flags=17, applied_seq=6)
    assert p.encode(msg, 0xDEADBEEF) == want
    assert p.decode_frame(want) == p.Frame(msg, 0xDEADBEEF)


def test_command_and_stop_bytes() -> None:
    want = _frame(4, 32, 9, 5, [(16, "d", 2.75)])
    assert p.encode(p.Command(seq=9, dac_v=2.75), 5) == want
    assert p.decode(want) == p.Command(seq=9, dac_v=2.75)
    stop = _frame(5, 24, 0, 5, [(16, "I", 3)])
    assert p.encode(p.Stop(reason=3), 5) == stop
    assert p.decode(stop) == p.Stop(reason=3)


def test_config_bytes_and_parameters() -> None:
    params = Parameters()
    sw = params.software
    doubles = [
        (44, 0.0),
        (52, 5.0),
        (60, 2.5),
        (68, sw.ball_gain_m_per_v),
        (76, sw.ball_offset_m),
        (84, sw.angle_gain_deg_per_v),
        (92, sw.angle_reference_v),
        (100, sw.angle_reference_motor_deg),
        (108, sw.angle_gear_ratio),
        (116, sw.software_pi),
        (124, sw.command_gain_v_per_v),
        (132, sw.command_zero_v),
        (140, sw.command_low_v),
        (148, sw.command_high_v),
    ]
    fields: list[tuple[int, str, object]] = [
        (16, "BBBB", (1, 2, 0, 1)),
        (20, "d", 0.02),
        (28, "d", 40000.0),
        (36, "I", 5),
        *[(off, "d", v) for off, v in doubles],
        (156, "40s", b"ballbeam-twin test"),
    ]
    want = _frame(2, 200, 0, 42, fields)
    cfg = p.Config.from_parameters(params, role=1, mode=2, watchdog_periods=5, rig="ballbeam-twin test")
    assert p.encode(cfg, 42) == want
    back = p.decode(want)
    assert back == cfg
    assert isinstance(back, p.Config)
    rebuilt = back.to_parameters()
    assert rebuilt.software == params.software
    assert rebuilt.daq.period_s == 0.02 and rebuilt.amplifier.zero_command_v == 2.5
    # a recalibrated rig's numbers reach the controller's parameters
    other = params.with_overrides({"software.ball_gain_m_per_v": 0.07, "daq.period_s": 0.01})
    cfg2 = p.Config.from_parameters(other, role=1, mode=1, watchdog_periods=3, rig="r")
    got = p.decode(p.encode(cfg2, 1))
    assert isinstance(got, p.Config)
    assert got.to_parameters().software.ball_gain_m_per_v == 0.07
    assert got.to_parameters().daq.period_s == 0.01


@pytest.mark.quick
def test_frame_lengths_are_the_docs() -> None:
    assert p.LENGTHS == {1: 56, 2: 200, 3: 56, 4: 32, 5: 24}


@pytest.mark.quick
@pytest.mark.parametrize(
    "msg",
    [
        p.Hello(role=1, client="x" * 32),
        p.Sample(seq=2**32 - 1, time_s=math.pi, ball_v=-0.0, angle_v=1e-300, flags=31, applied_seq=1),
        p.Command(seq=0, dac_v=5.0),
        p.Stop(reason=4),
    ],
)
def test_round_trip_is_bit_exact(msg: p.Message) -> None:
    frame = p.decode_frame(p.encode(msg, 123))
    assert frame == p.Frame(msg, 123)
    assert p.encode(frame.msg, 123) == p.encode(msg, 123)


def test_long_names_are_cut_not_refused() -> None:
    got = p.decode(p.encode(p.Hello(client="n" * 50), 0))
    assert isinstance(got, p.Hello) and got.client == "n" * 32


def _recrc(buf: bytearray) -> bytes:
    struct.pack_into("<I", buf, len(buf) - 4, zlib.crc32(bytes(buf[:-4])))
    return bytes(buf)


def _malformed() -> list[tuple[str, bytes, str]]:
    good = p.encode(p.Command(seq=1, dac_v=2.5), 9)
    bad_magic = bytearray(good)
    bad_magic[0] = ord("X")
    bad_version = bytearray(good)
    bad_version[4] = 2
    bad_type = bytearray(good)
    bad_type[5] = 6
    bad_length_field = bytearray(good)
    struct.pack_into("<H", bad_length_field, 6, 33)
    bad_crc = bytearray(good)
    bad_crc[16] ^= 1
    bad_role = bytearray(p.encode(p.Hello(), 0))
    bad_role[16] = 3
    return [
        ("empty", b"", "length 0"),
        ("short", good[:10], "length 10"),
        ("oversized", good + b"\0" * 400, "longer than any frame"),
        ("truncated", good[:-1], "a COMMAND frame is 32"),
        ("padded", good + b"\0", "a COMMAND frame is 32"),
        ("magic", _recrc(bad_magic), "magic"),
        ("version", _recrc(bad_version), "version 2"),
        ("type", _recrc(bad_type), "type 6"),
        ("length field", _recrc(bad_length_field), "length field 33"),
        ("crc", bytes(bad_crc), "crc"),
        ("role", _recrc(bad_role), "HELLO role 3"),
    ]


@pytest.mark.quick
@pytest.mark.parametrize(("what", "data", "message"), _malformed(), ids=[m[0] for m in _malformed()])
def test_malformed_frames_are_refused_by_name(what: str, data: bytes, message: str) -> None:
    with pytest.raises(p.ProtocolError, match=message):
        p.decode(data)


def test_protocol_error_is_a_value_error() -> None:
    assert issubclass(p.ProtocolError, ValueError)
