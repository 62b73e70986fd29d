"""Protocol 1 of the rig over the wire (docs/protocol.md): the frames, encoded and decoded.

Every frame is a 16-byte little-endian header, a fixed payload for its type and a CRC-32/ISO-HDLC
(``zlib.crc32``) of every byte before it. ``encode`` builds one; ``decode`` refuses anything that is not
exactly one valid frame with a ``ProtocolError`` naming what is wrong (length, magic, version, type, crc,
a field), so that a receiver can count it and carry on. Pure ``struct``: no pickles, nothing
Python-specific on the wire, so a C or Simulink peer is written from the page alone.
"""

from __future__ import annotations

import dataclasses
import math
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any

from twin.parameters import Daq, Parameters, SoftwareCalibration

__all__ = [
    "MAGIC",
    "VERSION",
    "Command",
    "Config",
    "Frame",
    "Hello",
    "Message",
    "ProtocolError",
    "Sample",
    "Stop",
    "FLAG_HELD",
    "FLAG_BALL_LOST",
    "FLAG_WATCHDOG",
    "FLAG_LATE",
    "FLAG_LAST",
    "FLAG_REFUSED",
    "ROLE_REFUSED",
    "ROLE_CONTROL",
    "ROLE_OBSERVE",
    "MODE_LOCKSTEP",
    "MODE_REALTIME",
    "STOP_DONE",
    "STOP_CLIENT_QUIT",
    "STOP_BALL_LOST",
    "STOP_ERROR",
    "STOP_SHUTDOWN",
    "decode",
    "decode_frame",
    "encode",
    "FieldError",
    "printable",
]

MAGIC = b"BBTW"
VERSION = 1

TYPE_HELLO, TYPE_CONFIG, TYPE_SAMPLE, TYPE_COMMAND, TYPE_STOP = 1, 2, 3, 4, 5
ROLE_REFUSED, ROLE_CONTROL, ROLE_OBSERVE = 0, 1, 2
MODE_LOCKSTEP, MODE_REALTIME = 1, 2
FLAG_HELD, FLAG_BALL_LOST, FLAG_WATCHDOG, FLAG_LATE, FLAG_LAST = 1, 2, 4, 8, 16
FLAG_REFUSED = 32  # the server refused a COMMAND carrying this sample's seq (non-finite or out of range)
STOP_DONE, STOP_CLIENT_QUIT, STOP_BALL_LOST, STOP_ERROR, STOP_SHUTDOWN = 0, 1, 2, 3, 4
BLOCK_LAST, BLOCK_MEAN = 0, 1  # CONFIG's ball_block / angle_block reductions

_HEADER = struct.Struct("<4sBBHII")  # magic, version, type, length, seq, session
_CRC = struct.Struct("<I")
_HELLO = struct.Struct("<BxH32s")  # role, pad, reply_port (0: the sender's port), client
_CONFIG = struct.Struct("<BBBBddI4x14d40s")  # role … angle_block, period, rate, watchdog, pad, 14 f64, rig
_SAMPLE = struct.Struct("<dddII4x")  # time, ball, angle, flags, applied_seq, pad
_COMMAND = struct.Struct("<d4x")  # dac_v, pad
_STOP = struct.Struct("<I")  # reason

_PAYLOADS = {
    TYPE_HELLO: _HELLO,
    TYPE_CONFIG: _CONFIG,
    TYPE_SAMPLE: _SAMPLE,
    TYPE_COMMAND: _COMMAND,
    TYPE_STOP: _STOP,
}
# Each type's whole frame length: header + payload + CRC (56, 200, 56, 32, 24 bytes: the doc's tables).
LENGTHS = {t: _HEADER.size + s.size + _CRC.size for t, s in _PAYLOADS.items()}
MAX_FRAME = max(LENGTHS.values())
_NAMES = {
    TYPE_HELLO: "HELLO",
    TYPE_CONFIG: "CONFIG",
    TYPE_SAMPLE: "SAMPLE",
    TYPE_COMMAND: "COMMAND",
    TYPE_STOP: "STOP",
}
_TEXT_HELLO, _TEXT_RIG = 32, 40
# CONFIG's software calibration, in its wire order (offsets 68…148): SoftwareCalibration's own fields.
_SOFTWARE_FIELDS = tuple(f.name for f in dataclasses.fields(SoftwareCalibration))


class ProtocolError(ValueError):
    """Bytes that are not one valid frame of protocol 1; the message names what is wrong."""


class FieldError(ProtocolError):
    """An intact frame (its CRC matches) whose field is outside its documented range: the sender's fault,
    not the line's. The message names the message type, the field and its value."""


NAME_LIMIT = 80  # the longest name ``printable`` returns (a name on the wire is 32 or 40 bytes)


def printable(name: str, limit: int = NAME_LIMIT) -> str:
    """A name received from the network (a HELLO's client, a CONFIG's rig) fit to print or put in a summary:
    printable ASCII kept, a backslash doubled, anything else (control characters, terminal escapes, a byte the
    ASCII decoding replaced) shown as ``\\xNN`` / ``\\uNNNN``, the result cut to ``limit`` characters
    (``...`` at the end when cut). One line, no escape sequence can reach a terminal through it."""
    out = []
    for c in name:
        if c == "\\":
            out.append("\\\\")
        elif " " <= c <= "~":
            out.append(c)
        elif ord(c) < 0x100:
            out.append(f"\\x{ord(c):02x}")
        else:
            out.append(f"\\u{ord(c):04x}")
    text = "".join(out)
    return text if len(text) <= limit else text[: max(limit - 3, 0)] + "..."


@dataclass(frozen=True)
class Hello:
    role: int = ROLE_CONTROL
    client: str = ""
    reply_port: int = 0  # UDP: the server sends to the HELLO's host at this port; 0: to the sender's port


@dataclass(frozen=True)
class Config:
    """The server's answer to HELLO: the granted role, the session's mode and the rig a controller needs."""

    role: int
    mode: int
    period_s: float
    sample_rate_hz: float
    watchdog_periods: int
    dac_min_v: float
    dac_max_v: float
    zero_command_v: float
    software: SoftwareCalibration = field(default_factory=SoftwareCalibration)
    rig: str = ""
    ball_block: int = BLOCK_LAST
    angle_block: int = BLOCK_MEAN

    @classmethod
    def from_parameters(
        cls, params: Parameters, *, role: int, mode: int, watchdog_periods: int, rig: str
    ) -> Config:
        return cls(
            role=role,
            mode=mode,
            period_s=params.period_s,
            sample_rate_hz=params.daq.sample_rate_hz,
            watchdog_periods=watchdog_periods,
            dac_min_v=params.daq.dac_min_v,
            dac_max_v=params.daq.dac_max_v,
            zero_command_v=params.amplifier.zero_command_v,
            software=params.software,
            rig=rig,
        )

    def to_parameters(self, base: Parameters | None = None) -> Parameters:
        """``base`` (default the thesis's) with this rig's DAQ timing, DAC range, zero command and software
        calibration: what a controller is designed and built with (a ``ParameterError`` if out of range)."""
        overrides: dict[str, object] = {
            "daq.period_s": self.period_s,
            "daq.sample_rate_hz": self.sample_rate_hz,
            "daq.dac_min_v": self.dac_min_v,
            "daq.dac_max_v": self.dac_max_v,
            "amplifier.zero_command_v": self.zero_command_v,
        }
        overrides.update({f"software.{name}": getattr(self.software, name) for name in _SOFTWARE_FIELDS})
        origin = f"CONFIG of {printable(self.rig) or 'the rig'}"  # a rig's name reaches messages escaped
        return (base or Parameters()).with_overrides(overrides, origin=origin)


@dataclass(frozen=True)
class Sample:
    seq: int
    time_s: float
    ball_v: float
    angle_v: float
    flags: int = 0
    applied_seq: int = 0


@dataclass(frozen=True)
class Command:
    seq: int
    dac_v: float


@dataclass(frozen=True)
class Stop:
    reason: int = STOP_DONE


Message = Hello | Config | Sample | Command | Stop


@dataclass(frozen=True)
class Frame:
    msg: Message
    session: int


def _text(value: str, size: int) -> bytes:
    """ASCII, cut to ``size`` (a name is for logs: truncate rather than refuse); struct NUL-pads it."""
    return value.encode("ascii", errors="replace").replace(b"\x00", b"?")[:size]


def _untext(raw: bytes) -> str:
    return raw.rstrip(b"\x00").decode("ascii", errors="replace")


def encode(msg: Message, session: int) -> bytes:
    """One frame of ``msg`` in session ``session`` (a u32)."""
    seq = 0
    if isinstance(msg, Hello):
        kind, payload = TYPE_HELLO, _HELLO.pack(msg.role, msg.reply_port, _text(msg.client, _TEXT_HELLO))
    elif isinstance(msg, Config):
        sw = [float(getattr(msg.software, name)) for name in _SOFTWARE_FIELDS]
        kind = TYPE_CONFIG
        payload = _CONFIG.pack(
            msg.role,
            msg.mode,
            msg.ball_block,
            msg.angle_block,
            msg.period_s,
            msg.sample_rate_hz,
            msg.watchdog_periods,
            msg.dac_min_v,
            msg.dac_max_v,
            msg.zero_command_v,
            *sw,
            _text(msg.rig, _TEXT_RIG),
        )
    elif isinstance(msg, Sample):
        kind, seq = TYPE_SAMPLE, msg.seq
        payload = _SAMPLE.pack(msg.time_s, msg.ball_v, msg.angle_v, msg.flags, msg.applied_seq)
    elif isinstance(msg, Command):
        kind, seq, payload = TYPE_COMMAND, msg.seq, _COMMAND.pack(msg.dac_v)
    elif isinstance(msg, Stop):
        kind, payload = TYPE_STOP, _STOP.pack(msg.reason)
    else:
        raise TypeError(f"not a protocol message: {type(msg).__name__}")
    body = _HEADER.pack(MAGIC, VERSION, kind, LENGTHS[kind], seq, session) + payload
    return body + _CRC.pack(zlib.crc32(body))


# CONFIG's doubles in wire order (offsets 20, 28, then 44…148): their names for a refusal's message.
_CONFIG_FLOATS = ("period_s", "sample_rate_hz", "dac_min_v", "dac_max_v", "zero_command_v", *_SOFTWARE_FIELDS)
_BLOCKS = {BLOCK_LAST: "the block's last sample", BLOCK_MEAN: "the block's mean"}


def _config_field(name: str, value: object, why: str) -> FieldError:
    return FieldError(f"CONFIG {name} = {value!r}: {why}")


def _decode_config(values: tuple[Any, ...]) -> Config:
    """CONFIG's payload, each field checked against its documented range (docs/protocol.md): a ``FieldError``
    naming the first field out of it. The DAQ fields get ``twin.parameters.Daq``'s ranges, the calibration
    ``SoftwareCalibration``'s; the zero command and the software's command limits must be DAC values."""
    role, mode, ball_block, angle_block, period_s, rate_hz, watchdog = values[:7]
    if role not in (ROLE_REFUSED, ROLE_CONTROL, ROLE_OBSERVE):
        raise _config_field("role", role, "expected 0 refused, 1 control or 2 observe")
    if mode not in (MODE_LOCKSTEP, MODE_REALTIME):
        raise _config_field("mode", mode, "expected 1 lock-step or 2 real time")
    for name, block in (("ball_block", ball_block), ("angle_block", angle_block)):
        if block not in _BLOCKS:
            raise _config_field(
                name, block, "an undefined block reduction (0 the block's last sample, 1 its mean)"
            )
    floats = (period_s, rate_hz, *values[7:21])
    for name, value in zip(_CONFIG_FLOATS, floats, strict=True):
        if not math.isfinite(value):
            raise _config_field(name, value, "not a finite number")
    if watchdog < 1:
        raise _config_field("watchdog_periods", watchdog, "expected at least 1 period")
    dac_min_v, dac_max_v, zero_v = values[7:10]
    try:
        Daq(period_s=period_s, sample_rate_hz=rate_hz, dac_min_v=dac_min_v, dac_max_v=dac_max_v)
    except ValueError as exc:  # twin.parameters.ParameterError: its message names daq.<field> and the value
        raise FieldError(f"CONFIG refused: {exc}") from None
    try:
        software = SoftwareCalibration(**dict(zip(_SOFTWARE_FIELDS, values[10:21], strict=True)))
    except ValueError as exc:  # twin.parameters.ParameterError: a calibration out of its range
        raise FieldError(f"CONFIG calibration refused: {exc}") from None
    dac = f"outside the DAC range dac_min_v … dac_max_v = {dac_min_v!r} … {dac_max_v!r} V"
    for name, value in (
        ("zero_command_v", zero_v),
        ("command_zero_v", software.command_zero_v),
        ("command_low_v", software.command_low_v),
        ("command_high_v", software.command_high_v),
    ):
        if not dac_min_v <= value <= dac_max_v:
            raise _config_field(name, value, dac)
    return Config(
        role=role,
        mode=mode,
        period_s=period_s,
        sample_rate_hz=rate_hz,
        watchdog_periods=watchdog,
        dac_min_v=dac_min_v,
        dac_max_v=dac_max_v,
        zero_command_v=zero_v,
        software=software,
        rig=_untext(values[21]),
        ball_block=ball_block,
        angle_block=angle_block,
    )


def decode_frame(data: bytes) -> Frame:
    """The message and session of one frame; a ``ProtocolError`` naming the first thing wrong."""
    n = len(data)
    if n < _HEADER.size + _CRC.size:
        raise ProtocolError(f"length {n} bytes: shorter than a header and a CRC ({_HEADER.size + _CRC.size})")
    if n > MAX_FRAME:
        raise ProtocolError(f"length {n} bytes: longer than any frame ({MAX_FRAME})")
    magic, version, kind, length, seq, session = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise ProtocolError(f"magic {magic!r}: expected {MAGIC!r}")
    if version != VERSION:
        raise ProtocolError(f"version {version}: this side speaks version {VERSION}")
    if kind not in _PAYLOADS:
        raise ProtocolError(f"type {kind}: expected 1…5")
    name = _NAMES[kind]
    if n != LENGTHS[kind]:
        raise ProtocolError(f"length {n} bytes: a {name} frame is {LENGTHS[kind]}")
    if length != n:
        raise ProtocolError(f"length field {length}: the {name} frame has {n} bytes")
    (crc,) = _CRC.unpack_from(data, n - _CRC.size)
    if crc != zlib.crc32(data[: n - _CRC.size]):
        raise ProtocolError(f"crc 0x{crc:08X} of the {name} frame does not match its bytes")
    values = _PAYLOADS[kind].unpack_from(data, _HEADER.size)
    msg: Message
    if kind == TYPE_HELLO:
        role, reply_port, client = values
        if role not in (ROLE_CONTROL, ROLE_OBSERVE):
            raise ProtocolError(f"HELLO role {role}: expected 1 control or 2 observe")
        msg = Hello(role=role, client=_untext(client), reply_port=reply_port)
    elif kind == TYPE_CONFIG:
        msg = _decode_config(values)
    elif kind == TYPE_SAMPLE:
        time_s, ball_v, angle_v, flags, applied = values
        msg = Sample(seq=seq, time_s=time_s, ball_v=ball_v, angle_v=angle_v, flags=flags, applied_seq=applied)
    elif kind == TYPE_COMMAND:
        msg = Command(seq=seq, dac_v=values[0])  # finiteness and range: the server's check (counted)
    else:
        msg = Stop(reason=values[0])
    return Frame(msg, session)


def decode(data: bytes) -> Message:
    """The message of one frame (``decode_frame`` for its session too)."""
    return decode_frame(data).msg
