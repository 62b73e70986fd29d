"""Protocol 1 over a serial line (docs/protocol.md, "Transports"): the framing (sync bytes, resync after
garbage, a frame split across reads, a bad CRC dropped and counted, a wrong length resynced), and a
lock-step session over a pseudo-terminal pair equal bit for bit to the in-process run."""

from __future__ import annotations

import json
import os
import random
import select
import subprocess
import sys
import threading
import time
import tty
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from serving import in_thread, session_of

from controllers import registry
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.engine import RunResult, run_on_rig, update_ticks
from twin.interface import Controller
from twin.log import THESIS_FIELDS, TRUTH_FIELDS, RunLog
from twin.parameters import Parameters
from twin.rigs.remote import RemoteError, open_remote
from twin.rigs.sim import run_closed_loop
from twin.serving.server import Server, SessionResult, SessionSettings
from twin.wire import protocol as p
from twin.wire.links import SERIAL_PEER, SYNC, FrameReader, LinkError, SerialLink, open_link, parse_url

ROOT = Path(__file__).resolve().parents[1]
STARTS = list(HARDWARE_STARTS.values())
TELEMETRY = ("x1", "x2", "x3", "x4", "u", "uhesap")  # the controller's own values: they do not travel

SAMPLE = p.encode(p.Sample(seq=7, time_s=0.14, ball_v=1.25, angle_v=2.5, flags=0, applied_seq=6), 42)
COMMAND = p.encode(p.Command(seq=7, dac_v=2.6), 42)


def _frames(reader: FrameReader) -> list[bytes]:
    out = []
    while (frame := reader.next_frame()) is not None:
        out.append(frame)
    return out


# --- the framing ----------------------------------------------------------------------------------------
@pytest.mark.quick
def test_frames_follow_the_sync_bytes_and_decode() -> None:
    reader = FrameReader()
    reader.feed(SYNC + SAMPLE + SYNC + COMMAND)
    got = _frames(reader)
    assert got == [SAMPLE, COMMAND]
    assert p.decode(got[0]) == p.Sample(seq=7, time_s=0.14, ball_v=1.25, angle_v=2.5, flags=0, applied_seq=6)
    assert reader.counts.frames == 2 and reader.counts.resyncs == 0 and reader.counts.garbage_bytes == 0
    assert len(reader.buf) == 0


def test_garbage_before_a_frame_is_skipped_and_counted() -> None:
    reader = FrameReader()
    garbage = bytes(range(256))[:200] + b"\xa5" + b"\xa5\x5aBB"  # a lone sync byte, a sync without the magic
    reader.feed(garbage + SYNC + SAMPLE)
    assert _frames(reader) == [SAMPLE]
    assert reader.counts.garbage_bytes == len(garbage)
    assert reader.counts.resyncs >= 1 and reader.counts.frames == 1


@pytest.mark.quick
def test_a_frame_split_across_reads_is_assembled() -> None:
    reader = FrameReader()
    stream = SYNC + SAMPLE + SYNC + COMMAND
    got: list[bytes] = []
    for i in range(len(stream)):  # one byte per read: the worst split there is
        reader.feed(stream[i : i + 1])
        got += _frames(reader)
    assert got == [SAMPLE, COMMAND]
    assert reader.counts.garbage_bytes == 0 and reader.counts.resyncs == 0


def test_a_bad_crc_is_dropped_and_counted_and_the_next_frame_kept() -> None:
    reader = FrameReader()
    bad = bytearray(SAMPLE)
    bad[30] ^= 0x01  # one flipped bit in ball_v
    reader.feed(SYNC + bytes(bad) + SYNC + COMMAND)
    assert _frames(reader) == [COMMAND]
    assert reader.counts.crc_errors == 1 and reader.counts.frames == 1
    assert reader.counts.garbage_bytes == len(SYNC) + len(SAMPLE)  # the bad frame's bytes, skipped


def test_a_wrong_length_field_is_resynced() -> None:
    reader = FrameReader()
    bad = bytearray(COMMAND)
    bad[6:8] = (199).to_bytes(2, "little")  # not one of the five frame lengths (24, 32, 56, 200)
    reader.feed(SYNC + bytes(bad) + SYNC + SAMPLE)
    assert _frames(reader) == [SAMPLE]
    assert reader.counts.bad_lengths == 1 and reader.counts.crc_errors == 0
    # a length of a frame, but not this one's: read as such, its CRC fails, and the reader resyncs
    bad[6:8] = (200).to_bytes(2, "little")
    reader.feed(SYNC + bytes(bad) + bytes(200) + SYNC + COMMAND)
    assert _frames(reader) == [COMMAND]
    assert reader.counts.crc_errors == 1


def test_garbage_alone_keeps_the_buffer_bounded() -> None:
    reader = FrameReader()
    for _ in range(100):
        reader.feed(b"\x00\xa5" * 500)
        assert reader.next_frame() is None
        assert len(reader.buf) < len(SYNC) + len(p.MAGIC)
    assert reader.counts.garbage_bytes == 100 * 1000 - len(reader.buf)


@pytest.mark.quick
def test_urls() -> None:
    assert parse_url("udp://127.0.0.1:9000") == ("udp", "127.0.0.1", 9000)
    assert parse_url("serial:///dev/ttyACM0?baud=115200") == ("serial", "/dev/ttyACM0", 115200)
    assert parse_url("serial:///dev/ttyUSB1") == ("serial", "/dev/ttyUSB1", 115200)
    for bad in ("udp://host", "serial:///dev/tty0?baud=12345", "serial:///dev/tty0?baud=x", "tcp://h:1", "x"):
        with pytest.raises(ValueError, match="expected|baud"):
            parse_url(bad)
    with pytest.raises(LinkError, match="cannot open /nonexistent/tty"):
        open_link("serial:///nonexistent/tty?baud=9600")
    with pytest.raises(RemoteError, match="not a tty"):
        open_remote(f"serial://{ROOT / 'README.md'}?baud=9600")


# --- a pseudo-terminal pair --------------------------------------------------------------------------------
@contextmanager
def _pty() -> Iterator[tuple[int, str]]:
    """The master fd (the server's end) and the slave's path (the client's), raw from the start."""
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        yield master, os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.quick
def test_frames_cross_a_pty_pair_with_garbage_between() -> None:
    with _pty() as (master, path):
        server, client = SerialLink.from_fd(master), SerialLink.open(path, 115200)
        try:
            assert client.recv(0.05) is None  # silence: a bounded wait, no frame
            os.write(master, b"\x00\xff\xa5garbage")  # noise on the line before the frame
            server.send(SAMPLE)
            assert client.recv(2.0) == (SAMPLE, SERIAL_PEER)
            client.send(COMMAND)
            assert server.recv(2.0) == (COMMAND, SERIAL_PEER)
            assert client.counts.garbage_bytes == 10 and client.counts.frames == 1
        finally:
            client.close()


def _build(name: str, params: Parameters) -> Controller:
    c = registry.make(name, params)
    assert isinstance(c, Controller)
    return c


def _served_over_pty(settings: SessionSettings, name: str) -> tuple[SessionResult, RunLog]:
    """A lock-step session: the server on the master end (a thread), RemoteRig on the slave's path."""
    with _pty() as (master, path):
        return _serve_on(SerialLink.from_fd(master), path, settings, name)


def _serve_on(
    link: SerialLink, client_path: str, settings: SessionSettings, name: str
) -> tuple[SessionResult, RunLog]:
    """The server on ``link`` (a thread), RemoteRig on the tty at ``client_path``."""
    server = Server(settings, log=lambda _: None, link=link)
    with in_thread(server) as box:
        with open_remote(f"serial://{client_path}?baud=115200") as rig:
            assert rig.url == f"serial://{client_path}?baud=115200"
            run = run_on_rig(_build(name, rig.parameters()), rig)
    served = session_of(box)
    assert run.ended == "last sample"
    return served, run.log


def _lockstep_case(name: str, start: int, seed: int, duration_s: float) -> None:
    x0, th0 = STARTS[start]
    settings = SessionSettings(x0_m=x0, theta0_rad=th0, seed=seed, duration_s=duration_s, wait_client_s=10.0)
    served, client_log = _served_over_pty(settings, name)
    ref = run_closed_loop(
        _build(name, Parameters()), x0_m=x0, theta0_rad=th0, duration_s=duration_s, seed=seed
    )
    assert served.stop_reason in (p.STOP_DONE, p.STOP_BALL_LOST)
    assert served.counts.malformed == 0 and served.counts.stale_commands <= served.counts.resent_samples
    assert served.result.log.timem.size == ref.log.timem.size > 100
    _check_equal(ref, served, client_log)


@pytest.mark.quick
def test_lockstep_over_a_pty_equals_the_in_process_run() -> None:
    _lockstep_case("appendix-sf", 0, 0, 3.0)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "start"),
    [(name, i) for name in ("appendix-sf", "appendix-clp", "lqr") for i in range(len(STARTS))],
)
def test_lockstep_over_a_pty_from_the_hardware_starts(name: str, start: int) -> None:
    _lockstep_case(name, start, 0, 15.0)


def _bridge(a: int, b: int, stop: threading.Event, noise: list[bytes] | None = None) -> None:
    """Copy bytes both ways between two pty masters: a null-modem cable between two processes' ttys;
    with ``noise``, one of its pieces is written into the line every 40th chunk (inside a frame if a
    chunk boundary falls there)."""
    chunks = 0
    while not stop.is_set():
        ready, _, _ = select.select([a, b], [], [], 0.05)
        for fd in ready:
            try:
                data = os.read(fd, 4096)
                chunks += 1
                if noise and chunks % 40 == 0:
                    cut = len(data) // 2
                    data = data[:cut] + noise[(chunks // 40) % len(noise)] + data[cut:]
                os.write(b if fd == a else a, data)
            except OSError:
                pass  # a side that closed its tty: the processes' own timeouts handle it


def test_line_noise_during_a_session_changes_nothing_in_it() -> None:
    """Noise on the line (random bytes, a false sync and magic, a cut frame) between the two ttys: the
    readers resync, a frame hit by it is dropped and repeated (lock-step's 0.2 s repeat), and the session
    still equals the in-process run bit for bit."""
    rng = random.Random(0)
    x0, th0 = STARTS[1]
    settings = SessionSettings(x0_m=x0, theta0_rad=th0, seed=0, duration_s=2.0, wait_client_s=10.0)
    noise = [
        bytes(rng.randrange(256) for _ in range(40)),
        SYNC + p.MAGIC + b"\x01\x03\x38\x00",
        SYNC + SAMPLE[:30],
    ]
    stop = threading.Event()
    with _pty() as (master_a, path_a), _pty() as (master_b, path_b):
        bridge = threading.Thread(target=_bridge, args=(master_a, master_b, stop, noise), daemon=True)
        bridge.start()
        try:
            server_link = SerialLink.open(path_a, 115200)
            try:
                served, client_log = _serve_on(server_link, path_b, settings, "appendix-sf")
            finally:
                server_link.close()
        finally:
            stop.set()
            bridge.join(5.0)
    ref = run_closed_loop(
        _build("appendix-sf", Parameters()), x0_m=x0, theta0_rad=th0, duration_s=2.0, seed=0
    )
    assert served.counts.resent_samples >= 1  # some frames were hit and had to be repeated
    assert server_link.counts.resyncs >= 1 and server_link.counts.frames > 100
    _check_equal(ref, served, client_log)


def test_serve_serial_and_run_rig_serial_on_the_command_line(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cli = [sys.executable, "-m", "twin.app.cli"]
    stop = threading.Event()
    with _pty() as (master_a, path_a), _pty() as (master_b, path_b):
        bridge = threading.Thread(target=_bridge, args=(master_a, master_b, stop), daemon=True)
        bridge.start()
        try:
            serve = subprocess.Popen(
                [*cli, "serve", "--serial", path_a, "--baud", "115200", "--x0", "0.14", "--theta0", "-0.2"]
                + ["--duration", "2", "--wait-client", "30", "--json"],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                env=env,
            )
            assert serve.stdout is not None
            first = json.loads(serve.stdout.readline())  # --json: JSON lines, the address first
            assert first == {"serving_on": f"serial://{path_a}?baud=115200"}, first
            run = subprocess.run(
                [
                    *cli,
                    "run",
                    "--rig",
                    f"serial://{path_b}?baud=115200",
                    "--controller",
                    "appendix-sf",
                    "--json",
                ],
                capture_output=True,
                text=True,
                env=env,
                timeout=60,
            )
            out, err = serve.communicate(timeout=60)
        finally:
            stop.set()
            bridge.join(5.0)
    summary = json.loads(out)
    ref = run_closed_loop(_build("appendix-sf", Parameters()), x0_m=0.14, theta0_rad=-0.2, duration_s=2.0)
    assert summary["stop"] == "done" and summary["held"] == ref.verdict.held
    assert serve.returncode == (0 if ref.verdict.held else 1), err
    line = summary["serial"]  # a clean line: every frame (HELLO, one COMMAND a tick) and nothing thrown away
    assert line["frames"] >= ref.log.timem.size + 1 and line["garbage_bytes"] == line["crc_errors"] == 0
    client = json.loads(run.stdout)
    assert client["ticks"] == ref.log.timem.size
    assert run.returncode == (0 if client["held"] else 1), run.stderr


def test_bad_serial_options_are_one_line_errors() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cli = [sys.executable, "-m", "twin.app.cli"]
    serve = subprocess.run(
        [*cli, "serve", "--serial", "/nonexistent/tty", "--x0", "0.1", "--theta0", "0"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert serve.returncode == 2 and "cannot open /nonexistent/tty" in serve.stderr
    assert "Traceback" not in serve.stderr and len(serve.stderr.strip().splitlines()) == 1
    both = subprocess.run(
        [*cli, "serve", "--serial", "/dev/null", "--port", "5750", "--x0", "0.1", "--theta0", "0"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert both.returncode == 2 and "--serial replaces --host and --port" in both.stderr
    run = subprocess.run(
        [*cli, "run", "--rig", "serial:///dev/null?baud=7", "--controller", "appendix-sf"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert run.returncode == 2 and "baud 7" in run.stderr and "Traceback" not in run.stderr


def _check_equal(ref: RunResult, served: SessionResult, client: RunLog) -> None:
    def same(a: np.ndarray, b: np.ndarray) -> bool:
        return a.shape == b.shape and a.tobytes() == b.tobytes()  # bit for bit (NaN patterns included)

    for name in THESIS_FIELDS + TRUTH_FIELDS:
        ours, theirs = getattr(ref.log, name), getattr(served.result.log, name)
        if name in TELEMETRY:
            assert np.isnan(theirs).all() and theirs.size == ours.size, name
        else:
            assert same(ours, theirs), f"server log {name}"
    for name in THESIS_FIELDS:
        assert same(getattr(ref.log, name), getattr(client, name)), f"client log {name}"
    assert served.result.verdict == ref.verdict


@pytest.mark.quick
def test_baud_without_serial_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    from twin.app.cli import main

    rc = main(["serve", "--x0", "0.1", "--theta0", "0", "--baud", "9600"])
    err = capsys.readouterr().err
    assert rc == 2 and "--baud" in err and "--serial" in err and len(err.strip().splitlines()) == 1


@pytest.mark.realtime
def test_real_time_over_a_pty_keeps_the_period_and_reports_the_timing() -> None:
    """Real time over the serial line: the server paces the ticks by the wall clock, the client's timing is
    reported as over UDP, and a session whose every command came in time is the in-process run."""
    x0, th0 = STARTS[0]
    duration_s = 2.0
    settings = SessionSettings(
        x0_m=x0, theta0_rad=th0, duration_s=duration_s, wait_client_s=10.0, mode=p.MODE_REALTIME
    )
    with _pty() as (master, path):
        server = Server(settings, log=lambda _: None, link=SerialLink.from_fd(master))
        began = time.perf_counter()
        with in_thread(server) as box, open_remote(f"serial://{path}?baud=115200") as rig:
            assert rig.config.mode == p.MODE_REALTIME
            run = run_on_rig(_build("appendix-sf", rig.parameters()), rig)
        wall_s = time.perf_counter() - began
    served = session_of(box)
    n = served.result.log.timem.size
    period_s = settings.params.daq.period_s
    assert (
        run.ended == "last sample" and run.log.timem.size == n == update_ticks(duration_s, Parameters()) + 1
    )
    assert wall_s > (n - 2) * period_s  # paced by the wall clock, not as fast as the line goes
    assert served.timing is not None and served.timing.ticks == n - 1
    assert run.timing is not None and run.timing.ticks == n - 1
    assert abs(run.timing.jitter_p50_ms) < run.timing.period_ms
    c = served.counts
    assert c.late_commands <= c.missing_commands and c.watchdog_trips == 0 and c.malformed == 0
    if c.missing_commands == 0:  # every command in time: the same run as in one process
        ref = run_closed_loop(
            _build("appendix-sf", Parameters()), x0_m=x0, theta0_rad=th0, duration_s=duration_s
        )
        assert np.array_equal(ref.log.aout[:-1], served.result.log.aout[:-1])  # the last is not awaited
        assert np.array_equal(ref.log.true_x_m, served.result.log.true_x_m)
