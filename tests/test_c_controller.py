"""The C client of the served rig (examples/c/): its codec against frames packed here from the tables of
docs/protocol.md (``struct`` and ``zlib.crc32``, not the project's codec), and the appendix state feedback
in C closing the loop on the twin through pipes, compared with the Python ``appendix-sf`` on the same seed.

The harness plays the served rig: a ``ClosedLoop`` on a ``SimRig`` whose controller is an adapter that sends
each block as a SAMPLE to the C process and returns the DAC volts of its COMMAND."""

from __future__ import annotations

import math
import re
import shutil
import signal
import socket
import struct
import subprocess
import zlib
from collections.abc import Iterator
from dataclasses import fields
from pathlib import Path
from typing import IO

import numpy as np
import pytest

from controllers.appendix import AppendixStateFeedback
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.engine import ClosedLoop, update_ticks
from twin.interface import Controller, DaqSample, Telemetry
from twin.log import RunLog
from twin.parameters import Parameters
from twin.rigs.sim import make_rig, run_closed_loop

C_DIR = Path(__file__).resolve().parent.parent / "examples" / "c"
SOURCES = ("bb_sf.c", "bbwire.c", "appendix_sf.c")

# --- the frames, packed from the tables of docs/protocol.md ------------------------------------------------

HELLO, CONFIG, SAMPLE, COMMAND, STOP = 1, 2, 3, 4, 5
HEADER = struct.Struct("<4sBBHII")  # magic, version, type, length, seq, session
PAYLOAD = {
    HELLO: struct.Struct("<B3x32s"),  # role, pad, client
    CONFIG: struct.Struct("<4B2dI4x14d40s"),  # role…angle_block, period, rate, watchdog, pad, 14 f64, rig
    SAMPLE: struct.Struct("<3dII4x"),  # time_s, ball_v, angle_v, flags, applied_seq, pad
    COMMAND: struct.Struct("<d4x"),  # dac_v, pad
    STOP: struct.Struct("<I"),  # reason
}
LENGTH = {HELLO: 56, CONFIG: 200, SAMPLE: 56, COMMAND: 32, STOP: 24}
HELD, LAST = 0x1, 0x10


def frame(kind: int, seq: int, session: int, *values: object, version: int = 1) -> bytes:
    payload = PAYLOAD[kind].pack(*values)
    body = HEADER.pack(b"BBTW", version, kind, 16 + len(payload) + 4, seq, session) + payload
    return body + struct.pack("<I", zlib.crc32(body))


def unframe(data: bytes) -> tuple[int, int, int, tuple]:
    """(type, seq, session, payload fields) of one frame, every check of the spec asserted."""
    magic, version, kind, length, seq, session = HEADER.unpack_from(data)
    assert (magic, version, length, len(data)) == (b"BBTW", 1, LENGTH[kind], LENGTH[kind])
    assert struct.unpack_from("<I", data, length - 4)[0] == zlib.crc32(data[: length - 4])
    return kind, seq, session, PAYLOAD[kind].unpack_from(data, 16)


def config_values(params: Parameters, *, period_s: float | None = None, role: int = 1) -> tuple:
    sw, daq = params.software, params.daq
    return (
        role,
        1,  # lock-step
        0,  # ball: the block's last sample
        1,  # angle: the block's mean
        daq.period_s if period_s is None else period_s,
        daq.sample_rate_hz,
        5,  # watchdog periods (not the client's business)
        daq.dac_min_v,
        daq.dac_max_v,
        params.amplifier.zero_command_v,
        sw.ball_gain_m_per_v,
        sw.ball_offset_m,
        sw.angle_gain_deg_per_v,
        sw.angle_reference_v,
        sw.angle_reference_motor_deg,
        sw.angle_gear_ratio,
        sw.software_pi,
        sw.command_gain_v_per_v,
        sw.command_zero_v,
        sw.command_low_v,
        sw.command_high_v,
        b"ballbeam-twin test harness",
    )


# --- building and running the C program --------------------------------------------------------------------


def _makefile_flags() -> list[str]:
    """CFLAGS and FPFLAGS as the Makefile states them: the test builds what the README tells a user to."""
    text = (C_DIR / "Makefile").read_text()
    flags: list[str] = []
    for name in ("CFLAGS", "FPFLAGS"):
        match = re.search(rf"^{name}\s*\??=\s*(.+)$", text, re.MULTILINE)
        assert match, f"the Makefile sets no {name}"
        flags += match.group(1).split()
    return flags


def build_bb_sf(directory: Path) -> Path:
    """examples/c/bb_sf built into ``directory`` with the Makefile's flags and the system ``cc`` (skips
    the test when there is none); the wire tests that run the C client build it here."""
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler: `cc` is not on PATH (install gcc to test examples/c/)")
    out = directory / "bb_sf"
    subprocess.run(
        [cc, *_makefile_flags(), "-Werror", "-o", str(out), *(str(C_DIR / s) for s in SOURCES), "-lm"],
        check=True,
        capture_output=True,
        timeout=120,
    )
    return out


@pytest.fixture(scope="module")
def bb_sf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_bb_sf(tmp_path_factory.mktemp("c"))


def test_the_makefile_forbids_contraction_into_fma() -> None:
    flags = _makefile_flags()
    assert "-ffp-contract=off" in flags and "-fno-fast-math" in flags and "-std=c99" in flags


def test_crc_is_zlibs(bb_sf: Path) -> None:
    check = subprocess.run([bb_sf, "crc"], input=b"123456789", capture_output=True, timeout=10)
    assert check.stdout.decode().strip() == "cbf43926"
    data = bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8))
    out = subprocess.run([bb_sf, "crc"], input=data, capture_output=True, timeout=10)
    assert int(out.stdout, 16) == zlib.crc32(data)


def _selftest(bb_sf: Path, data: bytes) -> list[str]:
    out = subprocess.run([bb_sf, "selftest"], input=data, capture_output=True, timeout=10, check=True)
    return out.stdout.decode().splitlines()


def _fields(line: str) -> dict[str, str]:
    return dict(item.split("=", 1) for item in line.split())


def test_c_decodes_and_reencodes_every_message_of_the_tables(bb_sf: Path, params: Parameters) -> None:
    nan_payload = struct.unpack("<d", struct.pack("<Q", 0x7FF8_0000_DEAD_BEEF))[0]
    frames = [
        frame(HELLO, 0, 0, 1, b"simulink model"),
        frame(CONFIG, 0, 0xCAFE_F00D, *config_values(params)),
        frame(SAMPLE, 0, 7, -0.01, 2.5830086580086584, 5.002, HELD, 0),
        frame(SAMPLE, 2**32 - 1, 7, 5e-324, -0.0, nan_payload, 0x1F, 2**32 - 2),
        frame(COMMAND, 41, 7, 3.75),
        frame(STOP, 0, 7, 4),
    ]
    lines = _selftest(bb_sf, b"".join(frames))
    assert len(lines) == len(frames)
    for data, line in zip(frames, lines, strict=True):
        got = _fields(line)
        kind, seq, session, values = unframe(data)
        assert (int(got["type"]), int(got["seq"]), int(got["session"])) == (kind, seq, session)
        assert bytes.fromhex(got["encoded"]) == data  # the C encoder packs the same bytes
    cfg = _fields(lines[1])
    names = (
        "period_s sample_rate_hz dac_min_v dac_max_v zero_command_v ball_gain_m_per_v ball_offset_m "
        "angle_gain_deg_per_v angle_reference_v angle_reference_motor_deg angle_gear_ratio software_pi "
        "command_gain_v_per_v command_zero_v command_low_v command_high_v"
    ).split()
    expected = config_values(params)
    doubles = expected[4:6] + expected[7:21]
    assert [float.fromhex(cfg[n]) for n in names] == list(doubles)
    assert (cfg["role"], cfg["mode"], cfg["ball_block"], cfg["angle_block"]) == ("1", "1", "0", "1")
    assert cfg["watchdog_periods"] == "5" and cfg["rig"] == r"ballbeam-twin\x20test\x20harness"
    assert _fields(lines[0])["client"] == r"simulink\x20model"
    s0, s1 = _fields(lines[2]), _fields(lines[3])
    assert float.fromhex(s0["ball_v"]) == 2.5830086580086584 and s0["flags"] == "1"
    assert float.fromhex(s1["time_s"]) == 5e-324 and math.copysign(1.0, float.fromhex(s1["ball_v"])) == -1.0
    assert s1["flags"] == "31" and s1["applied_seq"] == str(2**32 - 2)
    assert float.fromhex(_fields(lines[4])["dac_v"]) == 3.75 and _fields(lines[5])["reason"] == "4"


def test_c_rejects_each_malformed_frame_and_finds_the_next_good_one(bb_sf: Path) -> None:
    good = frame(COMMAND, 3, 9, 2.5)
    bad_crc = good[:-1] + bytes([good[-1] ^ 0x01])
    flipped = bytearray(good)
    flipped[20] ^= 0x40  # a payload bit: the CRC no longer matches
    wrong_length = bytearray(good)
    wrong_length[6] = 33
    unknown_type = bytearray(good)
    unknown_type[5] = 9
    lines = _selftest(
        bb_sf,
        b"".join(
            [
                b"\x00garbage\xa5\x5a",
                bad_crc,
                bytes(flipped),
                frame(COMMAND, 3, 9, 2.5, version=2),
                bytes(wrong_length),
                bytes(unknown_type),
                good,
            ]
        ),
    )
    rejected = [line for line in lines if line.startswith("REJECTED")]
    assert rejected == [
        "REJECTED bad crc",
        "REJECTED bad crc",
        "REJECTED unsupported version",
        "REJECTED wrong length",
        "REJECTED unknown type",
    ]
    decoded = [line for line in lines if line.startswith("type=")]
    assert len(decoded) == 1 and bytes.fromhex(_fields(decoded[0])["encoded"]) == good


# --- the C controller as a client of a rig played here -----------------------------------------------------


class PipeClient:
    """The C program in ``pipe`` mode: frames to its stdin, from its stdout; its trace line per sample."""

    def __init__(self, bb_sf: Path, trace: Path, *transport: str) -> None:
        self.proc = subprocess.Popen(
            [bb_sf, *(transport or ("pipe",)), "--trace", str(trace), "--timeout", "5"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        self.trace_path = trace
        self.trace: IO[str] | None = None

    def send(self, data: bytes) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(data)
        self.proc.stdin.flush()

    def read_frame(self) -> bytes:
        assert self.proc.stdout is not None
        header = self.proc.stdout.read(16)
        assert len(header) == 16, f"bb_sf sent no frame: {self.finish()[1]}"
        return header + self.proc.stdout.read(HEADER.unpack(header)[3] - 16)

    def receive(self, kind: int) -> tuple[int, int, tuple]:
        got, seq, session, values = unframe(self.read_frame())
        assert got == kind
        return seq, session, values

    def trace_line(self) -> list[float]:
        if self.trace is None:
            self.trace = self.trace_path.open()
        line = self.trace.readline()
        assert line.endswith("\n"), "the trace line comes before the COMMAND it explains"
        words = line.split()
        return [float(words[0]), *(float.fromhex(w) for w in words[1:])]

    def finish(self) -> tuple[int, str]:
        try:
            _, err = self.proc.communicate(timeout=10)
        finally:
            if self.trace is not None:
                self.trace.close()
        return self.proc.returncode, err.decode()


class UdpClient(PipeClient):
    """The C program in ``udp`` mode against a socket of this test on loopback: one frame per datagram."""

    def __init__(self, bb_sf: Path, trace: Path) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(5.0)  # a client that never answers fails the test instead of hanging it
        self.peer: tuple[str, int] | None = None
        super().__init__(bb_sf, trace, "udp", "127.0.0.1", str(self.sock.getsockname()[1]))

    def send(self, data: bytes) -> None:
        assert self.peer is not None
        self.sock.sendto(data, self.peer)

    def read_frame(self) -> bytes:
        while True:
            first = self.peer is None
            data, self.peer = self.sock.recvfrom(1024)
            if first or data[5] != HELLO:  # HELLO repeats until CONFIG arrives: one may cross it
                return data

    def finish(self) -> tuple[int, str]:
        try:
            return super().finish()
        finally:
            self.sock.close()


def handshake(client: PipeClient, params: Parameters, session: int, **config: object) -> None:
    seq, hello_session, (role, name) = client.receive(HELLO)
    assert (seq, hello_session, role) == (0, 0, 1)
    assert name.rstrip(b"\0") == b"bb_sf appendix-sf (C99)"
    client.send(frame(CONFIG, 0, session, *config_values(params, **config)))  # type: ignore[arg-type]


class CController(Controller):
    """The rig's side of the wire: each block to the C process as a SAMPLE, its COMMAND's volts back; the
    telemetry is the C controller's own (its trace line for the sample)."""

    name = "bb_sf (C)"

    def __init__(self, client: PipeClient, session: int, last_k: int) -> None:
        super().__init__()
        self.client, self.session, self.last_k = client, session, last_k
        self.k = 0
        self.answers: list[float] = []

    def _exchange(self, sample: DaqSample, flags: int) -> float:
        applied = self.k - 1 if self.k >= 2 else 0  # the command the DAC holds during this block
        self.client.send(
            frame(SAMPLE, self.k, self.session, sample.time_s, sample.ball_v, sample.angle_v, flags, applied)
        )
        seq, session, (dac_v,) = self.client.receive(COMMAND)
        assert (seq, session) == (self.k, self.session)
        k, x1, x2, x3, x4, u, u_temp, command_v = self.client.trace_line()
        assert k == self.k and command_v == dac_v
        self.telemetry = Telemetry(np.array([x1, x2, x3, x4]), u, u_temp)
        self.answers.append(dac_v)
        return dac_v

    def start(self, sample: DaqSample) -> None:
        self._exchange(sample, HELD)

    def update(self, sample: DaqSample) -> float:
        self.k += 1
        return self._exchange(sample, LAST if self.k == self.last_k else 0)


def run_c_closed_loop(
    bb_sf: Path,
    tmp_path: Path,
    params: Parameters,
    x0_m: float,
    theta0_rad: float,
    seed: int,
    udp: bool = False,
) -> tuple[ClosedLoop, CController, int, str]:
    """The sequence of ``run_closed_loop`` (10 s, noise on) with the C controller over pipes (or loopback
    UDP); ends with STOP."""
    trace = tmp_path / f"trace_{x0_m}_{theta0_rad}.txt"
    client = UdpClient(bb_sf, trace) if udp else PipeClient(bb_sf, trace)
    session = 0x5EED_0000 + seed
    handshake(client, params, session)
    rig = make_rig(params, seed=seed, noise=True)
    rig.reset(x0_m, theta0_rad)
    ticks = update_ticks(10.0, rig.params)
    controller = CController(client, session, ticks)
    loop = ClosedLoop(rig, controller)
    loop.start()
    for _ in range(ticks):
        loop.tick()
        if rig.ball_lost:
            break
    client.send(frame(STOP, 0, session, 2 if rig.ball_lost else 0))
    code, err = client.finish()
    return loop, controller, code, err


def _max_abs_difference(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b))) if len(a) == len(b) else math.inf


@pytest.mark.parametrize(("figure", "start"), list(HARDWARE_STARTS.items()), ids=list(HARDWARE_STARTS))
def test_the_c_controller_holds_from_the_hardware_starts_bit_for_bit_as_the_python_port(
    bb_sf: Path, tmp_path: Path, params: Parameters, figure: str, start: tuple[float, float]
) -> None:
    x0, theta0 = start
    loop, controller, code, err = run_c_closed_loop(bb_sf, tmp_path, params, x0, theta0, seed=0)
    assert code == 0, err
    assert "stopped by the server: done (reason 0)" in err and "0 frames ignored" in err
    c_log: RunLog = loop.log()
    c_verdict = loop.verdict(x0)
    assert c_verdict.held, f"{figure}: {c_verdict.reason}"
    py = run_closed_loop(AppendixStateFeedback(params.software), x0_m=x0, theta0_rad=theta0, seed=0)
    assert py.verdict.held
    # Measured: max |Δ DAC volts| = 0 from all four starts; every column of the log is the same bits (the
    # C port computes each double in the Python port's order, without FMA), hence the same verdict.
    assert _max_abs_difference(c_log.aout, py.log.aout) == 0.0
    for f in fields(RunLog):
        np.testing.assert_array_equal(getattr(c_log, f.name), getattr(py.log, f.name), err_msg=f.name)
    assert c_verdict == py.verdict
    assert len(controller.answers) == c_log.k == 1 + update_ticks(10.0, params)


# --- the client's side of the session: repeats, strays, refusals, silence ----------------------------------


@pytest.fixture
def sample_frames(params: Parameters) -> Iterator[list[DaqSample]]:
    """The first three blocks of the twin from the first hardware start, as a rig would send them."""
    rig = make_rig(params, seed=0, noise=True)
    rig.reset(*HARDWARE_STARTS["Fig 6.16 (state feedback)"])
    samples = [rig.read()]
    for _ in range(2):
        samples.append(rig.read())
        rig.write(params.amplifier.zero_command_v)
    yield samples


def test_the_client_ignores_strays_repeats_its_answer_and_never_advances_twice(
    bb_sf: Path, tmp_path: Path, params: Parameters, sample_frames: list[DaqSample]
) -> None:
    client = PipeClient(bb_sf, tmp_path / "trace.txt")
    handshake(client, params, 77)
    s0, s1, s2 = sample_frames
    client.send(frame(SAMPLE, 0, 77, s0.time_s, s0.ball_v, s0.angle_v, HELD, 0))
    assert client.receive(COMMAND)[2] == (params.amplifier.zero_command_v,)
    one = frame(SAMPLE, 1, 77, s1.time_s, s1.ball_v, s1.angle_v, 0, 0)
    stray = [
        frame(SAMPLE, 1, 76, s1.time_s, s1.ball_v, s1.angle_v, 0, 0),  # another session
        one[:-4] + b"\0\0\0\0",  # a bad CRC
        frame(COMMAND, 1, 77, 2.5),  # a frame a client never receives
        frame(CONFIG, 0, 77, *config_values(params)),  # a repeated CONFIG
    ]
    client.send(b"".join(stray) + one)
    (dac_1,) = client.receive(COMMAND)[2]
    client.send(one)  # the same sample again: the same answer, the observer not advanced
    assert client.receive(COMMAND)[2] == (dac_1,)
    client.send(frame(SAMPLE, 0, 77, s0.time_s, s0.ball_v, s0.angle_v, HELD, 0))  # stale: ignored
    client.send(frame(SAMPLE, 2, 77, s2.time_s, s2.ball_v, s2.angle_v, LAST, 1))
    (dac_2,) = client.receive(COMMAND)[2]
    client.send(frame(STOP, 0, 77, 0))
    code, err = client.finish()
    assert code == 0 and "3 answered, 5 frames ignored" in err, err
    python = AppendixStateFeedback(params.software)
    python.start(s0)
    assert [python.update(s1), python.update(s2)] == [dac_1, dac_2]


@pytest.mark.parametrize(
    ("config", "reason"),
    [
        ({"period_s": 0.01}, "CONFIG period_s = 0.01 s: the observer is discretised for 0.02 s"),
        ({"role": 0}, "the server refused control (CONFIG role = 0): another client controls"),
        ({"role": 2}, "granted observe only, not control (CONFIG role = 2)"),
    ],
)
def test_a_config_this_controller_cannot_run_on_ends_it_with_one_line(
    bb_sf: Path, tmp_path: Path, params: Parameters, config: dict[str, object], reason: str
) -> None:
    client = PipeClient(bb_sf, tmp_path / "trace.txt")
    handshake(client, params, 5, **config)
    code, err = client.finish()
    assert code == 1 and reason in err and err.count("\n") == 1, err


def test_a_silent_server_ends_the_session_within_the_timeout(bb_sf: Path) -> None:
    proc = subprocess.run(
        [bb_sf, "udp", "127.0.0.1", "9", "--timeout", "0.5"], capture_output=True, timeout=10
    )
    assert proc.returncode == 1
    assert proc.stderr.decode() == "bb_sf: no CONFIG from the server within 0.5 s (--timeout)\n"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["udp", "127.0.0.1"], "bb_sf: udp needs HOST and PORT"),
        (["tcp"], "bb_sf: unknown mode 'tcp'"),
        (["pipe", "--timeout", "never"], "bb_sf: --timeout never: a number of seconds in (0, 3600]"),
        (["pipe", "--trace"], "bb_sf: an option needs a value"),
    ],
)
def test_usage_errors_exit_2_with_one_line(bb_sf: Path, args: list[str], message: str) -> None:
    proc = subprocess.run([bb_sf, *args], capture_output=True, timeout=10)
    assert proc.returncode == 2 and proc.stderr.decode().splitlines()[0] == message


def test_over_udp_the_c_controller_runs_the_same_session(
    bb_sf: Path, tmp_path: Path, params: Parameters
) -> None:
    x0, theta0 = HARDWARE_STARTS["Fig 6.17 (state feedback)"]
    loop, controller, code, err = run_c_closed_loop(bb_sf, tmp_path, params, x0, theta0, seed=0, udp=True)
    assert code == 0, err
    py = run_closed_loop(AppendixStateFeedback(params.software), x0_m=x0, theta0_rad=theta0, seed=0)
    assert controller.answers == py.log.aout.tolist() and loop.verdict(x0) == py.verdict


def test_ctrl_c_ends_the_session_with_a_stop_not_a_silent_controller(
    bb_sf: Path, tmp_path: Path, params: Parameters, sample_frames: list[DaqSample]
) -> None:
    client = PipeClient(bb_sf, tmp_path / "trace.txt")
    handshake(client, params, 12)
    s0 = sample_frames[0]
    client.send(frame(SAMPLE, 0, 12, s0.time_s, s0.ball_v, s0.angle_v, HELD, 0))
    client.receive(COMMAND)
    client.proc.send_signal(signal.SIGINT)
    assert client.receive(STOP)[1:] == (12, (1,))  # reason 1: client quit
    code, err = client.finish()
    assert code == 130 and err == "bb_sf: interrupted (signal 2) after sample 0: sent STOP 1 (client quit)\n"


# --- against the served twin: bb_sf over UDP, ballbeam's own server in lock-step ----------------------------


@pytest.mark.parametrize(("figure", "start"), list(HARDWARE_STARTS.items()), ids=list(HARDWARE_STARTS))
def test_the_c_controller_against_the_served_twin_is_the_python_port_bit_for_bit(
    bb_sf: Path, params: Parameters, figure: str, start: tuple[float, float]
) -> None:
    """``bb_sf udp`` against ``twin.serving.server.Server`` (lock-step, 10 s, seed 0): the session's log and verdict
    (true state included) equal the in-process ``appendix-sf`` run's, array by array; held."""
    from serving import in_thread, session_of

    from twin.log import REQUIRED_FIELDS, TRUTH_FIELDS
    from twin.serving.server import Server, SessionSettings

    x0, theta0 = start
    settings = SessionSettings(x0_m=x0, theta0_rad=theta0, seed=0, duration_s=10.0, wait_client_s=30.0)
    server = Server(settings, "127.0.0.1", 0, log=lambda _: None)
    with in_thread(server) as box:
        client = subprocess.run(
            [str(bb_sf), "udp", "127.0.0.1", str(server.port), "--timeout", "10"],
            capture_output=True,
            text=True,
            timeout=120,
        )
    assert client.returncode == 0, client.stderr
    served = session_of(box).result
    py = run_closed_loop(AppendixStateFeedback(params.software), x0_m=x0, theta0_rad=theta0, seed=0)
    assert served.verdict.held, f"{figure}: {served.verdict.reason}"
    assert served.verdict == py.verdict
    # the I/O card's columns and the true state; the controller's own values do not travel over the wire
    for name in (*REQUIRED_FIELDS, *TRUTH_FIELDS):
        np.testing.assert_array_equal(getattr(served.log, name), getattr(py.log, name), err_msg=name)
