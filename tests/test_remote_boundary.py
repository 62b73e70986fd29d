"""The remote rig is a boundary, as a file is: what a server sends (CONFIG, SAMPLE, names) is checked on arrival,
and a bad one ends the session with a message naming the rig, the message, the field and its value — the rig's
fault, never the controller's — with the log up to it kept. The servers here are fakes: a UDP socket in the
test that sends frames crafted with ``twin.wire.protocol.encode``."""

from __future__ import annotations

import dataclasses
import socket
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import pytest

from controllers import registry
from twin.engine import ENDED_BALL_LOST, ENDED_LAST_SAMPLE, RunResult, run_on_rig
from twin.interface import Controller
from twin.parameters import Parameters
from twin.rigs.remote import LATE_PERIODS, RemoteError, RemoteRig
from twin.rigs.session import remote_session
from twin.serving.server import Server, SessionSettings
from twin.wire import protocol as p

SESSION = 77
PERIOD_S = 0.02
FAULT = "the rig's fault"


def _config(**changes: Any) -> p.Config:
    base = p.Config.from_parameters(
        Parameters(), role=p.ROLE_CONTROL, mode=p.MODE_LOCKSTEP, watchdog_periods=5, rig="fake rig"
    )
    return dataclasses.replace(base, **changes)


def _samples(n: int, *, last: bool = True) -> list[p.Sample]:
    """SAMPLE 0 (held) … n−1 on the grid t = −period/2 + k·period, the ball at rest near the middle."""
    out = [
        p.Sample(k, -PERIOD_S / 2 + k * PERIOD_S, 0.5, 0.0, p.FLAG_HELD if k == 0 else 0) for k in range(n)
    ]
    if last:
        out[-1] = dataclasses.replace(out[-1], flags=out[-1].flags | p.FLAG_LAST)
    return out


class FakeRig:
    """A rig at ``url``: every HELLO answered with ``config`` (a message, or raw bytes), then in lock-step each of
    ``samples`` sent once the previous one is answered (or the client's STOP ends it); after a sample flagged last
    it sends STOP ``final_stop``. Everything the client sends is kept in ``received``."""

    def __init__(
        self,
        config: p.Config | bytes | None = None,
        samples: Sequence[p.Sample] = (),
        *,
        final_stop: int = p.STOP_DONE,
    ) -> None:
        self.config = p.encode(config or _config(), SESSION) if not isinstance(config, bytes) else config
        self.samples = list(samples)
        self.final_stop = final_stop
        self.received: list[p.Message] = []
        self.configs_sent = 0
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.02)
        self.url = f"udp://127.0.0.1:{self.sock.getsockname()[1]}"
        self._halt = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)

    def _recv(self) -> tuple[p.Message, Any] | None:
        try:
            data, addr = self.sock.recvfrom(4096)
        except OSError:
            return None
        msg = p.decode(data)
        self.received.append(msg)
        if isinstance(msg, p.Hello):
            self.sock.sendto(self.config, addr)
            self.configs_sent += 1
        return msg, addr

    def _serve(self) -> None:
        peer = None
        while peer is None and not self._halt.is_set():
            got = self._recv()
            peer = got[1] if got is not None else None
        for sample in self.samples:
            self.sock.sendto(p.encode(sample, SESSION), peer)
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline and not self._halt.is_set():
                got = self._recv()
                if got is not None and isinstance(got[0], p.Stop):
                    return self._drain()
                if got is not None and isinstance(got[0], p.Command) and got[0].seq == sample.seq:
                    break
            else:
                return self._drain()
            if sample.flags & p.FLAG_LAST:
                self.sock.sendto(p.encode(p.Stop(self.final_stop), SESSION), peer)
                break
        self._drain()

    def _drain(self) -> None:
        while not self._halt.is_set():
            self._recv()

    def __enter__(self) -> FakeRig:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        time.sleep(0.1)  # the client's last datagrams
        self._halt.set()
        self._thread.join(5.0)
        self.sock.close()
        assert not self._thread.is_alive()

    def sent_by_client(self, kind: type) -> list[Any]:
        return [m for m in self.received if isinstance(m, kind)]


def _controller(rig: RemoteRig) -> Controller:
    c = registry.make("appendix-sf", rig.parameters())
    assert isinstance(c, Controller)
    return c


def _run(fake: FakeRig, **kw: Any) -> tuple[RemoteRig, RunResult]:
    with fake, RemoteRig("127.0.0.1", int(fake.url.rsplit(":", 1)[1]), **kw) as rig:
        return rig, run_on_rig(_controller(rig), rig)


def _session(fake: FakeRig) -> tuple[RunResult | None, dict[str, Any]]:
    with fake, RemoteRig("127.0.0.1", int(fake.url.rsplit(":", 1)[1])) as rig:
        got = remote_session(
            rig,
            Parameters(),
            lambda prm: registry.make("appendix-sf", prm),
            name="sf",
            url=fake.url,
            many=False,
        )
    assert got is not None
    return got[1], got[2]


def _assert_faulted(fake: FakeRig, run: RunResult, seq: int, *needles: str) -> None:
    """The run ended at SAMPLE ``seq`` with a message naming the rig, the seq, the rig's fault and ``needles``;
    the log holds every sample before it; the fake got STOP 3 after the last answer."""
    for needle in (fake.url, f"SAMPLE {seq}", FAULT, f"the log up to SAMPLE {seq - 1} is kept", *needles):
        assert needle in run.ended, (needle, run.ended)
    assert run.log.timem.size == seq  # SAMPLE 0 (start) … seq−1: every block before the fault
    assert [c.seq for c in fake.sent_by_client(p.Command)] == list(range(seq))
    assert fake.sent_by_client(p.Stop) == [p.Stop(p.STOP_ERROR)]


# --- 1. SAMPLE times -----------------------------------------------------------------------------------
@pytest.mark.quick
def test_a_sample_whose_time_runs_backwards_ends_the_run_naming_it() -> None:
    samples = _samples(10)
    samples[6] = dataclasses.replace(samples[6], time_s=samples[4].time_s)
    fake = FakeRig(samples=samples)
    _, run = _run(fake)
    _assert_faulted(fake, run, 6, f"time_s = {samples[4].time_s!r} s", "backwards")


@pytest.mark.quick
def test_a_sample_that_jumps_a_million_seconds_ends_the_run_naming_it() -> None:
    samples = _samples(10)
    samples[5] = dataclasses.replace(samples[5], time_s=1e6)
    fake = FakeRig(samples=samples)
    _, run = _run(fake)
    _assert_faulted(fake, run, 5, "time_s = 1000000.0 s", "after its due time", "none in lock-step")
    assert run.log.timem.max() < 1.0  # the jump never entered the log, hence not the verdict's duration


@pytest.mark.quick
def test_a_sample_earlier_than_its_period_ends_the_run() -> None:
    samples = _samples(10)
    samples[3] = dataclasses.replace(samples[3], time_s=samples[2].time_s + PERIOD_S / 4)  # after, but early
    fake = FakeRig(samples=samples)
    _, run = _run(fake)
    _assert_faulted(fake, run, 3, "earlier than its due time")


@pytest.mark.quick
@pytest.mark.parametrize("time_s", [float("nan"), float("inf")])
def test_a_non_finite_sample_time_ends_the_run(time_s: float) -> None:
    samples = _samples(6)
    samples[2] = dataclasses.replace(samples[2], time_s=time_s)
    fake = FakeRig(samples=samples)
    _, run = _run(fake)
    _assert_faulted(fake, run, 2, f"time_s = {time_s!r} s: not a finite number")


@pytest.mark.quick
def test_in_real_time_a_late_block_is_allowed_up_to_its_bound_in_lockstep_none() -> None:
    """Real time (CONFIG mode 2): blocks late by 1.5 and 0.75 periods and then one back on the grid are taken (each
    still after the one before); one later than ``LATE_PERIODS`` is refused. Lock-step: a late block is refused."""
    late = _samples(8)
    late[3] = dataclasses.replace(late[3], time_s=late[3].time_s + 1.5 * PERIOD_S)
    late[4] = dataclasses.replace(late[4], time_s=late[4].time_s + 0.75 * PERIOD_S)
    fake = FakeRig(_config(mode=p.MODE_REALTIME), samples=late)
    _, run = _run(fake)
    assert run.ended == ENDED_LAST_SAMPLE and run.log.timem.size == 8
    too_late = _samples(8)
    too_late[3] = dataclasses.replace(too_late[3], time_s=too_late[3].time_s + (LATE_PERIODS + 1) * PERIOD_S)
    fake = FakeRig(_config(mode=p.MODE_REALTIME), samples=too_late)
    _, run = _run(fake)
    _assert_faulted(fake, run, 3, f"late allowed: {LATE_PERIODS} periods")
    fake = FakeRig(samples=late)
    _, run = _run(fake)
    _assert_faulted(fake, run, 3, "1.5 periods after its due time", "none in lock-step")


# --- 2. SAMPLE volts: the rig's fault, not the controller's ------------------------------------------------
@pytest.mark.quick
def test_a_nan_sample_is_the_rigs_fault_not_the_controllers(capsys: pytest.CaptureFixture[str]) -> None:
    samples = _samples(8)
    samples[4] = dataclasses.replace(samples[4], ball_v=float("nan"))
    fake = FakeRig(samples=samples)
    run, summary = _session(fake)
    assert run is not None  # the controller did not fail: the run is kept, and summarised
    _assert_faulted(fake, run, 4, "ball_v = nan V: not a finite number")
    assert summary["ended"] == run.ended and summary["ticks"] == 4
    err = capsys.readouterr().err
    assert "controller failed" not in err
    assert f"ballbeam run: the rig ended the run: {run.ended}" in err  # on stderr, not only in the summary


@pytest.mark.quick
def test_sample_volts_outside_the_adc_range_end_the_run() -> None:
    samples = _samples(8)
    samples[5] = dataclasses.replace(samples[5], angle_v=7.5)
    fake = FakeRig(samples=samples)
    _, run = _run(fake)
    _assert_faulted(fake, run, 5, "angle_v = 7.5 V: outside the ADC's range -5.0 … 5.0 V")
    # the range is the client's card's: a ±10 V card takes the same block
    fake = FakeRig(samples=samples)
    _, run = _run(fake, adc_range_v=(-10.0, 10.0))
    assert run.ended == ENDED_LAST_SAMPLE and run.log.timem.size == 8


# --- 3. BALL_LOST ------------------------------------------------------------------------------------------
@pytest.mark.quick
def test_the_run_ends_when_the_rig_reports_the_ball_lost_and_the_rig_is_told() -> None:
    """A rig that reports the ball lost and goes on: that sample is answered, the run ends ``ball lost`` (the
    summary's ``ended``) and the client sends STOP 2, so that the rig does not wait for the next command."""
    samples = _samples(12)
    for k in range(4, 12):
        samples[k] = dataclasses.replace(samples[k], flags=samples[k].flags | p.FLAG_BALL_LOST)
    fake = FakeRig(samples=samples)
    run, summary = _session(fake)
    assert run is not None and run.ended == ENDED_BALL_LOST
    assert summary["ended"] == ENDED_BALL_LOST and summary["ticks"] == 5
    assert [c.seq for c in fake.sent_by_client(p.Command)] == [0, 1, 2, 3, 4]  # the lost sample answered
    assert fake.sent_by_client(p.Stop) == [p.Stop(p.STOP_BALL_LOST)]


@pytest.mark.quick
def test_a_rig_that_stops_on_the_lost_ball_flags_it_last_and_ends_the_session_itself() -> None:
    samples = _samples(6)
    samples[5] = dataclasses.replace(samples[5], flags=p.FLAG_BALL_LOST | p.FLAG_LAST)
    fake = FakeRig(samples=samples, final_stop=p.STOP_BALL_LOST)
    run, summary = _session(fake)
    assert run is not None and run.ended == ENDED_LAST_SAMPLE and summary["ticks"] == 6
    assert [c.seq for c in fake.sent_by_client(p.Command)] == list(range(6))  # the last one answered too
    assert fake.sent_by_client(p.Stop) == []  # the rig ended it: nothing to tell


# --- 4–6. CONFIG --------------------------------------------------------------------------------------------
def _connect(fake: FakeRig, **kw: Any) -> RemoteRig:
    return RemoteRig("127.0.0.1", int(fake.url.rsplit(":", 1)[1]), **kw)


@pytest.mark.quick
@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"zero_command_v": 99.0}, "CONFIG zero_command_v = 99.0: outside the DAC range"),
        ({"ball_block": 7}, "CONFIG ball_block = 7: an undefined block reduction"),
        ({"angle_block": 2}, "CONFIG angle_block = 2: an undefined block reduction"),
        ({"watchdog_periods": 0}, "CONFIG watchdog_periods = 0"),
        ({"period_s": 0.0}, "daq.period_s = 0.0"),
        ({"sample_rate_hz": float("nan")}, "CONFIG sample_rate_hz = nan: not a finite number"),
        ({"dac_min_v": 5.0, "dac_max_v": 0.0}, "daq.dac_max_v = 0.0 V must exceed daq.dac_min_v = 5.0 V"),
    ],
)
def test_a_config_out_of_its_range_is_refused_naming_field_and_value(
    changes: dict[str, Any], needle: str
) -> None:
    fake = FakeRig(_config(**changes))
    with fake, pytest.raises(RemoteError) as caught:
        _connect(fake, connect_timeout_s=5.0)
    message = str(caught.value)
    for part in (fake.url, needle, FAULT, "1 CONFIG received, 1 refused"):
        assert part in message, (part, message)
    assert fake.configs_sent == 1  # refused at once: no waiting out the timeout
    with pytest.raises(p.FieldError, match=needle.split(":")[0]):  # every receiver's decode refuses it
        p.decode(p.encode(_config(**changes), 1))


@pytest.mark.quick
def test_configs_refused_until_the_timeout_are_counted_in_the_message() -> None:
    good = bytearray(p.encode(_config(), SESSION))
    good[-1] ^= 0xFF  # a CRC that does not match: not the rig's field, perhaps the line: wait for a good one
    fake = FakeRig(bytes(good))
    with fake, pytest.raises(RemoteError) as caught:
        _connect(fake, connect_timeout_s=1.0)
    message = str(caught.value)
    n = fake.configs_sent
    assert n >= 3 and f"{n} CONFIG received, {n} refused" in message, message
    assert (
        "no acceptable CONFIG" in message
        and "crc" in message
        and "is `ballbeam serve` running" not in message
    )


@pytest.mark.quick
def test_a_role_other_than_the_one_asked_for_is_refused() -> None:
    fake = FakeRig(_config(role=p.ROLE_OBSERVE))
    with fake, pytest.raises(RemoteError) as caught:
        _connect(fake)
    message = str(caught.value)
    assert "granted the role 2 (observe) to a HELLO asking for 1 (control)" in message and FAULT in message


# --- 7. sequence gaps ---------------------------------------------------------------------------------------
@pytest.mark.quick
def test_sequence_gaps_are_counted_and_reported_in_the_summary() -> None:
    samples = [s for s in _samples(12) if s.seq not in (3, 4, 8)]  # three blocks lost on the way
    fake = FakeRig(samples=samples)
    run, summary = _session(fake)
    assert run is not None and run.ended == ENDED_LAST_SAMPLE and run.log.timem.size == 9
    assert summary["sequence_gaps"] == 3
    fake = FakeRig(samples=_samples(6))
    _, summary = _session(fake)
    assert summary["sequence_gaps"] == 0


# --- 8. names from the network ------------------------------------------------------------------------------
HOSTILE = "\x1b[2J\x1b[H\nheld: True\x07\\"


@pytest.mark.quick
def test_printable_escapes_control_characters_and_bounds_the_length() -> None:
    shown = p.printable(HOSTILE)
    assert shown == "\\x1b[2J\\x1b[H\\x0aheld: True\\x07\\\\"
    assert all(" " <= c <= "~" for c in shown)
    assert p.printable("\ufffd") == "\\ufffd"
    assert len(p.printable("\x1b" * 40)) == p.NAME_LIMIT and p.printable("\x1b" * 40).endswith("...")
    assert p.printable("ballbeam-twin 0.1.0 twin") == "ballbeam-twin 0.1.0 twin"


@pytest.mark.quick
def test_the_rigs_name_reaches_the_summary_escaped() -> None:
    fake = FakeRig(_config(rig=HOSTILE), samples=_samples(4))
    _, summary = _session(fake)
    assert summary["rig_identity"] == p.printable(HOSTILE[:40])
    assert "\x1b" not in summary["rig_identity"] and "\n" not in summary["rig_identity"]


@pytest.mark.quick
def test_the_clients_name_reaches_serves_summary_escaped() -> None:
    server = Server(SessionSettings(), "127.0.0.1", 0, log=lambda _: None)
    with server, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as client:
        client.sendto(p.encode(p.Hello(client=HOSTILE), 0), ("127.0.0.1", server.port))
        deadline = time.monotonic() + 5.0
        while server.controller_addr is None and time.monotonic() < deadline:
            server.receive(0.2)
        assert server.client_name == p.printable(HOSTILE)
        assert "\x1b" not in server.client_name and "\n" not in server.client_name


# --- 9. view --serve: a HELLO alone does not hold the wire session ------------------------------------------
def _view_frames_until(live: Any, condition: Any, limit: int = 250) -> None:
    from twin.viewer import FRAME_S
    from twin.viewer.wire import WIRE_MARGIN_S

    for _ in range(limit):
        if condition():
            return
        end = time.perf_counter() + FRAME_S
        live.tick(end - WIRE_MARGIN_S)
        time.sleep(max(end - time.perf_counter(), 0.0))
    raise AssertionError("the condition did not come within the frames")


@contextmanager
def _view(timeout_s: float) -> Iterator[tuple[Any, Server]]:
    from controllers.thesis_numbers import HARDWARE_STARTS
    from twin.viewer import LiveTwin
    from twin.viewer.wire import WireCatalogue

    server = Server(
        SessionSettings(mode=p.MODE_REALTIME, timeout_s=timeout_s), "127.0.0.1", 0, log=lambda _: None
    )
    try:
        catalogue = WireCatalogue(registry, server)
        live = LiveTwin(Parameters(), catalogue, catalogue.name, seed=0, speed=1.0)
        live.apply("initial", HARDWARE_STARTS["Fig 6.16 (state feedback)"])
        live.apply("reset")
        yield live, server
        live.close()
    finally:
        server.close()


@pytest.mark.realtime
def test_a_hello_alone_loses_the_view_session_after_the_timeout_and_a_new_client_takes_it() -> None:
    """``view --serve``: one HELLO takes the session, its held sample is never acknowledged; within the server's
    ``timeout_s`` (``serve --timeout``'s) the session ends with STOP 3, and another client's HELLO gets the
    control of the next session (CONFIG role 1, its held SAMPLE 0) and releases the run."""
    with _view(timeout_s=0.4) as (live, server):
        squatter = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        squatter.settimeout(5.0)
        squatter.sendto(p.encode(p.Hello(client="squatter"), 0), ("127.0.0.1", server.port))
        wire = live.wire
        _view_frames_until(live, lambda: wire.phase == "held")
        first = server.session
        t0 = time.monotonic()
        _view_frames_until(live, lambda: wire.phase == "waiting")
        assert 0.35 <= time.monotonic() - t0 < 2.0  # the server's timeout, not Reset
        stops = []
        while not stops:
            msg = p.decode(squatter.recv(4096))
            stops = [msg] if isinstance(msg, p.Stop) else []
        assert stops == [p.Stop(p.STOP_ERROR)] and server.session != first
        newcomer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        newcomer.settimeout(5.0)
        newcomer.sendto(p.encode(p.Hello(client="newcomer"), 0), ("127.0.0.1", server.port))
        _view_frames_until(live, lambda: wire.phase == "held")
        config = p.decode_frame(newcomer.recv(4096))
        held = p.decode_frame(newcomer.recv(4096))
        assert isinstance(config.msg, p.Config) and config.msg.role == p.ROLE_CONTROL
        assert config.session == server.session != first and server.client_name == "newcomer"
        assert isinstance(held.msg, p.Sample) and held.msg.seq == 0 and held.msg.flags & p.FLAG_HELD
        newcomer.sendto(
            p.encode(p.Command(0, config.msg.zero_command_v), server.session), ("127.0.0.1", server.port)
        )
        _view_frames_until(live, lambda: wire.released)
        squatter.close()
        newcomer.close()
