"""The rig over the wire: a lock-step session served on UDP equals the in-process run bit for bit; the
server survives hostile input, a vanished client and a second client; the watchdog zeroes the output; a
vanished server is a bounded error on the client side."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import random
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from serving import answer, in_thread, session_of

from controllers import registry
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.converters import ball_position_m, beam_angle_rad, clip_command_v, dac_command_v
from twin.engine import RunResult, run_on_rig, update_ticks
from twin.interface import Controller, DaqSample
from twin.log import THESIS_FIELDS, TRUTH_FIELDS, RunLog
from twin.parameters import Parameters
from twin.rigs.remote import RemoteError, RemoteRig
from twin.rigs.sim import run_closed_loop
from twin.serving.server import ServeError, Server, SessionResult, SessionSettings
from twin.wire import protocol as p

ROOT = Path(__file__).resolve().parents[1]
STARTS = list(HARDWARE_STARTS.values())
TELEMETRY = ("x1", "x2", "x3", "x4", "u", "uhesap")  # the controller's own values: they do not travel


class UserPD(Controller):
    """A user's controller (not in the registry): a cascade PD on the software-calibrated volts."""

    name = "user-pd"

    def __init__(self, params: Parameters) -> None:
        super().__init__()
        self.sw = params.software
        self.period_s = params.daq.period_s
        self.prev = (0.0, 0.0)

    def _measure(self, sample: DaqSample) -> tuple[float, float]:
        return ball_position_m(sample.ball_v, self.sw), beam_angle_rad(sample.angle_v, self.sw)

    def start(self, sample: DaqSample) -> None:
        self.prev = self._measure(sample)

    def update(self, sample: DaqSample) -> float:
        x, th = self._measure(sample)
        xd, thd = (x - self.prev[0]) / self.period_s, (th - self.prev[1]) / self.period_s
        self.prev = (x, th)
        th_ref = -1.2 * x - 0.9 * xd
        volts = 25.0 * (th_ref - th) - 1.5 * thd
        self.telemetry.estimate = np.array([x, th, xd, thd])
        self.telemetry.u = self.telemetry.u_computed = volts
        return float(clip_command_v(dac_command_v(volts, self.sw), self.sw))


def _build(name: str, params: Parameters) -> Controller:
    c = UserPD(params) if name == "user" else registry.make(name, params)
    assert isinstance(c, Controller)
    return c


@contextmanager
def _serving(settings: SessionSettings, **kw: object) -> Iterator[tuple[Server, dict[str, object]]]:
    """A server in a thread on a free loopback port; ``box["session"]`` (or ``box["error"]``) when done."""
    server = Server(settings, "127.0.0.1", 0, log=lambda _: None, **kw)  # type: ignore[arg-type]
    with in_thread(server) as box:
        yield server, box


_session = session_of


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()  # bit for bit (NaN patterns included)


def _check_equal(ref: RunResult, served: SessionResult, client: RunLog) -> None:
    for name in THESIS_FIELDS + TRUTH_FIELDS:
        ours, theirs = getattr(ref.log, name), getattr(served.result.log, name)
        if name in TELEMETRY:
            assert np.isnan(theirs).all() and theirs.size == ours.size, name
        else:
            assert _same(ours, theirs), f"server log {name}"
    for name in THESIS_FIELDS:
        assert _same(getattr(ref.log, name), getattr(client, name)), f"client log {name}"
    assert served.result.verdict == ref.verdict


def _lockstep_case(name: str, x0: float, th0: float, seed: int, duration_s: float) -> None:
    params = Parameters()
    settings = SessionSettings(x0_m=x0, theta0_rad=th0, seed=seed, duration_s=duration_s, wait_client_s=10.0)
    with _serving(settings) as (server, box), RemoteRig("127.0.0.1", server.port) as rig:
        assert rig.software == params.software
        run = run_on_rig(_build(name, rig.parameters()), rig)
    served = _session(box)
    ref = run_closed_loop(_build(name, params), x0_m=x0, theta0_rad=th0, duration_s=duration_s, seed=seed)
    assert run.ended == "last sample"
    assert served.stop_reason in (p.STOP_DONE, p.STOP_BALL_LOST)
    c = served.counts
    assert (
        c.malformed == 0 and c.stale_commands <= c.resent_samples
    )  # a stale one answers a repeat (slow start)
    _check_equal(ref, served, run.log)


@pytest.mark.quick
def test_lockstep_session_equals_the_in_process_run() -> None:
    x0, th0 = STARTS[0]
    _lockstep_case("appendix-sf", x0, th0, 0, 5.0)


_CASES = [
    (name, i, seed)
    for name in ("appendix-sf", "appendix-clp", "lqr", "user")
    for i in range(len(STARTS))
    for seed in range(3)
    if (name, i, seed) != ("appendix-sf", 0, 0)
]


@pytest.mark.slow
@pytest.mark.parametrize(("name", "start", "seed"), _CASES)
def test_lockstep_equality_from_the_hardware_starts(name: str, start: int, seed: int) -> None:
    x0, th0 = STARTS[start]
    _lockstep_case(name, x0, th0, seed, 10.0)


class RawClient:
    """A client at the socket level, to send what a well-behaved RemoteRig never would."""

    def __init__(self, port: int, role: int = p.ROLE_CONTROL) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect(("127.0.0.1", port))
        self.sock.settimeout(5.0)
        self.sock.send(p.encode(p.Hello(role=role, client="raw"), 0))
        frame = self.recv()
        assert isinstance(frame.msg, p.Config)
        self.config, self.session = frame.msg, frame.session

    def recv(self) -> p.Frame:
        return p.decode_frame(self.sock.recv(4096))

    def send(self, msg: p.Message, session: int | None = None) -> None:
        self.sock.send(p.encode(msg, self.session if session is None else session))

    def close(self) -> None:
        self.sock.close()


def _junk(rng: random.Random, session: int, seq: int) -> list[bytes]:
    """One of each kind of refused datagram (malformed, other session, replay, out of range, NaN)."""
    good = p.encode(p.Command(seq, 2.5), session)
    bad_crc = bytearray(good)
    bad_crc[20] ^= 0x40
    return [
        bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 300))),  # noise
        good[: rng.randrange(0, 32)],  # truncated
        good + bytes(rng.randrange(1, 2000)),  # oversized
        bytes(bad_crc),
        p.encode(p.Command(seq, 2.5), session ^ 0x5A5A),  # another session
        p.encode(p.Command(max(seq - 1, 0) if seq else seq + 7, 4.0), session),  # replay / out of order
        p.encode(p.Command(seq, math.nan), session),  # refused value
        p.encode(p.Command(seq, 7.5), session),  # out of the DAC's range
    ]


@pytest.mark.quick
def test_hostile_datagrams_are_counted_and_change_nothing() -> None:
    x0, th0 = STARTS[1]
    settings = SessionSettings(x0_m=x0, theta0_rad=th0, seed=2, duration_s=2.0, wait_client_s=10.0)
    rng = random.Random(18)
    sent = {"malformed": 0, "wrong_session": 0, "stale": 0, "refused": 0, "unauthorised": 0}
    controller = _build("appendix-sf", Parameters())
    with _serving(settings) as (server, box):
        raw = RawClient(server.port)
        observer = RawClient(server.port, role=p.ROLE_OBSERVE)
        assert observer.config.role == p.ROLE_OBSERVE
        stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        stranger.connect(("127.0.0.1", server.port))
        seen: dict[int, p.Sample] = {}
        answers: dict[int, float] = {}
        n_junk = 0
        while True:
            frame = raw.recv()
            msg = frame.msg
            if isinstance(msg, p.Stop):
                break
            assert isinstance(msg, p.Sample)
            seen[msg.seq] = msg
            command = answer(controller, msg)
            if n_junk < 200:
                kinds = _junk(rng, raw.session, msg.seq)
                for i, data in enumerate(kinds):
                    if msg.seq == 0 and i == 5:
                        continue  # no earlier sample to replay
                    raw.sock.send(data)
                    key = ("malformed",) * 4 + ("wrong_session", "stale", "refused", "refused")
                    sent[key[i]] += 1
                    n_junk += 1
                observer.send(p.Command(msg.seq, 2.5))  # an observer may not command
                stranger.send(p.encode(p.Command(msg.seq, 2.5), raw.session))  # nor a stranger
                sent["unauthorised"] += 2
                n_junk += 2
            raw.send(p.Command(msg.seq, command))
            answers[msg.seq] = command
            if msg.flags & p.FLAG_LAST:
                assert raw.recv().msg == p.Stop(p.STOP_DONE)
                break
        observed: list[p.Sample] = []  # a copy of every sample since the observer joined, then STOP
        echoed: list[p.Command] = []  # and of every command the server accepted (the junk none)
        while not isinstance(got := observer.recv().msg, p.Stop):
            if isinstance(got, p.Command):
                echoed.append(got)
            else:
                assert isinstance(got, p.Sample)
                observed.append(got)
        for s in (raw, observer):
            s.close()
        stranger.close()
    served = _session(box)
    c = served.counts
    assert n_junk >= 200
    assert (c.malformed, c.wrong_session, c.stale_commands, c.refused_commands, c.unauthorised_commands) == (
        sent["malformed"],
        sent["wrong_session"],
        sent["stale"],
        sent["refused"],
        sent["unauthorised"],
    )
    assert c.observers == 1
    assert observed and observed == [seen[k] for k in range(observed[0].seq, len(seen))]
    assert echoed and echoed == [p.Command(k, answers[k]) for k in range(echoed[0].seq, len(seen))]
    ref = run_closed_loop(
        _build("appendix-sf", Parameters()), x0_m=x0, theta0_rad=th0, duration_s=2.0, seed=2
    )
    for name in THESIS_FIELDS[:4] + TRUTH_FIELDS:  # the state is what refused input left alone
        assert _same(getattr(ref.log, name), getattr(served.result.log, name)), name
    assert served.result.verdict == ref.verdict


@pytest.mark.quick
def test_a_second_controlling_client_is_refused() -> None:
    settings = SessionSettings(x0_m=0.1, theta0_rad=0.0, duration_s=0.5, wait_client_s=10.0)
    with _serving(settings) as (server, box), RemoteRig("127.0.0.1", server.port) as rig:
        with pytest.raises(RemoteError, match="refused"):
            RemoteRig("127.0.0.1", server.port, connect_timeout_s=2.0)
        run_on_rig(_build("appendix-sf", rig.parameters()), rig)
    assert _session(box).counts.refused_clients == 1


@pytest.mark.realtime
def test_a_client_that_disappears_ends_the_session_within_the_timeout() -> None:
    settings = SessionSettings(x0_m=0.1, theta0_rad=0.0, duration_s=5.0, wait_client_s=10.0, timeout_s=0.3)
    with _serving(settings) as (server, box):
        raw = RawClient(server.port)
        for _ in range(4):  # answer the held sample and three ticks, then vanish
            msg = raw.recv().msg
            assert isinstance(msg, p.Sample)
            raw.send(p.Command(msg.seq, 2.5))
        began = time.monotonic()
        raw.close()
    served = _session(box)
    assert time.monotonic() - began < 2.0
    assert served.stop_reason == p.STOP_ERROR and "no COMMAND 4 within 0.3 s" in served.stop_detail
    assert served.result.log.timem.size == 4  # the held block and three ticks were logged


@pytest.mark.quick
def test_a_client_stop_ends_the_session() -> None:
    settings = SessionSettings(x0_m=0.1, theta0_rad=0.0, duration_s=5.0, wait_client_s=10.0)
    with _serving(settings) as (server, box), RemoteRig("127.0.0.1", server.port) as rig:
        rig.read()
        rig.read()
        rig.stop()
    assert _session(box).stop_reason == p.STOP_CLIENT_QUIT


@pytest.mark.realtime
def test_a_server_that_disappears_is_a_bounded_error() -> None:
    settings = SessionSettings(x0_m=0.1, theta0_rad=0.0, duration_s=5.0, wait_client_s=10.0, timeout_s=0.2)
    with pytest.raises(ServeError, match="ended before"), _serving(settings) as (server, _box):
        rig = RemoteRig("127.0.0.1", server.port, timeout_s=0.5)
        rig.read()
        server.sock.close()  # the server's socket is gone: no more samples, no STOP
        began = time.monotonic()
        with pytest.raises(
            RemoteError, match=r"no SAMPLE \d+ from udp://\S+ for 0\.\d s \(timeout_s 0\.5 s\)"
        ):
            rig.read()
        assert time.monotonic() - began < 1.5
        rig.close()


@pytest.mark.realtime
def test_no_server_is_a_bounded_error() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # a port nobody answers on (bound, silent)
        began = time.monotonic()
        with pytest.raises(RemoteError, match="no CONFIG"):
            RemoteRig("127.0.0.1", port, connect_timeout_s=0.6)
        assert time.monotonic() - began < 1.5


@pytest.mark.realtime
def test_watchdog_zeroes_the_output_in_real_time() -> None:
    periods = 3
    settings = SessionSettings(
        x0_m=0.05,
        theta0_rad=0.0,
        duration_s=1.0,
        wait_client_s=10.0,
        mode=p.MODE_REALTIME,
        watchdog_periods=periods,
    )
    answered = 10
    with _serving(settings) as (server, box):
        raw = RawClient(server.port)
        assert raw.config.mode == p.MODE_REALTIME and raw.config.watchdog_periods == periods
        samples: list[p.Sample] = []
        while True:
            msg = raw.recv().msg
            if isinstance(msg, p.Stop):
                break
            assert isinstance(msg, p.Sample)
            samples.append(msg)
            if msg.seq <= answered:
                raw.send(p.Command(msg.seq, 3.0))  # a steady command, then the controller dies
        raw.close()
    served = _session(box)
    c = served.counts
    flagged = [s.seq for s in samples if s.flags & p.FLAG_WATCHDOG]
    assert flagged and flagged[0] == answered + 1 + periods  # the first sample after `periods` silent ones
    assert c.watchdog_trips == 1 and c.missing_commands == len(samples) - 1 - answered - 1  # last: no answer
    aout = served.result.log.aout
    assert np.all(aout[answered + 1 : answered + periods] == 3.0)  # the DAC holds meanwhile
    assert np.all(aout[answered + periods :] == Parameters().amplifier.zero_command_v)
    assert served.timing is not None and served.timing.ticks == len(samples) - 1


def test_serve_and_run_rig_on_the_command_line(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cli = [sys.executable, "-m", "twin.app.cli"]
    serve = subprocess.Popen(
        [
            *cli,
            "serve",
            "--x0",
            "0.14",
            "--theta0",
            "-0.2",
            "--duration",
            "3",
            "--wait-client",
            "30",
            "--json",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert serve.stdout is not None
    first = json.loads(serve.stdout.readline())  # --json: stdout is JSON lines, the address first
    assert list(first) == ["serving_on"] and first["serving_on"].startswith("udp://127.0.0.1:")
    url = first["serving_on"]
    log = tmp_path / "client.csv"
    run = subprocess.run(
        [*cli, "run", "--rig", url, "--controller", "appendix-sf", "--log", str(log), "--json"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    out, err = serve.communicate(timeout=60)
    summary = json.loads(out)
    ref = run_closed_loop(_build("appendix-sf", Parameters()), x0_m=0.14, theta0_rad=-0.2, duration_s=3.0)
    assert summary["stop"] == "done" and summary["held"] == ref.verdict.held
    assert serve.returncode == (0 if ref.verdict.held else 1), err
    client = json.loads(run.stdout)
    assert client["ticks"] == ref.log.timem.size
    # the client judges what it measured: the same answer as the true state's here, and its exit code
    assert client["held"] == ref.verdict.held and not client["ball_lost"]
    assert run.returncode == (0 if client["held"] else 1), run.stderr
    assert log.exists()


@pytest.mark.quick
def test_a_reconnect_gets_a_new_session_and_the_old_ones_datagrams_are_dropped() -> None:
    settings = SessionSettings(x0_m=0.1, theta0_rad=0.0, duration_s=0.3, wait_client_s=10.0)
    server = Server(settings, log=lambda _: None)
    sessions: list[SessionResult] = []
    thread = threading.Thread(target=lambda: sessions.extend([server.serve(), server.serve()]), daemon=True)
    thread.start()
    ids = []
    for _ in range(2):
        with RemoteRig("127.0.0.1", server.port) as rig:
            ids.append(rig.session)
            if len(ids) == 2:
                rig.sock.send(p.encode(p.Command(1, 2.5), ids[0]))  # a late datagram of the first session
            run = run_on_rig(_build("appendix-sf", rig.parameters()), rig)
            assert run.ended == "last sample"
    thread.join(10.0)
    server.close()
    assert ids[0] != ids[1]
    assert [s.stop_reason for s in sessions] == [p.STOP_DONE, p.STOP_DONE]
    assert sessions[1].counts.wrong_session == 1
    assert _same(
        sessions[0].result.log.true_x_m, sessions[1].result.log.true_x_m
    )  # the same seed, the same run


@pytest.mark.realtime
def test_real_time_session_reports_the_client_timing() -> None:
    x0, th0 = STARTS[0]
    settings = SessionSettings(
        x0_m=x0, theta0_rad=th0, duration_s=1.0, wait_client_s=10.0, mode=p.MODE_REALTIME
    )
    began = time.perf_counter()
    with _serving(settings) as (server, box), RemoteRig("127.0.0.1", server.port) as rig:
        run = run_on_rig(_build("appendix-sf", rig.parameters()), rig)
    wall_s = time.perf_counter() - began
    served = _session(box)
    n = served.result.log.timem.size
    assert run.ended == "last sample" and run.log.timem.size == n
    assert run.timing is not None and run.timing.ticks == n - 1
    assert abs(run.timing.jitter_p50_ms) < run.timing.period_ms  # the samples came at the period
    assert wall_s > (n - 2) * settings.params.daq.period_s  # paced by the wall clock, not as fast as possible
    c = served.counts
    assert c.late_commands <= c.missing_commands and c.watchdog_trips == 0
    if c.missing_commands == 0:  # every command in time: the same run as in one process
        ref = run_closed_loop(_build("appendix-sf", Parameters()), x0_m=x0, theta0_rad=th0, duration_s=1.0)
        assert _same(ref.log.aout[:-1], served.result.log.aout[:-1])  # the last is not awaited in real time
        assert _same(ref.log.true_x_m, served.result.log.true_x_m)


_FLOODER = """
import random, socket, sys, time
port, seconds = int(sys.argv[1]), float(sys.argv[2])
rng = random.Random(7)
sent = 0
with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
    s.connect(("127.0.0.1", port))
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            s.send(rng.randbytes(rng.choice((0, 16, 24, 32, 56, 200, 1500))))
            sent += 1
        except OSError:
            time.sleep(0.0005)  # the server's receive buffer is full: the flood is bounded there
print(sent)
"""


class _Paced(Controller):
    """A controller answering at the rig's own pace (one block per period of wall clock), as a client on a
    target would: a lock-step session that lasts as long as its simulated time."""

    def __init__(self, inner: Controller, period_s: float) -> None:
        super().__init__()
        self.inner, self.period_s, self.name = inner, period_s, inner.name
        self._t0 = 0.0
        self._k = 0

    def start(self, sample: DaqSample) -> None:
        self.inner.start(sample)
        self.telemetry = self.inner.telemetry
        self._t0, self._k = time.monotonic(), 0

    def update(self, sample: DaqSample) -> float:
        self._k += 1
        time.sleep(max(0.0, self._t0 + self._k * self.period_s - time.monotonic()))
        command = self.inner.update(sample)
        self.telemetry = self.inner.telemetry  # the law may hand over a new record each tick
        return command


@pytest.mark.slow
def test_a_ten_second_flood_leaves_the_session_alive_and_its_state_unchanged() -> None:
    """A 10 s flood of random datagrams from another process at a lock-step session paced at 50 Hz: the
    session ticks through it, every refused datagram is counted, a sample or command the full buffer lost
    is repeated, and the session equals the in-process run bit for bit."""
    x0, th0 = STARTS[2]
    duration_s, flood_s = 12.0, 10.0
    settings = SessionSettings(x0_m=x0, theta0_rad=th0, seed=1, duration_s=duration_s, wait_client_s=10.0)
    with _serving(settings) as (server, box):
        with RemoteRig("127.0.0.1", server.port) as rig:
            flooder = subprocess.Popen(
                [sys.executable, "-c", _FLOODER, str(server.port), str(flood_s)],
                stdout=subprocess.PIPE,
                text=True,
            )
            began = time.monotonic()
            run = run_on_rig(_Paced(_build("appendix-clp", rig.parameters()), rig.period_s), rig)
            wall_s = time.monotonic() - began
        out, _ = flooder.communicate(timeout=30)
    flooded = int(out)
    served = _session(box)
    c = served.counts
    print(
        f"\n{flood_s:g} s flood: {flooded} datagrams sent; the server received {c.frames} frames, "
        f"{c.malformed} malformed, {c.wrong_session} of no session, repeated {c.resent_samples} samples; "
        f"session of {served.result.log.timem.size} ticks in {wall_s:.1f} s wall, ended: {run.ended}"
    )
    assert run.ended == "last sample" and wall_s > flood_s  # the flood lasted through the session
    assert flooded > 10_000 and c.malformed + c.wrong_session > 1_000
    assert c.frames == c.malformed + c.wrong_session + served.result.log.timem.size + 1 + c.stale_commands
    ref = run_closed_loop(
        _build("appendix-clp", Parameters()), x0_m=x0, theta0_rad=th0, duration_s=duration_s, seed=1
    )
    _check_equal(ref, served, run.log)


def test_binding_beyond_loopback_warns_and_loopback_does_not() -> None:
    lines: list[str] = []
    with Server(SessionSettings(), "127.0.0.1", 0, log=lines.append):
        assert lines == []
    with Server(SessionSettings(), "0.0.0.0", 0, log=lines.append) as server:
        assert lines == [
            f"warning: serving on every interface (port {server.port}): anyone who can reach this machine "
            "there can drive the twin — there is no authentication. Serve on 127.0.0.1 (the default) unless "
            "that is what you want."
        ]


def _until_sample(raw: RawClient) -> p.Sample:
    """The next SAMPLE (an echo or anything else skipped)."""
    while not isinstance(msg := raw.recv().msg, p.Sample):
        assert not isinstance(msg, p.Stop), msg
    return msg


@pytest.mark.realtime  # told within 1 s of wall time, before the 3 s timeout
def test_a_refused_command_is_told_at_once_and_counted() -> None:
    """Lock-step: NaN answering SAMPLE 3 gets SAMPLE 3 again with the refused flag at its 0.2 s repeat (not
    a timeout); a valid answer then goes on, and the summary counts the refusal."""
    settings = SessionSettings(x0_m=0.1, theta0_rad=0.0, duration_s=0.3, wait_client_s=10.0, timeout_s=3.0)
    with _serving(settings) as (server, box):
        raw = RawClient(server.port)
        refused_at = 3
        told: p.Sample | None = None
        while True:
            msg = raw.recv().msg
            if isinstance(msg, p.Stop):
                break
            assert isinstance(msg, p.Sample)
            if msg.seq == refused_at and told is None:
                assert not msg.flags & p.FLAG_REFUSED
                raw.send(p.Command(msg.seq, math.nan))
                began = time.monotonic()
                told = _until_sample(raw)
                waited = time.monotonic() - began
                assert told == dataclasses.replace(msg, flags=msg.flags | p.FLAG_REFUSED)  # the same block
                assert waited < 1.0  # told, not timed out (3 s)
            else:
                assert not msg.flags & p.FLAG_REFUSED
            raw.send(p.Command(msg.seq, 2.5))
        raw.close()
    served = _session(box)
    assert told is not None
    assert served.stop_reason == p.STOP_DONE
    assert served.counts.refused_commands == 1 and served.summary()["refused_commands"] == 1


def test_a_client_repeating_a_refused_command_gets_a_flagged_repeat_every_0_2_s() -> None:
    """A client written before the flag answers every repeat with its refused command: each repeat (0.2 s
    apart, no ping-pong) carries the flag, until the server's timeout ends the session."""
    settings = SessionSettings(x0_m=0.1, theta0_rad=0.0, duration_s=1.0, wait_client_s=10.0, timeout_s=0.7)
    with pytest.raises(ServeError, match="ended before"), _serving(settings) as (server, _box):
        raw = RawClient(server.port)
        first = raw.recv().msg
        assert isinstance(first, p.Sample) and first.seq == 0
        raw.send(p.Command(0, 7.5))  # out of the DAC's 0…5 V
        repeats = 0
        while not isinstance(msg := raw.recv().msg, p.Stop):
            assert isinstance(msg, p.Sample) and msg.seq == 0 and msg.flags & p.FLAG_REFUSED
            repeats += 1
            raw.send(p.Command(0, 7.5))
        raw.close()
        assert 1 <= repeats <= 0.7 / 0.2 + 1


@pytest.mark.realtime
def test_remote_rig_turns_the_refused_flag_into_an_error() -> None:
    """``RemoteRig`` against a rig that refuses its command: a ``RemoteError`` naming it, not a timeout."""
    rig_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rig_sock.bind(("127.0.0.1", 0))
    rig_sock.settimeout(5.0)
    config = p.Config.from_parameters(
        Parameters(), role=p.ROLE_CONTROL, mode=p.MODE_LOCKSTEP, watchdog_periods=5, rig="firmware"
    )
    sample = p.Sample(1, 0.02, 1.0, 2.0)

    def firmware() -> None:
        _, addr = rig_sock.recvfrom(4096)  # HELLO
        rig_sock.sendto(p.encode(config, 9), addr)
        rig_sock.sendto(p.encode(sample, 9), addr)
        rig_sock.recvfrom(4096)  # its COMMAND 1, refused
        rig_sock.sendto(p.encode(dataclasses.replace(sample, flags=p.FLAG_REFUSED), 9), addr)

    thread = threading.Thread(target=firmware, daemon=True)
    thread.start()
    with RemoteRig("127.0.0.1", rig_sock.getsockname()[1], timeout_s=3.0) as rig:
        rig.read()
        rig.write(4.0)
        began = time.monotonic()
        with pytest.raises(RemoteError, match="refused COMMAND 1"):
            rig.read()
        assert time.monotonic() - began < 2.0
    thread.join(5.0)
    rig_sock.close()


@pytest.mark.realtime
def test_a_dead_client_in_real_time_leaves_the_session_to_run_out_under_the_watchdog() -> None:
    """Real time: a client that vanishes does not end the session; it runs to its duration with the output
    at the zero command from the watchdog on, then STOP 0 (done)."""
    settings = SessionSettings(
        x0_m=0.05, duration_s=0.6, wait_client_s=10.0, mode=p.MODE_REALTIME, watchdog_periods=3
    )
    with _serving(settings) as (server, box):
        raw = RawClient(server.port)
        for _ in range(6):  # the held sample and five ticks answered, then the process is gone
            msg = _until_sample(raw)
            raw.send(p.Command(msg.seq, 3.0))
        raw.close()
    served = _session(box)
    log = served.result.log
    assert served.stop_reason == p.STOP_DONE
    assert log.timem.size == update_ticks(0.6, Parameters()) + 1  # every tick of the duration
    assert served.counts.watchdog_trips == 1
    assert np.all(log.aout[-5:] == Parameters().amplifier.zero_command_v)


@pytest.mark.realtime
def test_in_real_time_a_command_in_time_takes_effect_at_the_next_boundary() -> None:
    """Real time: the command answering SAMPLE k, received before the next period boundary however late in
    the period, is the DAC's value for the whole of block k+1 (SAMPLE k+1's ``applied_seq`` = k): with
    every command in time the run is the lock-step one."""
    x0, th0 = STARTS[0]
    settings = SessionSettings(
        x0_m=x0, theta0_rad=th0, duration_s=1.0, wait_client_s=10.0, mode=p.MODE_REALTIME
    )
    controller = _build("appendix-sf", Parameters())
    samples: list[p.Sample] = []
    with _serving(settings) as (server, box):
        raw = RawClient(server.port)
        while not isinstance(msg := raw.recv().msg, p.Stop):
            assert isinstance(msg, p.Sample)
            samples.append(msg)
            if msg.flags & p.FLAG_LAST:
                continue  # real time: the last sample is not answered
            command = answer(controller, msg)
            time.sleep(0.006)  # answer well into the period
            raw.send(p.Command(msg.seq, command))
        raw.close()
    served = _session(box)
    for before, after in zip(samples[1:], samples[2:], strict=False):
        if not after.flags & p.FLAG_LATE:  # the answer to `before` came in time
            assert after.applied_seq == before.seq
    if served.counts.missing_commands == 0:
        ref = run_closed_loop(_build("appendix-sf", Parameters()), x0_m=x0, theta0_rad=th0, duration_s=1.0)
        assert _same(ref.log.true_x_m, served.result.log.true_x_m)


@pytest.mark.quick
def test_stop_from_an_observer_is_ignored_and_a_repeated_hello_gets_config_again() -> None:
    settings = SessionSettings(x0_m=0.1, theta0_rad=0.0, duration_s=0.3, wait_client_s=10.0)
    with _serving(settings) as (server, box):
        observer = RawClient(server.port, role=p.ROLE_OBSERVE)
        raw = RawClient(server.port)
        raw.send(p.Hello(role=p.ROLE_OBSERVE, client="again"), 0)  # the controller's HELLO again, any role
        frames = [raw.recv(), raw.recv()]  # the held sample and CONFIG again, in either order
        configs = [f for f in frames if isinstance(f.msg, p.Config)]
        assert len(configs) == 1 and configs[0].session == raw.session
        assert configs[0].msg == raw.config  # the role first granted: control
        observer.send(p.Stop(p.STOP_CLIENT_QUIT))  # an observer may not end the session
        msg = next(f.msg for f in frames if isinstance(f.msg, p.Sample))
        while True:
            assert isinstance(msg, p.Sample)
            raw.send(p.Command(msg.seq, 2.5))
            if msg.flags & p.FLAG_LAST:
                break
            msg = _until_sample(raw)
        assert raw.recv().msg == p.Stop(p.STOP_DONE)
        raw.close()
        observer.close()
    served = _session(box)
    assert served.stop_reason == p.STOP_DONE and served.counts.unexpected == 1
