"""Wire sessions that a vanished peer must not hold: an observer that goes —
its socket closed, its process killed, or silent — frees its place for the next; a lone HELLO does not take
``view --serve``'s session; the view releases a run only with its browser and its wire client both there,
and the client waits for that as long as it was told; the waits are options on both sides, validated, and
a wait that runs out says what was waited for, from whom and for how long."""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from cli_checks import refused
from serving import in_thread, session_of
from test_c_controller import build_bb_sf

from controllers import registry
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.engine import RunResult, run_on_rig
from twin.parameters import Parameters
from twin.rigs.remote import RemoteError, RemoteRig
from twin.serving.server import MAX_OBSERVERS, Server, SessionSettings
from twin.viewer import FRAME_S, LiveTwin
from twin.viewer.wire import WIRE_MARGIN_S, WireCatalogue, WireClient
from twin.wire import protocol as p

START = HARDWARE_STARTS["Fig 6.16 (state feedback)"]  # (0.14 m, −0.2 rad)


class Peer:
    """A client at the socket level: HELLO with a role, then whatever the test sends."""

    def __init__(self, port: int, role: int, name: str = "peer") -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect(("127.0.0.1", port))
        self.sock.settimeout(5.0)
        self.role, self.name = role, name
        self.hello()

    def hello(self) -> None:
        self.sock.send(p.encode(p.Hello(role=self.role, client=self.name), 0))

    def recv(self) -> p.Frame:
        return p.decode_frame(self.sock.recv(4096))

    def config(self) -> p.Frame:
        """The next CONFIG (other frames skipped)."""
        while not isinstance((frame := self.recv()).msg, p.Config):
            pass
        return frame

    def close(self) -> None:
        self.sock.close()


def _granted(frame: p.Frame) -> int:
    assert isinstance(frame.msg, p.Config)
    return frame.msg.role


def _server(**settings: object) -> Server:
    kw: dict[str, object] = {
        "x0_m": START[0],
        "theta0_rad": START[1],
        "duration_s": 30.0,
        "wait_client_s": 20.0,
    }
    return Server(SessionSettings(**{**kw, **settings}), log=lambda _: None)  # type: ignore[arg-type]


# --- item 6: an observer that vanishes frees its place ----------------------------------------------------
@pytest.mark.quick
@pytest.mark.parametrize("rounds", [1, 3])
def test_observers_that_close_their_sockets_free_their_places_at_the_next_sample(rounds: int) -> None:
    """4 observers per round join a lock-step session and close their sockets: the samples sent to them come
    back unreachable and their places are free at once (the silence limit, 30 s, plays no part)."""
    server = _server(timeout_s=30.0)
    with in_thread(server) as box:
        control = Peer(server.port, p.ROLE_CONTROL, "controller")
        session = control.config().session
        seq = -1

        def answer_next() -> None:  # the controller answers the next new sample with the zero command
            nonlocal seq
            while not (isinstance((f := control.recv()).msg, p.Sample) and f.msg.seq > seq):
                pass
            seq = f.msg.seq
            control.sock.send(p.encode(p.Command(seq, 2.5), session))

        answer_next()
        for r in range(rounds):
            gone = [Peer(server.port, p.ROLE_OBSERVE, f"observer {r}.{i}") for i in range(MAX_OBSERVERS)]
            assert [_granted(o.config()) for o in gone] == [p.ROLE_OBSERVE] * MAX_OBSERVERS
            for o in gone:
                o.close()
            for _ in range(3):  # the next samples go to the closed ports; the kernel says so
                answer_next()
        late = Peer(server.port, p.ROLE_OBSERVE, "late observer")
        assert _granted(late.config()) == p.ROLE_OBSERVE  # admitted: the vanished ones' places were freed
        assert len(server.observers) == 1
        control.sock.send(p.encode(p.Stop(p.STOP_CLIENT_QUIT), session))
        late.close()
        control.close()
    counts = session_of(box).counts
    assert (counts.observers, counts.observers_gone, counts.refused_clients) == (
        MAX_OBSERVERS * rounds + 1,
        MAX_OBSERVERS * rounds,
        0,
    )


@pytest.mark.quick
def test_silent_observers_lose_their_places_after_the_silence_limit() -> None:
    """Observers that stop answering (no keep-alive HELLO: a stopped process, a lost network) are forgotten
    after the server's silence limit; before it a fifth observer is refused."""
    server = _server(timeout_s=0.5)  # the limit is then its floor, 1 s
    assert server.observer_silence_s == 1.0
    with in_thread(server) as box:
        silent = [Peer(server.port, p.ROLE_OBSERVE, f"silent {i}") for i in range(MAX_OBSERVERS)]
        assert [_granted(o.config()) for o in silent] == [p.ROLE_OBSERVE] * MAX_OBSERVERS
        early = Peer(server.port, p.ROLE_OBSERVE, "early")
        assert _granted(early.config()) == p.ROLE_REFUSED  # the places are still held
        time.sleep(1.3)
        late = Peer(server.port, p.ROLE_OBSERVE, "late")
        assert _granted(late.config()) == p.ROLE_OBSERVE
        assert server.observers == [late.sock.getsockname()]
        control = Peer(server.port, p.ROLE_CONTROL, "controller")
        session = control.config().session
        control.sock.send(p.encode(p.Command(0, 2.5), session))
        control.sock.send(p.encode(p.Stop(p.STOP_CLIENT_QUIT), session))
        for peer in [*silent, early, late, control]:
            peer.close()
    counts = session_of(box).counts
    assert (counts.observers, counts.refused_clients) == (MAX_OBSERVERS + 1, 1)
    assert (
        counts.observers_gone >= MAX_OBSERVERS
    )  # (the late one may be counted too: it closed before the STOP)


def test_an_observer_that_keeps_saying_hello_keeps_its_place_and_a_killed_one_loses_it() -> None:
    """The ``Observer`` client's keep-alive holds its place past the silence limit; the process of another is
    killed (SIGKILL) and its place is free at the next sample."""
    server = _server(timeout_s=0.5, stop_when_lost=False)  # the zero command loses the ball: go on
    code = textwrap.dedent(
        f"""
        import sys, time
        from twin.serving.observer import Observer
        o = Observer("{server.url}", client="doomed")
        print("joined", flush=True)
        time.sleep(60)
        """
    )
    from twin.serving.observer import Observer

    with in_thread(server) as box:
        kept = Observer(server.url, client="kept")
        doomed = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
        try:
            assert doomed.stdout is not None and doomed.stdout.readline().strip() == "joined"
            fillers = [Peer(server.port, p.ROLE_OBSERVE, f"filler {i}") for i in range(MAX_OBSERVERS - 2)]
            assert [_granted(f.config()) for f in fillers] == [p.ROLE_OBSERVE] * (MAX_OBSERVERS - 2)
            os.kill(doomed.pid, signal.SIGKILL)
            doomed.wait(10.0)
        finally:
            if doomed.poll() is None:
                doomed.kill()
                doomed.wait(10.0)
        control = Peer(server.port, p.ROLE_CONTROL, "controller")
        session = control.config().session
        for seq in range(3):  # samples to the killed observer's port come back unreachable
            while not (isinstance((f := control.recv()).msg, p.Sample) and f.msg.seq == seq):
                pass
            control.sock.send(p.encode(p.Command(seq, 2.5), session))
            for filler in fillers:
                filler.hello()  # the fillers' own keep-alive
        newcomer = Peer(server.port, p.ROLE_OBSERVE, "newcomer")
        assert _granted(newcomer.config()) == p.ROLE_OBSERVE
        # Past the silence limit (the session going on): the Observer's keep-alive holds its place, the
        # silent fillers' and newcomer's are freed.
        seq, until = 2, time.monotonic() + 1.5
        while time.monotonic() < until:
            while not (isinstance((f := control.recv()).msg, p.Sample) and f.msg.seq == seq + 1):
                pass
            seq += 1
            control.sock.send(p.encode(p.Command(seq, 2.5), session))
            time.sleep(0.02)
        while not (isinstance((f := control.recv()).msg, p.Sample) and f.msg.seq == seq + 1):
            pass
        assert server.observers == [kept.sock.getsockname()]
        control.sock.send(p.encode(p.Stop(p.STOP_CLIENT_QUIT), session))
        for peer in [*fillers, newcomer, control]:
            peer.close()
        events = kept.until_stop(5.0)
        assert isinstance(events[-1], p.Stop)
        kept.close()
    counts = session_of(box).counts
    assert counts.observers_gone >= 1 and counts.refused_clients == 0


# --- items 6 and 15: the view's one session --------------------------------------------------------------
@contextmanager
def _view(*, browser: bool, timeout_s: float) -> Iterator[tuple[LiveTwin, Server]]:
    """A live twin whose run is the wire client's, at the first hardware start, as ``view --serve`` builds it
    (``browser``: one is already there; else the view waits for one); a wire client that went starts a new
    run (the view's Reset), as ``twin.viewer.server`` wires it."""
    server = Server(
        SessionSettings(mode=p.MODE_REALTIME, timeout_s=timeout_s), "127.0.0.1", 0, log=lambda _: None
    )
    try:
        catalogue = WireCatalogue(registry, server)
        live = LiveTwin(
            Parameters(), catalogue, catalogue.name, seed=0, speed=1.0, wait_for_client=not browser
        )
        catalogue.on_vacant = lambda: live.enqueue("reset")
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


def _frames(live: LiveTwin, seconds: float) -> None:
    """The view's loop for ``seconds``: its actions, then the wire's tick (running) or its service (not
    running: no browser yet, or paused), with the frame's end as the deadline."""
    until = time.perf_counter() + seconds
    while time.perf_counter() < until:
        end = time.perf_counter() + FRAME_S
        live.apply_actions()
        if live.running:
            live.tick(end - WIRE_MARGIN_S)
        else:
            live.service_wire(end - WIRE_MARGIN_S)
        left = end - time.perf_counter()
        if left > 0:
            time.sleep(left)


def _frames_until(live: LiveTwin, condition, seconds: float = 10.0) -> None:  # type: ignore[no-untyped-def]
    until = time.perf_counter() + seconds
    while not condition():
        assert time.perf_counter() < until, "the condition did not come"
        _frames(live, FRAME_S)


@contextmanager
def _client(port: int, **waits: float | None) -> Iterator[dict[str, object]]:
    """``appendix-sf`` through ``RemoteRig`` in a thread (the ``run --rig`` path) with its waits; its run (or
    its error) after the block."""
    box: dict[str, object] = {}

    def client() -> None:
        try:
            with RemoteRig("127.0.0.1", port, client="pytest appendix-sf", **waits) as rig:  # type: ignore[arg-type]
                box["run"] = run_on_rig(registry.make("appendix-sf", rig.parameters()), rig)
        except RemoteError as exc:
            box["error"] = exc

    thread = threading.Thread(target=client, daemon=True)
    thread.start()
    box["thread"] = thread
    yield box
    thread.join(10.0)
    assert not thread.is_alive(), "the client hung"


@pytest.mark.slow
@pytest.mark.realtime
def test_the_recipe_in_its_order_the_client_waits_for_the_browser_and_then_balances() -> None:
    """``view --serve``, then the client, then the browser, long after the client's silence limit: the run is
    not released until the browser came; meanwhile the held sample is repeated and answered, so the client
    (0.5 s of silence allowed) stays; then it balances the ball."""
    with _view(browser=False, timeout_s=1.0) as (live, server), _client(server.port, timeout_s=0.5) as box:
        _frames_until(live, lambda: _wire(live)._answered_at is not None)  # acknowledged
        _frames(live, 2.5)  # no browser: 5× the client's silence limit, 2.5× the view's wait
        wire = _wire(live)
        assert wire.phase == "held" and not wire.released and live.rig.time_s < 0.0
        assert box["thread"].is_alive() and "error" not in box, box  # type: ignore[attr-defined]
        assert "held until the run starts" in live.status_markdown()
        session = server.session
        live.enqueue("connected")  # the browser
        _frames_until(live, lambda: _wire(live).released)
        _frames(live, 3.0)
        assert server.session == session  # the session the client was admitted to
        assert not live.rig.ball_lost and live.error is None and live.rig.time_s > 2.5
        assert server.counts.watchdog_trips == 0
        live.apply("reset")  # STOP 0: the client's run ends
    assert "error" not in box, box
    run = box["run"]
    assert isinstance(run, RunResult) and run.log.k > 100


@pytest.mark.quick
def test_a_client_that_acknowledged_and_died_before_the_browser_came_is_not_released() -> None:
    """A client acknowledges the held sample and vanishes before the browser comes: when it comes the run is
    not released to nobody; the session ends (STOP 3) after the view's wait and the next client takes it."""
    with _view(browser=False, timeout_s=0.4) as (live, server):
        dead = Peer(server.port, p.ROLE_CONTROL, "dies")
        _frames_until(live, lambda: _wire(live).phase == "held")
        config = dead.config()
        while not isinstance(dead.recv().msg, p.Sample):
            pass
        dead.sock.send(p.encode(p.Command(0, 2.5), config.session))
        _frames_until(live, lambda: _wire(live)._answered_at is not None)
        dead.close()
        first = server.session
        live.enqueue("connected")
        _frames_until(live, lambda: server.session != first, seconds=5.0)
        assert not _wire(live).released and live.rig.time_s < 0.0  # the rig never moved
        assert "did not answer the repeats of the held sample within 0.4 s" in _wire(live).note
        second = Peer(server.port, p.ROLE_CONTROL, "second")
        _frames_until(live, lambda: _wire(live).phase == "held")
        assert _granted(second.config()) == p.ROLE_CONTROL
        second.close()


@pytest.mark.quick
def test_one_hello_does_not_keep_the_views_session() -> None:
    """A lone HELLO (no acknowledgement) loses the session after the view's wait; a HELLO and an
    acknowledgement, then silence, loses it too (STOP 3, a new run waits, held); each time the next client
    is admitted."""
    with _view(browser=True, timeout_s=0.4) as (live, server):
        lone = Peer(server.port, p.ROLE_CONTROL, "lone")
        _frames_until(live, lambda: _wire(live).phase == "held")
        first = server.session
        _frames_until(live, lambda: server.session != first, seconds=5.0)
        assert _wire(live).phase == "waiting"

        vanishing = Peer(server.port, p.ROLE_CONTROL, "vanishing")
        _frames_until(live, lambda: _wire(live).phase == "held")
        config = vanishing.config()
        assert config.msg.role == p.ROLE_CONTROL  # type: ignore[union-attr]
        while not isinstance(vanishing.recv().msg, p.Sample):
            pass
        vanishing.sock.send(p.encode(p.Command(0, 2.5), config.session))
        _frames_until(live, lambda: _wire(live).released)
        wire, runs = _wire(live), live.runs
        _frames_until(live, lambda: live.runs > runs, seconds=5.0)  # no command for 0.4 s: a new run
        assert wire.phase == "ended" and "no COMMAND in time from the client for 0.4 s" in wire.note
        stops = []
        while not stops:
            f = vanishing.recv()
            if isinstance(f.msg, p.Stop):
                stops.append(f.msg.reason)
        assert stops == [p.STOP_ERROR]
        assert _wire(live).phase == "waiting" and live.rig.time_s < 0.0  # held again, for the next one

        third = Peer(server.port, p.ROLE_CONTROL, "third")
        _frames_until(live, lambda: _wire(live).phase == "held")
        assert _granted(third.config()) == p.ROLE_CONTROL
        for peer in (lone, vanishing, third):
            peer.close()


@pytest.mark.quick
def test_a_client_that_quit_frees_the_views_session_after_the_wait() -> None:
    """A client that sent STOP while running: the run goes on under the watchdog for the view's wait, then a
    new run waits, held, and the next client is admitted."""
    with _view(browser=True, timeout_s=0.4) as (live, server):
        quitter = Peer(server.port, p.ROLE_CONTROL, "quitter")
        _frames_until(live, lambda: _wire(live).phase == "held")
        config = quitter.config()
        while not isinstance(quitter.recv().msg, p.Sample):
            pass
        quitter.sock.send(p.encode(p.Command(0, 2.5), config.session))
        _frames_until(live, lambda: _wire(live).released)
        quitter.sock.send(p.encode(p.Stop(p.STOP_CLIENT_QUIT), config.session))
        _frames_until(live, lambda: _wire(live).phase == "quit")
        assert "Reset, or 0.4 s (the wire wait), starts a new session" in _wire(live).note
        runs = live.runs
        _frames_until(live, lambda: live.runs > runs, seconds=5.0)
        assert _wire(live).phase == "waiting" and live.rig.time_s < 0.0
        nxt = Peer(server.port, p.ROLE_CONTROL, "next")
        _frames_until(live, lambda: _wire(live).phase == "held")
        assert _granted(nxt.config()) == p.ROLE_CONTROL
        for peer in (quitter, nxt):
            peer.close()


# --- item 16: the waits are options on both sides, and a wait that runs out says which ---------------------
class HoldingServer:
    """A rig that answers HELLO with CONFIG (``mode``), sends SAMPLE 0 (held) and then, in a thread, repeats
    it every 0.2 s (``repeat``) or says nothing more, whatever the client answers."""

    def __init__(self, *, repeat: bool, seq: int = 0, mode: int = p.MODE_REALTIME) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.url = f"udp://127.0.0.1:{self.port}"
        self.repeat, self.seq, self.mode = repeat, seq, mode
        self.stops: list[int] = []
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        session, peer, next_at = 0x5E55, None, math.inf
        flags = p.FLAG_HELD if self.seq == 0 else 0
        sample = p.Sample(self.seq, -0.01 if self.seq == 0 else 0.02 * self.seq, 1.0, 0.0, flags, 0)
        while not self._closing.is_set():
            if peer is not None and time.monotonic() >= next_at:
                self.sock.sendto(p.encode(sample, session), peer)
                next_at = time.monotonic() + 0.2 if self.repeat else math.inf
            try:
                data, addr = self.sock.recvfrom(4096)
            except OSError:
                continue
            msg = p.decode_frame(data).msg
            if isinstance(msg, p.Hello) and peer is None:
                peer, next_at = addr, time.monotonic()
                config = p.Config.from_parameters(
                    Parameters(), role=p.ROLE_CONTROL, mode=self.mode, watchdog_periods=5, rig="holding"
                )
                self.sock.sendto(p.encode(config, session), addr)
            elif isinstance(msg, p.Stop):
                self.stops.append(msg.reason)

    def close(self) -> None:
        self._closing.set()
        self._thread.join(5.0)
        self.sock.close()


@contextmanager
def _holding(**kw: object) -> Iterator[HoldingServer]:
    server = HoldingServer(**kw)  # type: ignore[arg-type]
    try:
        yield server
    finally:
        server.close()


def _first_read_then(rig: RemoteRig) -> None:
    """Read SAMPLE 0 (held) and acknowledge it; then wait for the next."""
    rig.read()
    rig.write(rig.config.zero_command_v)
    rig.read()


@pytest.mark.realtime
def test_the_python_client_waits_for_a_held_session_as_long_as_told_and_says_so() -> None:
    names = ("--wait-sample", "--wait-start")
    with _holding(repeat=True) as server:  # a live view waiting for its browser
        rig = RemoteRig("127.0.0.1", server.port, timeout_s=0.3, start_wait_s=1.2, wait_names=names)
        started = time.monotonic()
        with rig, pytest.raises(RemoteError) as caught:
            _first_read_then(rig)
        waited = time.monotonic() - started
        assert waited >= 1.2  # 4× its silence limit: the repeats say the server is there
        message = str(caught.value)
        assert f"the session at {server.url} did not start within" in message
        assert "(--wait-start 1.2 s)" in message and "repeating SAMPLE 0" in message
        assert "gone" not in message
        time.sleep(0.3)
        assert server.stops == [p.STOP_CLIENT_QUIT]  # the client told the server it quit


@pytest.mark.quick
def test_a_silent_server_and_a_deaf_one_are_told_apart() -> None:
    names = ("--wait-sample", "--wait-start")
    with _holding(repeat=False) as server:  # SAMPLE 0 once, then nothing
        with RemoteRig("127.0.0.1", server.port, timeout_s=0.4, wait_names=names) as rig:
            with pytest.raises(RemoteError) as caught:
                _first_read_then(rig)
        message = str(caught.value)
        assert f"no SAMPLE 1 from {server.url} for 0." in message and "(--wait-sample 0.4 s)" in message
        assert "the server is gone, the link is down" in message
    with _holding(repeat=True, seq=7, mode=p.MODE_LOCKSTEP) as server:  # repeats SAMPLE 7: deaf to us
        with RemoteRig("127.0.0.1", server.port, timeout_s=0.6, wait_names=names) as rig:
            with pytest.raises(RemoteError) as caught:
                rig.read()
                rig.write(2.5)
                rig.read()
        message = str(caught.value)
        assert f"no SAMPLE 8 from {server.url} for 0." in message and "(--wait-sample 0.6 s)" in message
        assert "repeated SAMPLE 7" in message and "do not reach it" in message


@pytest.mark.quick
@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (
            ["run", "--rig", "udp://127.0.0.1:9", "--controller", "appendix-sf", "--wait-sample", "nan"],
            ["--wait-sample"],
        ),
        (
            ["run", "--rig", "udp://127.0.0.1:9", "--controller", "appendix-sf", "--wait-sample", "-1"],
            ["--wait-sample"],
        ),
        (
            ["run", "--rig", "udp://127.0.0.1:9", "--controller", "appendix-sf", "--wait-start", "1e9"],
            ["--wait-start"],
        ),
        (
            ["run", "--controller", "appendix-sf", "--x0", "0.1", "--theta0", "0", "--wait-start", "3"],
            ["need --rig"],
        ),
        (["view", "--serve", "0", "--wire-timeout", "inf"], ["--wire-timeout"]),
        (["view", "--serve", "0", "--wire-timeout", "0"], ["--wire-timeout"]),
        (["view", "--wire-timeout", "3"], ["needs --serve"]),
        (["serve", "--x0", "0", "--theta0", "0", "--timeout", "-5"], ["--timeout"]),
        (["serve", "--x0", "0", "--theta0", "0", "--wait-client", "1e300"], ["--wait-client"]),
    ],
)
def test_the_wait_options_refuse_bad_values(
    capsys: pytest.CaptureFixture[str], argv: list[str], needles: list[str]
) -> None:
    refused(capsys, argv, *needles)


@pytest.fixture(scope="module")
def bb_sf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_bb_sf(tmp_path_factory.mktemp("c"))


@pytest.mark.realtime
def test_the_c_client_waits_for_a_held_session_as_told(bb_sf: Path) -> None:
    """bb_sf answers the repeated held sample past its --timeout (the server is there), and gives up at its
    --wait-start with a line that names it, having sent STOP 1; a bad --wait-start is a usage error."""
    with _holding(repeat=True) as server:
        started = time.monotonic()
        done = subprocess.run(
            [str(bb_sf), "udp", "127.0.0.1", str(server.port), "--timeout", "0.4", "--wait-start", "1.5"],
            capture_output=True,
            text=True,
            timeout=30,
        )
        waited = time.monotonic() - started
        assert done.returncode == 1, done.stderr
        assert waited >= 1.5
        assert "the session did not start within 1.5 s (--wait-start)" in done.stderr
        assert "waiting for the server to start the run" in done.stderr  # said once, after 1 s held
        time.sleep(0.3)
        assert server.stops == [p.STOP_CLIENT_QUIT]
    for bad in ("nan", "-1", "1e9", "x"):
        usage = subprocess.run(
            [str(bb_sf), "udp", "127.0.0.1", "9", "--wait-start", bad], capture_output=True, text=True
        )
        assert usage.returncode == 2 and "--wait-start" in usage.stderr


@pytest.mark.realtime
def test_the_readme_recipe_with_the_c_client_before_the_browser(bb_sf: Path) -> None:
    """README "In the live view": the view, then ``bb_sf`` as pasted (no --wait-start), then the browser long
    after the client's silence limit (--timeout 0.5 here, 10 by default: the same wait, shorter): the client
    stays, held; once the browser comes it balances the ball; the view's Reset ends its session, STOP 0."""
    with _view(browser=False, timeout_s=1.0) as (live, server):
        client = subprocess.Popen(
            [str(bb_sf), "udp", "127.0.0.1", str(server.port), "--timeout", "0.5", "--name", "bb_sf recipe"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            _frames_until(live, lambda: _wire(live)._answered_at is not None)
            _frames(live, 2.0)  # no browser: 4× the client's silence limit
            assert client.poll() is None and not _wire(live).released and live.rig.time_s < 0.0
            live.enqueue("connected")
            _frames_until(live, lambda: _wire(live).released)
            _frames(live, 2.0)
            assert not live.rig.ball_lost and live.error is None and live.rig.time_s > 1.5
            assert server.client_name == "bb_sf recipe"
            live.apply("reset")
            _, err = client.communicate(timeout=10.0)
        finally:
            if client.poll() is None:
                client.kill()
                client.communicate()
    assert client.returncode == 0, err  # STOP 0: the session ended as the server said
    assert "stopped by the server: done" in err and "waiting for the server to start the run" in err


# --- item 17's part: the docs pin the HELLO reply port's byte numbering ---------------------------------------
@pytest.mark.quick
def test_the_docs_pin_the_reply_ports_bytes_as_the_codec_writes_them() -> None:
    root = Path(__file__).resolve().parents[1]
    frame = p.encode(p.Hello(role=p.ROLE_CONTROL, client="simulink", reply_port=25001), 0)
    assert (frame[18], frame[19]) == (0xA9, 0x61)  # offset 18 from 0, low byte first
    protocol = (root / "docs" / "protocol.md").read_text()
    assert "**Offsets count bytes from 0**" in protocol
    assert "byte 18 = 0xA9, byte 19 = 0x61" in protocol
    assert "Bytes 18 (low) and 19 (high), counted from 0: the frame's 19th and 20th bytes" in protocol
    readme = " ".join((root / "docs" / "connect.md").read_text().split())  # the manual's Simulink recipe
    assert "bytes 19–20, `uint16`" not in readme  # the old, 1-based numbering without saying so
    assert (
        "at offset 18: bytes 18–19 counting from 0 as docs/protocol.md does, the frame's 19th and 20th"
        in readme
    )
