"""The live view driven over the wire (``ballbeam view --serve``), without a browser: a ``LiveTwin`` whose
controller is the wire client (twin.viewer.wire), ticked here frame by frame at the view's 50 Hz with each
frame's end as the command's deadline, and a client in a thread (``RemoteRig`` + ``appendix-sf``, or a raw
socket). The rig is held while no client came; the client balances the ball from a hardware start; Reset
ends its session with STOP 0; a silent client trips the watchdog after its periods; malformed datagrams are
counted and change nothing."""

from __future__ import annotations

import random
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest

from controllers import registry
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.engine import RunResult, run_on_rig
from twin.parameters import Parameters
from twin.rigs.remote import RemoteRig
from twin.rigs.sim import run_closed_loop
from twin.serving.server import Server, SessionSettings
from twin.viewer import FRAME_S, LiveTwin
from twin.viewer.common import _markdown_text
from twin.viewer.wire import WIRE_MARGIN_S, WireCatalogue, WireClient
from twin.wire import protocol as p

START = HARDWARE_STARTS["Fig 6.16 (state feedback)"]  # (0.14 m, −0.2 rad)


@contextmanager
def _wired(**settings: object) -> Iterator[tuple[LiveTwin, Server]]:
    """A live twin whose run is the wire client's, held at the first hardware start; the server closed after."""
    server = Server(
        SessionSettings(mode=p.MODE_REALTIME, **settings),  # type: ignore[arg-type]
        "127.0.0.1",
        0,
        log=lambda _: None,
    )
    try:
        catalogue = WireCatalogue(registry, server)
        live = LiveTwin(Parameters(), catalogue, catalogue.name, seed=0, speed=1.0)
        live.apply("initial", START)
        live.apply("reset")
        yield live, server
        live.close()
    finally:
        server.close()


def _wire(live: LiveTwin) -> WireClient:
    wire = live.wire
    assert wire is not None
    return wire


def _frames(live: LiveTwin, n: int) -> None:
    """``n`` frames of the view: the tick with the frame's end as its deadline, then the rest of the frame."""
    for _ in range(n):
        end = time.perf_counter() + FRAME_S
        live.tick(end - WIRE_MARGIN_S)
        left = end - time.perf_counter()
        if left > 0:
            time.sleep(left)


def _frames_until(live: LiveTwin, condition, limit: int = 250) -> int:  # type: ignore[no-untyped-def]
    for n in range(limit):
        if condition():
            return n
        _frames(live, 1)
    raise AssertionError("the condition did not come within the frames")


@contextmanager
def _python_client(port: int) -> Iterator[dict[str, RunResult]]:
    """``appendix-sf`` through ``RemoteRig`` in a thread (the ``run --rig`` path); its run after the block."""
    box: dict[str, RunResult] = {}

    def client() -> None:
        with RemoteRig("127.0.0.1", port, client="pytest appendix-sf") as rig:
            box["run"] = run_on_rig(registry.make("appendix-sf", rig.parameters()), rig)

    thread = threading.Thread(target=client, daemon=True)
    thread.start()
    yield box
    thread.join(10.0)
    assert not thread.is_alive(), "the client hung"


def test_the_rig_is_held_until_a_client_says_hello() -> None:
    with _wired() as (live, server):
        wire = _wire(live)
        before_t, before_state = live.rig.time_s, live.rig.true_state().copy()
        _frames(live, 25)  # half a second of frames, nobody on the wire
        assert wire.phase == "waiting" and live.running
        assert live.rig.time_s == before_t < 0.0  # time does not advance
        np.testing.assert_array_equal(live.rig.true_state(), before_state)
        np.testing.assert_array_equal(before_state, [*START, 0.0, 0.0])
        assert live.loop.log().k == 1  # the held block only
        assert _markdown_text(f"waiting for a client on {server.url}") in live.status_markdown()
        assert " · waiting for the wire client · " in live.status_markdown()  # not "running": the rig is held


@pytest.mark.realtime
def test_a_client_balances_the_ball_from_a_hardware_start_and_reset_stops_it() -> None:
    seconds = 3.0
    with _wired() as (live, server):
        wire = _wire(live)
        first_session = server.session
        with _python_client(server.port) as box:
            _frames_until(live, lambda: wire.released)
            assert server.client_name == "pytest appendix-sf"
            _frames(live, int(seconds / FRAME_S))
            c = server.counts
            assert live.rig.time_s > seconds - 0.2 and not live.rig.ball_lost
            assert wire.phase == "running" and c.malformed == 0 and c.refused_commands == 0
            assert c.missing_commands <= 3 and c.watchdog_trips == 0, c  # a loaded machine may miss one
            log = live.loop.log()
            x, theta = live.rig.true_state()[:2]
            assert abs(x) < 0.03 and abs(theta) < 0.05  # from (0.14 m, −0.2 rad): near the centre, level
            status = live.status_markdown()
            assert (
                f"client **{_markdown_text('pytest appendix-sf')}** at {_markdown_text('127.0.0.1:')}"
                in status
                and "· connected" in status
            )
            if c.missing_commands == 0:  # every command in time: the in-process run, bit for bit
                ref = run_closed_loop(
                    registry.make("appendix-sf"),
                    x0_m=START[0],
                    theta0_rad=START[1],
                    duration_s=seconds,
                    seed=0,
                )
                n = log.k
                assert _same(log.aout, ref.log.aout[:n]) and _same(log.true_x_m, ref.log.true_x_m[:n])
            live.apply("reset")  # the run is replaced: STOP 0 to the client
        assert box["run"].ended.endswith("ended the session (STOP 0)")
        assert box["run"].log.k == log.k  # the client answered every sample of the session
        assert server.session != first_session and wire.phase == "ended"
        assert _wire(live).phase == "waiting" and live.rig.time_s < 0.0  # the new run: held, a new session
        np.testing.assert_array_equal(live.rig.true_state()[:2], START)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


class RawClient:
    """A client at the socket level: HELLO, then what the test sends."""

    def __init__(self, port: int, role: int = p.ROLE_CONTROL) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect(("127.0.0.1", port))
        self.sock.settimeout(5.0)
        self.sock.send(p.encode(p.Hello(role=role, client="raw"), 0))

    def recv(self) -> p.Frame:
        return p.decode_frame(self.sock.recv(4096))

    def close(self) -> None:
        self.sock.close()


@pytest.mark.realtime
def test_a_silent_client_trips_the_watchdog_after_its_periods() -> None:
    periods, answered = 3, 10
    samples: list[p.Sample] = []
    with _wired(watchdog_periods=periods) as (live, server):
        raw = RawClient(server.port)
        raw.sock.settimeout(0.5)  # the client's thread ends soon after the last sample

        def client() -> None:  # acknowledges the held sample, answers 3.0 V up to `answered`, then dies
            config = raw.recv()
            assert isinstance(config.msg, p.Config) and config.msg.mode == p.MODE_REALTIME
            assert config.msg.watchdog_periods == periods
            while True:
                try:
                    frame = raw.recv()
                except OSError:
                    return
                if not isinstance(frame.msg, p.Sample):
                    return
                samples.append(frame.msg)
                if frame.msg.seq <= answered:
                    command = 2.5 if frame.msg.seq == 0 else 3.0
                    raw.sock.send(p.encode(p.Command(frame.msg.seq, command), config.session))

        thread = threading.Thread(target=client, daemon=True)
        thread.start()
        _frames_until(live, lambda: _wire(live).released)
        _frames(live, answered + 2 * periods + 2)
        raw.close()
        thread.join(5.0)
        c = server.counts
        aout = live.loop.log().aout
        zero = Parameters().amplifier.zero_command_v
        assert np.all(aout[1 : answered + periods] == 3.0), aout  # answered, then the DAC holds
        assert np.all(aout[answered + periods :] == zero), aout  # then the zero command
        flagged = [s.seq for s in samples if s.flags & p.FLAG_WATCHDOG]
        assert flagged and flagged[0] == answered + periods + 1  # the first sample after the trip
        assert c.watchdog_trips == 1 and c.missing_commands == live.loop.log().k - 1 - answered
        assert "watchdog trips 1 (output at zero now)" in live.status_markdown()


def test_malformed_datagrams_are_counted_and_change_nothing() -> None:
    rng = random.Random(5)
    with _wired() as (live, server):
        before_t, before_state = live.rig.time_s, live.rig.true_state().copy()
        junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        junk.connect(("127.0.0.1", server.port))
        good = p.encode(p.Command(0, 2.5), server.session)
        bad_crc = bytearray(good)
        bad_crc[20] ^= 0x01
        malformed = [
            *(bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 300))) for _ in range(40)),
            good[:17],
            good + bytes(100),
            bytes(bad_crc),
            b"",
        ]
        for data in malformed:
            junk.send(data)
        junk.send(p.encode(p.Command(0, 2.5), server.session ^ 0x77))  # another session's
        _frames(live, 10)
        c = server.counts
        assert (c.malformed, c.wrong_session) == (len(malformed), 1)
        assert _wire(live).phase == "waiting" and live.rig.time_s == before_t
        np.testing.assert_array_equal(live.rig.true_state(), before_state)
        assert f"malformed {len(malformed)} · refused 1" in live.status_markdown()

        # With a client on: its session goes on, a second controller is refused, an observer watches.
        with _python_client(server.port):
            _frames_until(live, lambda: _wire(live).released)
            observer = RawClient(server.port, role=p.ROLE_OBSERVE)
            second = RawClient(server.port)
            _frames(live, 10)
            for data in malformed:
                junk.send(data)
            _frames(live, 10)
            assert isinstance(observer.recv().msg, p.Config)
            assert isinstance(observer.recv().msg, (p.Sample, p.Command))  # a command: the echo
            assert second.recv().msg.role == p.ROLE_REFUSED  # type: ignore[union-attr]
            assert server.counts.malformed == 2 * len(malformed)  # the client joined the same session
            assert server.counts.refused_clients == 1 and len(server.observers) == 1
            assert not live.rig.ball_lost and live.error is None and _wire(live).phase == "running"
            live.apply("reset")
            stops = []
            for _ in range(50):
                frame = observer.recv()
                if isinstance(frame.msg, p.Stop):
                    stops.append(frame.msg.reason)
                    break
            assert stops == [p.STOP_DONE]  # the observers get the STOP too
        for s in (junk, observer.sock, second.sock):
            s.close()


def test_a_client_that_never_acknowledges_the_held_sample_gets_stop_3_and_a_new_session_waits() -> None:
    with _wired(timeout_s=0.3) as (live, server):
        raw = RawClient(server.port)
        _frames_until(live, lambda: _wire(live).phase == "held")
        session = server.session
        assert isinstance(raw.recv().msg, p.Config)
        held = raw.recv()
        assert isinstance(held.msg, p.Sample) and held.msg.seq == 0 and held.msg.flags & p.FLAG_HELD
        _frames_until(live, lambda: _wire(live).phase == "waiting")
        frames = []
        while not isinstance((frame := raw.recv()).msg, p.Stop):
            frames.append(frame.msg)
        assert frame.msg == p.Stop(p.STOP_ERROR) and frame.session == session
        assert frames and all(isinstance(m, p.Sample) and m.seq == 0 for m in frames)  # repeats every 0.2 s
        assert server.session != session and live.rig.time_s < 0.0
        assert _markdown_text("did not acknowledge the held sample within 0.3 s") in live.status_markdown()
        raw.close()


@pytest.mark.quick
def test_a_flick_and_the_noise_switch_act_on_the_wire_run() -> None:
    with _wired() as (live, server), _python_client(server.port):
        _frames_until(live, lambda: _wire(live).released)
        _frames(live, 5)
        xdot = float(live.rig.true_state()[2])
        live.apply("flick_right", 0.3)
        assert float(live.rig.true_state()[2]) - xdot == pytest.approx(0.3, abs=1e-9)
        live.apply("noise", False)
        assert not live.rig.noise_enabled and live.refused == 0
        _frames(live, 5)
        name, data = live.recording("csv")
        assert name.startswith("ballbeam_run2_wire-client-udp-127.0.0.1-") and name.endswith(".csv")
        assert data
        live.apply("reset")


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_view_serves_with_a_warning_beyond_loopback_and_stops_its_client_at_shutdown(
    capfd: pytest.CaptureFixture[str],
) -> None:
    from twin.viewer import serve

    udp = _free_port(socket.SOCK_DGRAM)
    box: dict[str, RunResult] = {}

    def client() -> None:  # repeats HELLO until the view listens, then runs until the view's STOP
        with RemoteRig("127.0.0.1", udp, client="pytest", connect_timeout_s=20.0) as rig:
            box["run"] = run_on_rig(registry.make("appendix-sf", rig.parameters()), rig)

    thread = threading.Thread(target=client, daemon=True)
    thread.start()
    stats = serve(
        registry,
        port=_free_port(socket.SOCK_STREAM),
        duration_s=2.5,
        wire=("0.0.0.0", udp),
        wait_for_client=False,  # no browser here: the run goes
    )
    thread.join(10.0)
    out, err = capfd.readouterr()
    assert f"warning: serving on every interface (port {udp}): anyone who can reach this machine" in err
    assert f"(controller wire client (udp://0.0.0.0:{udp}), speed ×1)" in out
    assert f"serving the twin on udp://0.0.0.0:{udp} (protocol 1, real time)" in out
    run = box["run"]
    assert run.ended.endswith("ended the session (STOP 4)")  # the view shut down
    assert run.log.k > 25 and stats["ticks"] >= run.log.k - 1


@pytest.mark.realtime
def test_a_stalled_client_never_slows_the_views_frames() -> None:
    """The client acknowledges the held sample and then says nothing: the view's own loop (``serve``) keeps
    sending a sample every 20 ms, every period counts missing, the output goes to the zero command after the
    watchdog, and the ball (released at 0.15 m, 0.1 rad) rolls off: STOP 2."""
    from twin.viewer import Viewer, serve

    udp = _free_port(socket.SOCK_DGRAM)
    seen: list[Viewer] = []
    arrivals: list[float] = []
    stops: list[int] = []

    def stalled() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("127.0.0.1", udp))
            s.settimeout(0.2)
            while True:  # HELLO until CONFIG (the view may not listen yet)
                s.send(p.encode(p.Hello(role=p.ROLE_CONTROL, client="stalled"), 0))
                try:
                    frame = p.decode_frame(s.recv(4096))
                except OSError:
                    continue
                if isinstance(frame.msg, p.Config):
                    break
            s.settimeout(5.0)
            while not isinstance((held := p.decode_frame(s.recv(4096)).msg), p.Sample):
                pass  # a repeated HELLO's CONFIG
            s.send(p.encode(p.Command(held.seq, 2.5), frame.session))
            while True:  # alive, silent: only the arrivals are noted
                msg = p.decode_frame(s.recv(4096)).msg
                if isinstance(msg, p.Stop):
                    stops.append(msg.reason)
                    return
                if isinstance(msg, p.Sample) and msg.seq > 0:
                    arrivals.append(time.perf_counter())

    thread = threading.Thread(target=stalled, daemon=True)
    thread.start()
    serve(
        registry,
        port=_free_port(socket.SOCK_STREAM),
        duration_s=3.0,
        wire=("127.0.0.1", udp),
        wait_for_client=False,
        announce=False,
        on_ready=seen.append,
    )
    thread.join(5.0)
    live = seen[0].live
    c = _wire(live).server.counts
    log = live.loop.log()
    assert live.rig.ball_lost and stops == [p.STOP_BALL_LOST]
    gaps = np.diff(arrivals)
    assert len(arrivals) == log.k - 1 > 20
    assert abs(float(np.mean(gaps)) - FRAME_S) < 0.002 and float(np.max(gaps)) < 3 * FRAME_S, gaps
    assert c.missing_commands == log.k - 2 and c.watchdog_trips == 1  # the lost ball's sample: not awaited
    assert np.all(log.aout[5:] == Parameters().amplifier.zero_command_v)


def test_another_controller_ends_the_session_and_selecting_the_wire_entry_opens_a_new_one() -> None:
    with _wired() as (live, server):
        wire_name = live.controller_name
        raw = RawClient(server.port)
        _frames_until(live, lambda: _wire(live).phase == "held")
        config, held = raw.recv(), raw.recv()
        assert isinstance(config.msg, p.Config) and isinstance(held.msg, p.Sample)
        raw.sock.send(p.encode(p.Command(0, 2.5), config.session))
        _frames_until(live, lambda: _wire(live).released)
        live.apply("controller", "appendix-sf")  # the in-process controller: the client's session is done
        while not isinstance((frame := raw.recv()).msg, p.Stop):
            pass
        assert frame.msg == p.Stop(p.STOP_DONE) and frame.session == config.session
        assert live.wire is None and live.controller_name == "appendix-sf"
        _frames(live, 10)
        assert live.rig.time_s > 0.1  # the in-process run goes
        live.apply("controller", wire_name)
        assert _wire(live).phase == "waiting" and server.session != config.session
        _frames(live, 5)
        assert live.rig.time_s < 0.0 and server.controller_addr is None  # held; the old client is not in it
        raw.close()
