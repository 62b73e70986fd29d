"""An observer of a served session (``twin.serving.observer.Observer``): it sees every sample and, echoed, every command
the server accepted, bit for bit as the session's log; from them it knows what the DAC held during each
block; it sees the STOP and the next session of a served job; the fifth is refused, a serial line refused;
and it never changes the session."""

from __future__ import annotations

import dataclasses
import math
import socket
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from serving import in_thread, session_of

from controllers import registry
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.engine import RunResult, run_on_rig
from twin.interface import Controller, DaqSample
from twin.log import THESIS_FIELDS, TRUTH_FIELDS, RunLog
from twin.rigs.remote import Refused, RemoteRig
from twin.rigs.sim import SimRig
from twin.serving import server as serve
from twin.serving.observer import Joined, Observer, ObserverEvent, held_dac_v, open_observer
from twin.serving.server import Server, SessionResult, SessionSettings
from twin.wire import protocol as p

X0, TH0 = next(iter(HARDWARE_STARTS.values()))
ZERO_V = 2.5


def _settings(duration_s: float = 3.0) -> SessionSettings:
    return SessionSettings(x0_m=X0, theta0_rad=TH0, seed=1, duration_s=duration_s, wait_client_s=10.0)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()  # bit for bit


def _control(server: Server) -> RunResult:
    """The controlling client: appendix-sf on the served rig, to the sample flagged last."""
    with RemoteRig("127.0.0.1", server.port) as rig:
        controller = registry.make("appendix-sf", rig.parameters())
        assert isinstance(controller, Controller)
        run = run_on_rig(controller, rig)
    assert run.ended == "last sample"
    return run


@pytest.fixture
def dac_during_blocks(monkeypatch: pytest.MonkeyPatch) -> list[list[float]]:
    """What the served rig's DAC held during each block it read, one list per session: the truth the
    observer's reconstruction is checked against (the block is simulated at the DAC's value)."""
    sessions: list[list[float]] = []
    make_rig: Callable[..., SimRig] = serve.make_rig

    def recording_make_rig(*args: object, **kw: object) -> SimRig:
        rig = make_rig(*args, **kw)
        held: list[float] = []
        sessions.append(held)
        read = rig.read

        def recording_read() -> DaqSample:
            held.append(rig.command_v)
            return read()

        monkeypatch.setattr(rig, "read", recording_read)
        return rig

    monkeypatch.setattr(serve, "make_rig", recording_make_rig)
    return sessions


def _samples(events: list[ObserverEvent]) -> list[p.Sample]:
    return [e for e in events if isinstance(e, p.Sample)]


def _commands(events: list[ObserverEvent]) -> list[p.Command]:
    return [e for e in events if isinstance(e, p.Command)]


def _check_session(events: list[ObserverEvent], log: RunLog, dac: list[float]) -> None:
    """One observed session against its server's log and its rig's DAC, from SAMPLE 0 to the STOP."""
    n = log.timem.size
    assert isinstance(events[0], Joined) and events[0].config.role == p.ROLE_OBSERVE
    # In order: each sample, then the command accepted for it (lock-step: the last one's too), then STOP.
    kinds = [type(e) for e in events[1:]]
    assert kinds == [p.Sample, p.Command] * n + [p.Stop]
    assert events[-1] == p.Stop(p.STOP_DONE)
    samples, commands = _samples(events), _commands(events)
    assert [s.seq for s in samples] == [c.seq for c in commands] == list(range(n))
    assert _same(np.array([s.time_s for s in samples]), log.timem)
    assert _same(np.array([s.ball_v for s in samples]), log.datam1)
    assert _same(np.array([s.angle_v for s in samples]), log.datam2)
    assert [s.flags for s in samples] == [p.FLAG_HELD] + [0] * (n - 2) + [p.FLAG_LAST]
    assert [s.applied_seq for s in samples] == [0] + list(range(n - 1))
    assert _same(np.array([c.dac_v for c in commands]), log.aout)  # the echo is the logged command
    # What the DAC held during each block: the rig's own, and (lock-step) command k during block k+1.
    held = held_dac_v(events, ZERO_V)
    assert _same(held, np.array(dac))
    assert _same(held, np.concatenate([[ZERO_V], log.aout[:-1]]))


def test_an_observer_sees_the_samples_the_commands_and_the_dac_of_a_lockstep_session(
    dac_during_blocks: list[list[float]],
) -> None:
    """Joined before the controller; the events are read only after the session ended, 2000 datagrams
    later (a consumer far slower than the lock-step session): the reader thread kept them all."""
    server = Server(_settings(20.0), log=lambda _: None)
    with in_thread(server) as box, Observer(server.url) as observer:
        assert observer.config is not None and observer.config.role == p.ROLE_OBSERVE
        assert observer.software == server.settings.params.software
        assert observer.parameters().daq.period_s == server.settings.params.daq.period_s
        run = _control(server)
        events = observer.until_stop()
        counts = observer.counts
    served = session_of(box)
    assert served.counts.observers == 1 and served.counts.unauthorised_commands == 0
    joined = events[0]
    assert isinstance(joined, Joined) and joined.config.zero_command_v == ZERO_V
    log = served.result.log
    _check_session(events, log, dac_during_blocks[0])
    for name in THESIS_FIELDS[:4]:  # the controlling client's log is the server's, as without observers
        assert _same(getattr(run.log, name), getattr(log, name)), name
    assert (counts.malformed, counts.wrong_session, counts.repeated, counts.sessions) == (0, 0, 0, 1)


@pytest.mark.quick
def test_observers_never_change_the_session(dac_during_blocks: list[list[float]]) -> None:
    results: list[SessionResult] = []
    for n_observers in (0, 2):
        server = Server(_settings(2.0), log=lambda _: None)
        with in_thread(server) as box:
            observers = [Observer(server.url) for _ in range(n_observers)]
            _control(server)
            for observer in observers:
                assert isinstance(observer.until_stop()[-1], p.Stop)
                observer.close()
        results.append(session_of(box))
    alone, watched = results
    assert watched.counts.observers == 2
    for name in THESIS_FIELDS + TRUTH_FIELDS:
        assert _same(getattr(alone.result.log, name), getattr(watched.result.log, name)), name
    assert alone.result.verdict == watched.result.verdict
    assert dac_during_blocks[0] == dac_during_blocks[1]


def test_a_fifth_observer_is_refused_and_the_four_get_the_stop() -> None:
    server = Server(_settings(0.5), log=lambda _: None)
    with in_thread(server) as box:
        observers = [open_observer(server.url, client=f"observer {i}") for i in range(4)]
        with pytest.raises(Refused, match="no more observers"):
            Observer(server.url, connect_timeout_s=2.0)
        _control(server)
        for observer in observers:
            assert observer.until_stop()[-1] == p.Stop(p.STOP_DONE)
            observer.close()
    counts = session_of(box).counts
    assert (counts.observers, counts.refused_clients) == (4, 1)


@pytest.mark.parametrize("url", ["serial:///dev/ttyACM0?baud=115200", "serial:///dev/ttyUSB0"])
def test_a_serial_url_is_refused_with_a_message(url: str) -> None:
    with pytest.raises(ValueError, match=r"an observer needs UDP .*a serial line has a single peer"):
        Observer(url)
    with pytest.raises(ValueError, match="serial line"):
        open_observer(url)


@pytest.mark.quick
def test_a_malformed_url_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="expected udp://HOST:PORT"):
        Observer("udp://127.0.0.1")


@contextmanager
def _serving_twice(server: Server) -> Iterator[list[SessionResult]]:
    """``server.serve()`` twice in a thread (a served job of two runs on one socket)."""
    sessions: list[SessionResult] = []
    thread = threading.Thread(target=lambda: sessions.extend([server.serve(), server.serve()]), daemon=True)
    thread.start()
    try:
        yield sessions
    finally:
        thread.join(30.0)
        server.close()
    assert not thread.is_alive(), "the server hung"


@pytest.mark.parametrize("follow", [True, False])
def test_an_observer_of_a_served_job_sees_each_session(
    dac_during_blocks: list[list[float]], follow: bool
) -> None:
    """After the first STOP the observer says HELLO again (at once with ``follow``, else on ``rejoin``); once
    it has joined the second session (its ``Joined``) the second controller comes, so the observer sees
    that session from SAMPLE 0."""
    server = Server(_settings(1.0), log=lambda _: None)
    with _serving_twice(server) as sessions, Observer(server.url, follow=follow) as observer:
        _control(server)
        first = observer.until_stop()
        if not follow:
            assert observer.next_event(0.3) is None  # no HELLO yet: not in the next session
            observer.rejoin()
        joined = observer.next_event(10.0)
        assert isinstance(joined, Joined)
        _control(server)
        second = [joined, *observer.until_stop()]
        assert observer.counts.sessions == 2
    assert len(sessions) == 2
    ids = [e.session for e in first + second if isinstance(e, Joined)]
    assert len(ids) == 2 and ids[0] != ids[1]
    for events, session, dac in zip((first, second), sessions, dac_during_blocks, strict=True):
        _check_session(events, session.result.log, dac)
    # The stream of both sessions at once: each session's seqs are its own.
    both = held_dac_v(first + second, ZERO_V)
    assert _same(both, np.array(dac_during_blocks[0] + dac_during_blocks[1]))


@pytest.mark.realtime
def test_in_real_time_the_observer_knows_the_dac_through_a_dead_controller_and_the_watchdog(
    dac_during_blocks: list[list[float]],
) -> None:
    """A controller that answers the first samples (a ramp of commands) and then dies: whichever commands
    made their boundary, the observer's DAC per block is the rig's, through the hold and the watchdog."""
    answered = 10
    settings = dataclasses.replace(_settings(0.6), mode=p.MODE_REALTIME, watchdog_periods=3)
    server = Server(settings, log=lambda _: None)
    with in_thread(server) as box, Observer(server.url) as observer:
        # At the socket: RemoteRig would acknowledge every sample it reads.
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.connect(("127.0.0.1", server.port))
            raw.settimeout(5.0)
            raw.send(p.encode(p.Hello(role=p.ROLE_CONTROL, client="dies"), 0))
            session = p.decode_frame(raw.recv(4096)).session
            while not isinstance(msg := p.decode_frame(raw.recv(4096)).msg, p.Stop):
                assert isinstance(msg, p.Sample)
                if msg.seq <= answered:
                    raw.send(p.encode(p.Command(msg.seq, 2.5 + 0.05 * msg.seq), session))
        events = observer.until_stop()
    served = session_of(box)
    assert served.counts.watchdog_trips == 1
    samples = _samples(events)
    assert [s.seq for s in samples] == list(range(served.result.log.timem.size))
    assert any(s.flags & p.FLAG_WATCHDOG for s in samples)
    held = held_dac_v(events, ZERO_V)
    assert _same(held, np.array(dac_during_blocks[0]))
    assert {c.dac_v for c in _commands(events)} <= {2.5 + 0.05 * k for k in range(answered + 1)}


@pytest.mark.quick
def test_held_dac_v_from_the_applied_seq_the_echo_and_the_watchdog() -> None:
    """A real-time stream: command 2 was late (not accepted, the DAC kept command 1), the echo of command 3
    was lost, then the watchdog held the output at the zero command; a second session starts afresh."""
    config = p.Config(p.ROLE_OBSERVE, p.MODE_REALTIME, 0.02, 40000.0, 5, 0.0, 5.0, ZERO_V)

    def sample(seq: int, applied: int, flags: int = 0) -> p.Sample:
        return p.Sample(seq, 0.02 * seq, 1.0, 2.0, flags, applied)

    events: list[ObserverEvent] = [
        Joined(7, config),
        sample(0, 0, p.FLAG_HELD),
        p.Command(0, 2.5),
        sample(1, 0),
        p.Command(1, 3.25),
        sample(2, 1),
        sample(3, 1, p.FLAG_LATE),  # command 2 missed its boundary: the DAC holds command 1
        sample(4, 3),  # command 3 was accepted, its echo lost
        sample(5, 3, p.FLAG_WATCHDOG | p.FLAG_LATE),
        p.Command(5, 1.75),
        sample(6, 5),
        p.Stop(p.STOP_CLIENT_QUIT),
        Joined(8, config),
        sample(0, 0, p.FLAG_HELD),
        p.Command(0, 2.5),
        sample(1, 0),
        p.Command(1, 4.0),
        sample(2, 1),
        sample(3, 5),  # session 8 has no command 5: not session 7's
    ]
    held = held_dac_v(events, ZERO_V)
    expected = [ZERO_V, ZERO_V, 3.25, 3.25, math.nan, ZERO_V, 1.75, ZERO_V, ZERO_V, 4.0, math.nan]
    np.testing.assert_array_equal(held, expected)
    assert held_dac_v([], ZERO_V).shape == (0,)


def test_an_observer_config_is_the_controllers_but_its_role() -> None:
    server = Server(_settings(0.5), log=lambda _: None)
    with in_thread(server), Observer(server.url) as observer:
        with RemoteRig("127.0.0.1", server.port) as rig:
            controller = registry.make("appendix-sf", rig.parameters())
            assert isinstance(controller, Controller)
            run_on_rig(controller, rig)
        assert observer.config is not None
        assert dataclasses.replace(observer.config, role=p.ROLE_CONTROL) == rig.config
        assert observer.until_stop()[-1] == p.Stop(p.STOP_DONE)
