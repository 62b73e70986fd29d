"""The live view under hostile input: nothing a client sends stops the server or changes the state it should
not change.

Fast unit tests drive ``LiveTwin.apply`` with bad values, failing controllers and rigs, the pacing's debt and
the origin policy. The slow test starts ``serve`` in-process on a free port and talks to it over a real
websocket the way viser's client does (msgpack frames, a ``viser-v…`` subprotocol, a camera message first):
out-of-range, non-finite and unknown values for every control, values of the wrong type, other properties
than a value, malformed, oversized and unknown frames, a client that never reads, a flood, the share tunnel,
failing controllers, and handshakes from a foreign ``Origin`` or ``Host``. After each case the server is
alive, its simulated time advances and a refused value left the state unchanged. The pace itself (50 Hz ± 1 %
at ×1) is asserted by ``realtime`` tests, which run alone: beside a client that never reads, and at the end
of the file, after every case (a file's tests run on one worker, in order, against the module's one server)."""

from __future__ import annotations

import contextlib
import math
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

import msgspec
import numpy as np
import pytest
import viser
import websockets.exceptions
import websockets.sync.client
import zstandard
from viewer_stubs import StubCatalogue

import twin.viewer as viewer_module
from controllers import registry
from twin.interface import Controller, DaqSample
from twin.parameters import Parameters
from twin.viewer import (
    FRAME_S,
    MAX_OWED_S,
    SPEED_MAX,
    LiveTwin,
    OriginPolicy,
    ViewerError,
    owe,
    serve,
)
from twin.viewer.security import control_uuid, download_bytes_queued

PROTOCOL = f"viser-v{viser.__version__}"
CAMERA = {
    "type": "ViewerCameraMessage",
    "wxyz": [1.0, 0.0, 0.0, 0.0],
    "position": [0.16, -0.58, 0.36],
    "fov": 1.0,
    "near": 0.01,
    "far": 100.0,
    "image_height": 600,
    "image_width": 800,
    "look_at": [0.16, 0.0, 0.25],
    "up_direction": [0.0, 0.0, 1.0],
}


# --- a catalogue with controllers that fail ---------------------------------------------------------------
class _Failing(Controller):
    """Returns a NaN command, or raises, from its fourth tick on."""

    def __init__(self, name: str, failure: float | Exception) -> None:
        super().__init__()
        self.name, self.failure, self.ticks = name, failure, 0

    def start(self, sample: DaqSample) -> None:
        self.ticks = 0

    def update(self, sample: DaqSample) -> float:
        self.ticks += 1
        if self.ticks < 4:
            return 2.5
        if isinstance(self.failure, Exception):
            raise self.failure
        return self.failure


class _Catalogue(StubCatalogue):
    def __init__(self) -> None:
        super().__init__(
            {
                "test-nan": lambda params: _Failing("test-nan", math.nan),
                "test-raises": lambda params: _Failing("test-raises", RuntimeError("boom")),
            }
        )


CATALOGUE = _Catalogue()


# --- unit level: LiveTwin.apply ---------------------------------------------------------------------------
def _state(live: LiveTwin) -> tuple:
    return (
        live.x0_m,
        live.theta0_rad,
        live.speed,
        live.controller_name,
        live.reference_x_m,
        live.noise,
        live.running,
        live.runs,
        live.error,
    )


BAD_VALUES = [
    ("x0", 5.0, "outside"),
    ("x0", math.nan, "not a finite number"),
    ("x0", -math.inf, "not a finite number"),
    ("x0", "0.1", "not a number"),
    ("x0", True, "not a number"),
    ("x0", 10**400, "not a finite number"),
    ("theta0", 2.0, "outside"),
    ("theta0", math.nan, "not a finite number"),
    ("initial", (0.1,), "not a pair"),
    ("initial", (0.1, 9.0), "outside"),
    ("initial", "ab", "not a pair"),
    ("controller", "no-such-controller", "unknown controller"),
    ("controller", 42, "unknown controller"),
    ("controller", None, "unknown controller"),
    ("flick", math.nan, "not a finite number"),
    ("flick", 1e300, "outside"),
    ("flick", -1.5, "outside"),
    ("speed", 1e9, "outside"),
    ("speed", math.nan, "not a finite number"),
    ("speed", -1.0, "outside"),
    ("speed", 0.0, "outside"),
    ("reference", math.nan, "not a finite number"),
    ("reference", 1.0, "outside"),
    ("noise", "yes", "not a boolean"),
    ("noise", 1, "not a boolean"),
    ("run", "no", "not a boolean"),
    ("launch-missiles", 1, "unknown action"),
    (None, None, "unknown action"),
]


@pytest.fixture(scope="module")
def live() -> LiveTwin:
    return LiveTwin(Parameters(), CATALOGUE, "lqr", 0, 1.0)


@pytest.mark.parametrize(
    ("action", "value", "why"), BAD_VALUES, ids=[f"{a}={v!r}"[:40] for a, v, _ in BAD_VALUES]
)
def test_a_bad_value_is_refused_and_changes_nothing(
    live: LiveTwin, action: Any, value: Any, why: str
) -> None:
    live.tick()
    before, refused, t = _state(live), live.refused, live.rig.time_s
    live.enqueue(action, value)
    live.apply_actions()
    assert live.refused == refused + 1
    assert why in live.refusals[-1].reason
    assert _state(live) == before
    assert live.rig.time_s == t  # the run was not restarted or stepped
    live.tick()
    assert live.error is None and live.rig.time_s > t


def test_a_flick_that_is_refused_leaves_the_ball_alone(live: LiveTwin) -> None:
    live.tick()
    ball = live.rig.true_state().copy()
    live.apply("flick", math.inf)
    np.testing.assert_array_equal(live.rig.true_state(), ball)


@pytest.mark.quick
def test_good_values_are_applied(live: LiveTwin) -> None:
    refused, runs = live.refused, live.runs
    for action, value in [
        ("x0", -0.2),
        ("theta0", 0.3),
        ("speed", 4.0),
        ("reference", 0.1),
        ("noise", False),
    ]:
        live.apply(action, value)
    live.apply("flick", -0.4)
    live.apply("reset")
    assert live.refused == refused
    assert (live.x0_m, live.theta0_rad, live.speed, live.reference_x_m, live.noise) == (
        -0.2,
        0.3,
        4.0,
        0.1,
        False,
    )
    assert live.runs == runs + 1 and live.rig.true_state()[0] == -0.2
    assert live.controller.setpoint_m == 0.1  # lqr follows the setpoint


def test_the_controls_follow_a_narrowed_track_and_stops() -> None:
    """Values inside the sliders' own ranges (±0.3 m, ±0.7 rad, ±0.2 m) are off a narrowed track or past
    narrowed stops: refused, and the default start is inside them."""
    params = Parameters().with_overrides({"track.half_length_m": 0.12, "beam.stop_angle_rad": 0.3})
    live = LiveTwin(params, CATALOGUE, "appendix-clp", 0, 1.0)
    assert abs(live.x0_m) <= 0.12 and abs(live.theta0_rad) <= 0.3
    for action, value in [("x0", 0.25), ("theta0", 0.6), ("reference", 0.15), ("initial", (0.2, 0.0))]:
        before = _state(live)
        live.apply(action, value)
        assert "outside" in live.refusals[-1].reason
        assert _state(live) == before
    live.apply("reset")
    live.tick()
    assert live.error is None


@pytest.mark.parametrize(
    ("name", "reason"),
    [("test-nan", "the DAC command must be a finite number"), ("test-raises", "raised RuntimeError")],
)
def test_a_failing_controller_marks_the_run_failed(name: str, reason: str) -> None:
    live = LiveTwin(Parameters(), CATALOGUE, "appendix-clp", 0, 1.0)
    live.apply("controller", name)
    for _ in range(5):
        live.tick()
    assert live.error is not None and reason in live.error and "tick k = " in live.error
    assert not live.running and live.failures == 1
    t = live.rig.time_s
    live.tick()
    assert live.rig.time_s == t  # a failed run stays where it failed
    live.apply("run", True)
    assert not live.running  # and cannot be resumed
    assert "run failed" in live.status_markdown()
    live.apply("controller", "appendix-clp")
    live.apply("run", True)
    live.tick()
    assert live.error is None and live.running and live.rig.time_s > 0


@pytest.mark.quick
@pytest.mark.parametrize(
    "exc", [FloatingPointError("MuJoCo state is not finite"), ValueError("off the track")]
)
def test_a_failing_rig_marks_the_run_failed(exc: Exception, monkeypatch: pytest.MonkeyPatch) -> None:
    live = LiveTwin(Parameters(), CATALOGUE, "appendix-clp", 0, 1.0)
    live.tick()

    def broken() -> None:
        raise exc

    monkeypatch.setattr(live.rig, "read", broken)
    live.tick()
    assert live.error is not None and type(exc).__name__ in live.error and "at tick k = " in live.error
    live.apply("step")  # stepping a failed run does nothing, raises nothing
    monkeypatch.setattr(live.rig, "kick_ball", broken)
    live.apply("flick", 0.1)  # an action the rig fails on fails the run, not the caller
    assert live.failures == 2
    live.apply("reset")  # a new rig: running again
    assert live.error is None


def test_a_controller_that_cannot_start_is_refused() -> None:
    class Broken(_Catalogue):
        def make(self, name: str, params: Parameters | None = None) -> Any:
            if name == "test-raises":
                raise RuntimeError("cannot build")
            return super().make(name, params)

    live = LiveTwin(Parameters(), Broken(), "appendix-clp", 0, 1.0)
    before = _state(live)
    live.apply("controller", "test-raises")
    assert "cannot build" in live.refusals[-1].reason and _state(live) == before
    with pytest.raises(ViewerError, match="cannot build"):
        LiveTwin(Parameters(), Broken(), "test-raises", 0, 1.0)


@pytest.mark.quick
def test_refusals_and_failures_cannot_inject_markup_into_the_status(live: LiveTwin) -> None:
    live.apply("controller", "<img src=x onerror=alert(1)>[link](javascript:alert(1))")
    status = live.status_markdown()
    assert "<img" not in status and "](" not in status and "&lt;img" in status


@pytest.mark.quick
@pytest.mark.parametrize("speed", [1e9, math.inf, math.nan, -1.0, 0.0, 1.0, SPEED_MAX])
def test_the_pacing_debt_never_exceeds_a_few_frames(speed: float) -> None:
    owed = 0.0
    for _ in range(1000):
        owed = owe(owed, speed)
        assert 0.0 <= owed <= MAX_OWED_S <= 5 * FRAME_S + 1e-12
        while owed >= FRAME_S - 1e-12:
            owed -= FRAME_S
    assert owe(math.nan, 1.0) == FRAME_S


@pytest.mark.quick
def test_the_origin_policy() -> None:
    loop = OriginPolicy.for_bind("127.0.0.1", 8080)
    for host, origin in [
        ("127.0.0.1:8080", "http://127.0.0.1:8080"),
        ("localhost:8080", "http://localhost:8080"),
    ]:
        assert loop.refusal([host], [origin], websocket=True) is None
    refused = [
        (["127.0.0.1:8080"], ["http://evil.example"]),
        (["127.0.0.1:8080"], ["http://127.0.0.1:8081"]),
        (["127.0.0.1:8080"], ["https://127.0.0.1:8080"]),
        (["127.0.0.1:8080"], ["null"]),
        (["127.0.0.1:8080"], []),  # a websocket must say where it comes from
        (["127.0.0.1:8080"], ["http://127.0.0.1:8080", "http://evil.example"]),
        (["evil.example:8080"], ["http://evil.example:8080"]),  # DNS rebinding
        (["127.0.0.1:8081"], ["http://127.0.0.1:8080"]),
        ([], ["http://127.0.0.1:8080"]),
        (["127.0.0.1:8080", "evil.example:8080"], ["http://127.0.0.1:8080"]),
        (["user@127.0.0.1:8080"], ["http://127.0.0.1:8080"]),
        (["127.0.0.1:80x"], ["http://127.0.0.1:8080"]),
    ]
    for hosts, origins in refused:
        assert loop.refusal(hosts, origins, websocket=True) is not None, (hosts, origins)
    assert loop.refusal(["127.0.0.1:8080"], [], websocket=False) is None  # the page itself
    assert loop.refusal(["evil.example:8080"], [], websocket=False) is not None

    lan = OriginPolicy.for_bind("192.168.7.7", 9000, ("https://twin.lab.example",))
    assert lan.refusal(["192.168.7.7:9000"], ["http://192.168.7.7:9000"], websocket=True) is None
    assert lan.refusal(["192.168.7.7:9000"], ["https://twin.lab.example"], websocket=True) is None
    assert lan.refusal(["twin.lab.example:443"], ["https://twin.lab.example"], websocket=True) is None
    assert lan.refusal(["192.168.7.7:9000"], ["http://127.0.0.1:9000"], websocket=True) is not None

    every = OriginPolicy.for_bind("0.0.0.0", 9000)
    assert every.refusal(["10.1.2.3:9000"], ["http://10.1.2.3:9000"], websocket=True) is None
    assert every.refusal(["[fe80::1]:9000"], ["http://[fe80::1]:9000"], websocket=True) is None
    assert every.refusal(["10.1.2.3:9000"], ["http://10.9.9.9:9000"], websocket=True) is not None
    assert every.refusal(["evil.example:9000"], ["http://evil.example:9000"], websocket=True) is not None

    for bad in ["*", "evil.example", "ftp://x", "http://x/path", 7]:
        with pytest.raises(ViewerError, match="allowed origin"):
            OriginPolicy.for_bind("127.0.0.1", 8080, (bad,))  # type: ignore[arg-type]


@pytest.mark.quick
def test_a_speed_outside_the_slider_is_refused_at_start() -> None:
    for speed in (10.0, 0.0, math.nan):
        with pytest.raises(ViewerError, match="--speed"):
            serve(registry, speed=speed, port=1, announce=False)


# --- the server over a real websocket ---------------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(condition: Callable[[], bool], timeout: float = 10.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.005)


class Server:
    def __init__(self) -> None:
        self.port = _free_port()
        self.stop = threading.Event()
        ready = threading.Event()
        self.viewer: Any = None
        self.failure: BaseException | None = None

        def on_ready(viewer: Any) -> None:
            self.viewer = viewer
            ready.set()

        def run() -> None:
            try:
                serve(
                    CATALOGUE,
                    port=self.port,
                    stop=self.stop,
                    on_ready=on_ready,
                    announce=False,
                    allowed_origins=("https://twin.lab.example",),
                )
            except BaseException as exc:  # the test reports it: the server must never die
                self.failure = exc
                raise

        self.thread = threading.Thread(target=run, daemon=True)
        self.thread.start()
        assert ready.wait(60), "the viewer did not start"
        self.live: LiveTwin = self.viewer.live

    def uuid(self, control: str) -> str:
        return control_uuid(self.viewer.controls[control])

    def assert_alive_and_ticking(self) -> None:
        """The server thread runs, the twin runs at ×1 (put back to it if a case changed it) and its simulated
        time advances, and the pacing owes no more than its bound. Nothing here reads the wall clock: the
        pace itself is ``assert_paced``'s, in the realtime tests."""
        live = self.live
        assert self.thread.is_alive() and self.failure is None
        if live.error is not None or not live.running or live.speed != 1.0:
            runs = live.runs
            for action, value in [
                ("controller", "appendix-clp"),
                ("reset", None),
                ("speed", 1.0),
                ("run", True),
            ]:
                live.enqueue(action, value)
            _wait(
                lambda: live.runs > runs and live.pending_actions == 0 and live.running and live.speed == 1.0,
                what="a running twin",
            )
        t = live.rig.time_s
        _wait(lambda: live.rig.time_s > t, what="the simulated time to advance")
        assert self.viewer.max_owed_s <= MAX_OWED_S + 1e-12

    def assert_paced(self) -> None:
        """Alive and ticking, and the simulated time advances at 50 Hz ± 1 % (×1): the slope of the simulated
        time against the wall clock at each 20 ms step, over 0.7 s. A wall-clock pace: only realtime tests
        call it (tests/test_realtime_markers.py)."""
        self.assert_alive_and_ticking()
        live = self.live
        time.sleep(0.3)  # building a new run's model (above) held the loop; it has caught up since
        steps = []
        last = live.rig.time_s
        start = time.perf_counter()
        while (now := time.perf_counter()) - start < 0.7:
            t = live.rig.time_s
            if t != last:
                steps.append((now, t))
                last = t
            time.sleep(0.001)
        # Theil-Sen: the median of the pairwise slopes, blind to a hiccup of a loaded machine that the pacing
        # catches up on, not to a rate that is off.
        wall, sim = np.array(steps).T
        i, j = np.triu_indices(wall.size, k=5)
        slope = float(np.median((sim[j] - sim[i]) / (wall[j] - wall[i])))
        assert abs(slope - 1.0) < 0.01, f"simulated time advances at {slope:.4f}× the wall clock"
        assert self.viewer.max_owed_s <= MAX_OWED_S + 1e-12


STALLED_RCVBUF_BYTES = 256 * 1024


class Client:
    """A websocket client that speaks viser's protocol: msgpack frames, the version subprotocol, a camera
    message first (viser runs GUI callbacks only for clients that sent one). It drains what the server sends
    unless ``read`` is false."""

    def __init__(self, server: Server, *, origin: str | None = None, read: bool = True) -> None:
        self.server = server
        origin = origin or f"http://127.0.0.1:{server.port}"
        sock = None
        if not read:
            # A fixed receive buffer: Linux autotunes an unset one up to net.ipv4.tcp_rmem's maximum (32 MiB on
            # some machines), which would take several files before the server saw a stalled browser.
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, STALLED_RCVBUF_BYTES)
            sock.connect(("127.0.0.1", server.port))
        self.ws = websockets.sync.client.connect(
            f"ws://127.0.0.1:{server.port}",
            sock=sock,
            origin=origin,
            subprotocols=[PROTOCOL],
            proxy=None,
            compression=None,
            max_size=None,
            max_queue=1 if not read else 4,  # a stalled browser: the fewest frames held on its side
            open_timeout=10,
            close_timeout=0.5,
        )
        self.closed: websockets.exceptions.ConnectionClosed | None = None
        self.received = 0
        self.notifications: list[tuple[str, str]] = []  # (title, body) of each notification shown
        if read:
            threading.Thread(target=self._drain, daemon=True).start()
        clients = len(server.viewer.server.get_clients())
        self.send(CAMERA)
        _wait(lambda: len(server.viewer.server.get_clients()) > clients, what="the client to register")

    def _drain(self) -> None:
        try:
            for frame in self.ws:
                self.received += 1
                for message in _messages(frame):
                    if message.get("type") == "NotificationShowMessage":
                        self.notifications.append((message["props"]["title"], message["props"]["body"]))
        except websockets.exceptions.ConnectionClosed as exc:
            self.closed = exc
        else:
            self.closed = self.ws.protocol.close_exc

    def send(self, message: Any) -> None:
        self.ws.send(message if isinstance(message, (bytes, str)) else msgspec.msgpack.encode(message))

    def set(self, control: str, value: Any) -> None:
        self.send(
            {"type": "GuiUpdateMessage", "uuid": self.server.uuid(control), "updates": {"value": value}}
        )

    def click(self, button: str) -> None:
        self.set(button, True)

    def wait_closed(self) -> int:
        _wait(lambda: self.closed is not None, what="the server to close the connection")
        assert self.closed is not None and self.closed.rcvd is not None
        return self.closed.rcvd.code

    def close(self) -> None:
        self.ws.close()


def _messages(frame: bytes | str) -> list[dict[str, Any]]:
    """The messages in one of viser's frames: two little-endian lengths, zstd-compressed msgpack, buffers."""
    assert isinstance(frame, bytes)
    size, compressed = int.from_bytes(frame[:8], "little"), int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16 : 16 + compressed], max_output_size=size)
    return list(msgspec.msgpack.decode(inner)["messages"])


def _handshake(port: int, host: str, origin: str | None, *, websocket: bool = True) -> str:
    """The status line the server answers a raw HTTP request with."""
    lines = ["GET / HTTP/1.1", f"Host: {host}"]
    if websocket:
        lines += [
            "Upgrade: websocket",
            "Connection: Upgrade",
            "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
            "Sec-WebSocket-Version: 13",
            f"Sec-WebSocket-Protocol: {PROTOCOL}",
        ]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        return s.recv(4096).split(b"\r\n")[0].decode()


@pytest.fixture(scope="module")
def server():
    server = Server()
    yield server
    server.stop.set()
    server.thread.join(timeout=20)
    assert server.failure is None


@pytest.fixture
def client(server: Server):
    viewer_module._log_last.clear()  # each case's first log line is printed (the log is rate-limited)
    c = Client(server)
    yield c
    c.close()
    server.assert_alive_and_ticking()


# Values the loop refuses: (control or button clicks after it, value, the state that must not change).
REFUSED = [
    ("x0", 5.0, ["reset"]),
    ("x0", math.nan, ["reset"]),
    ("x0", -math.inf, ["reset"]),
    ("theta0", 2.0, ["reset"]),
    ("theta0", math.nan, ["reset"]),
    ("controller", "no-such-controller", []),
    ("controller", "<img src=x onerror=alert(1)>", []),
    ("flick", math.nan, ["flick_right"]),
    ("flick", 1e300, ["flick_left"]),
    ("setpoint", math.nan, []),
    ("setpoint", 1.0, []),
    ("speed", 1e9, []),
    ("speed", math.nan, []),
    ("speed", -1.0, []),
    ("speed", 0.0, []),
]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("control", "value", "clicks"), REFUSED, ids=[f"{c}={v!r}"[:40] for c, v, _ in REFUSED]
)
def test_a_hostile_value_is_refused_over_the_websocket(
    server: Server, client: Client, control: str, value: Any, clicks: list[str]
) -> None:
    live = server.live
    if control == "setpoint":  # the NaN setpoint used to raise FloatingPointError inside lqr
        client.set("controller", "lqr")
        _wait(lambda: live.controller_name == "lqr", what="lqr")
    before = _state(live)
    refused = live.refused
    client.set(control, value)
    for button in clicks:
        client.click(button)
    _wait(lambda: live.refused > refused, what="the refusal")
    if "reset" in clicks:
        _wait(lambda: live.runs > before[7], what="the reset")
        assert live.rig.true_state()[0] == pytest.approx(before[0], abs=0.03)  # restarted from the same x0
    after = _state(live)
    assert after[:6] == before[:6]  # x0, θ0, speed, controller, setpoint, noise
    assert live.error is None
    assert "<img" not in live.status_markdown()
    _wait(lambda: any(title == "Refused" for title, _ in client.notifications), what="the notification")
    # The control is put back to the value the twin runs with.
    handle = server.viewer.controls[control]
    expected = {
        "x0": lambda: live.x0_m,
        "theta0": lambda: live.theta0_rad,
        "controller": lambda: live.controller_name,
        "flick": lambda: viewer_module.FLICK_DEFAULT_M_S,
        "setpoint": lambda: live.reference_x_m,
        "speed": lambda: live.speed,
    }[control]
    _wait(lambda: handle.value == expected(), what="the control to be put back")


# GUI messages dropped before viser applies them: (uuid of, updates).
DROPPED = [
    ("x0", {"value": "abc"}),  # a string for a slider: viser's float() would raise on its event loop
    ("x0", {"value": [1.0]}),
    ("noise", {"value": {"a": 1}}),
    ("controller", {"value": "x" * 10_000}),
    ("speed", {"update_cb": 1}),  # would replace viser's callbacks: the control would go dead
    ("speed", {"value": 2.0, "disabled": True}),
    ("speed", "not a dict"),
    (None, {"value": 1.0}),  # no such control
]


@pytest.mark.slow
@pytest.mark.parametrize(("control", "updates"), DROPPED, ids=[f"{c}:{u!r}"[:40] for c, u in DROPPED])
def test_a_message_that_is_not_a_controls_value_is_dropped(
    server: Server, client: Client, control: str | None, updates: Any
) -> None:
    live, viewer = server.live, server.viewer
    before, dropped = _state(live), viewer.dropped_messages
    uuid = server.uuid(control) if control else "no-such-uuid"
    client.send({"type": "GuiUpdateMessage", "uuid": uuid, "updates": updates})
    _wait(lambda: viewer.dropped_messages > dropped, what="the message to be dropped")
    assert _state(live)[:6] == before[:6]
    # The control still works.
    client.set("speed", 2.0)
    _wait(lambda: live.speed == 2.0, what="a good speed")
    client.set("speed", 1.0)
    _wait(lambda: live.speed == 1.0, what="speed back to 1")


# Frames the server must survive: (frame, the close code it answers with, or None if the connection stays
# open; the one log line it prints, if any).
FRAMES = [
    (b"\x00garbage\xc1", 1011, "websocket: connection handler failed"),  # not msgpack
    ("a text frame", 1011, "websocket: connection handler failed"),
    (msgspec.msgpack.encode(5), 1011, "websocket: connection handler failed"),  # msgpack, not a message
    (msgspec.msgpack.encode({"type": "NoSuchMessage"}), 1011, "websocket: connection handler failed"),
    (msgspec.msgpack.encode({"type": "GuiUpdateMessage"}), 1011, "websocket: connection handler failed"),
    (msgspec.msgpack.encode({**CAMERA, "position": None}), 1011, "websocket: connection handler failed"),
    # Well-formed, but a handler of viser's raises on it (an unhashable uuid).
    (
        msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": [1], "updates": {}}),
        None,
        "a client message failed",
    ),
    (msgspec.msgpack.encode({**CAMERA, "wxyz": [1.0]}), None, None),  # a short quaternion: viser warns
    (b"\x00" * (2 << 20), 1009, None),  # 2 MiB: over the 1 MiB limit, closed by the library
]


@pytest.mark.slow
@pytest.mark.parametrize(("frame", "code", "line"), FRAMES, ids=[repr(f)[:30] for f, _, _ in FRAMES])
def test_a_malformed_frame_is_one_log_line(
    server: Server,
    client: Client,
    frame: bytes | str,
    code: int | None,
    line: str | None,
    capfd: pytest.CaptureFixture[str],
) -> None:
    with contextlib.suppress(websockets.exceptions.ConnectionClosed):  # closed while still sending
        client.send(frame)
    if code is not None:
        assert client.wait_closed() == code
    else:
        time.sleep(0.3)
        assert client.closed is None
    time.sleep(0.1)
    err = capfd.readouterr().err
    assert "Traceback" not in err
    if line is not None:
        assert len([text for text in err.splitlines() if line in text]) == 1, err


@pytest.mark.slow
def test_the_share_tunnel_cannot_be_requested(server: Server, client: Client) -> None:
    client.send({"type": "ShareUrlRequest"})
    time.sleep(0.5)
    assert server.viewer.server._share_tunnel is None


@pytest.mark.slow
def test_files_cannot_be_uploaded(server: Server, client: Client) -> None:
    start = {
        "type": "FileTransferStartUpload",
        "source_component_uuid": server.uuid("x0"),
        "transfer_uuid": "t",
        "filename": "big",
        "mime_type": "application/octet-stream",
        "part_count": 1000,
        "size_bytes": 10**9,
    }
    client.send(start)
    client.send(
        {
            "type": "FileTransferPart",
            "source_component_uuid": server.uuid("x0"),
            "transfer_uuid": "t",
            "part_index": 0,
            "content": bytes(500_000),
        }
    )
    time.sleep(0.3)
    assert not server.viewer.server.gui._current_file_upload_states


@pytest.mark.slow
@pytest.mark.realtime
def test_a_client_that_never_reads_does_not_stall_the_twin(server: Server, client: Client) -> None:
    stalled = Client(server, read=False)
    try:
        time.sleep(2.0)  # the server's frames pile up for it
        server.assert_paced()
    finally:
        stalled.close()


def _rss_mib() -> float:
    for line in open("/proc/self/status").read().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return math.nan


@pytest.mark.slow
def test_250_download_clicks_from_a_browser_that_does_not_read_hold_a_file_or_two(
    server: Server, client: Client, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each click used to queue another copy of the record for the browser (250 clicks of a full record:
    +985 MB): now a click while the last file still waits for that browser sends nothing. The file is a full
    record's size (3.9 MB: 10 min of 17 columns), so that the socket's own buffers cannot take it."""
    live, viewer = server.live, server.viewer
    payload = np.random.default_rng(0).bytes(3_871_496)  # incompressible, as a .mat of noisy data
    monkeypatch.setattr(live, "recording", lambda kind: ("ballbeam_run.mat", payload))
    stalled = Client(server, read=False)
    try:
        clients = viewer.server.get_clients()
        handle = clients[max(clients)]  # the stalled client's
        refused, applied, rss = viewer.panels.downloads_refused, live.actions_applied, _rss_mib()
        # The first files go: into the sockets' kernel buffers, the server's write buffer, the frame viser is
        # writing; then one waits in the client's buffer and every later click sends nothing. Clicked one at
        # a time until that happens (a burst would race viser's writer taking each file from the buffer), then
        # the rest in a burst.
        # How many files go before one waits depends on how viser bundles messages into frames under load
        # (one frame can carry several files); the server's share of them is what is bounded here.
        clicks, full = 0, False
        while clicks < 40 and not full:
            stalled.click("download_mat")
            clicks += 1
            target = applied + clicks
            _wait(lambda: live.actions_applied >= target, 30.0, "the click")  # noqa: B023 (waited on here)
            try:
                _wait(lambda: download_bytes_queued(handle) == 0, 2.0, "the file to leave the buffer")
            except AssertionError:
                full = True  # a file stayed in the buffer for 2 s: the pipe is full
        assert full, f"{clicks} files left the server for a browser that reads nothing"
        before_burst = viewer.panels.downloads_refused
        for _ in range(250 - clicks):
            stalled.click("download_mat")
        _wait(lambda: live.pending_actions == 0 and live.actions_applied >= applied + 250, 30.0, "the clicks")
        time.sleep(0.5)
        sent = 250 - (viewer.panels.downloads_refused - refused)
        assert viewer.panels.downloads_refused - before_burst == 250 - clicks  # the burst sent nothing
        assert 1 <= sent <= clicks
        assert download_bytes_queued(handle) <= 2 * len(payload)
        # A file in flight is held about four times (the parts, msgpack's frame, zstd's, the socket's): at most
        # five of them on the server, where 250 queued copies came to about a gigabyte.
        assert _rss_mib() - rss < 4 * 5 * len(payload) / 2**20
        server.assert_alive_and_ticking()
    finally:
        stalled.close()


@pytest.mark.slow
def test_a_flood_of_refused_values(server: Server, client: Client) -> None:
    live = server.live
    refused = live.refused
    for i in range(2000):
        client.set("speed", math.nan if i % 2 else 1e9)
    _wait(lambda: live.refused >= refused + 100, what="the flood to be refused")
    quiet = live.refused
    while True:  # until the flood is over: no refusal for half a second
        time.sleep(0.5)
        if live.refused == quiet and live.pending_actions == 0:
            break
        quiet = live.refused
    assert live.speed == 1.0 and server.viewer.controls["speed"].value == 1.0


@pytest.mark.slow
@pytest.mark.parametrize("name", ["test-nan", "test-raises"])
def test_a_failing_controller_fails_the_run_not_the_server(server: Server, client: Client, name: str) -> None:
    live = server.live
    client.set("controller", name)
    _wait(lambda: live.error is not None, what="the failure")
    assert name in live.error and "tick k = " in live.error
    assert "run failed" in live.status_markdown()
    client.set("controller", "appendix-clp")
    _wait(lambda: live.error is None, what="a new run")


@pytest.mark.slow
@pytest.mark.realtime  # the simulated time over a second of wall clock: a pace
def test_the_pacing_survives_a_speed_that_bypassed_the_checks(server: Server, client: Client) -> None:
    live = server.live
    live.speed = 1e9  # as if a value had slipped through: the loop must not hang or build a debt
    t = live.rig.time_s
    time.sleep(1.0)
    assert 0.5 < live.rig.time_s - t <= 1.05 * SPEED_MAX
    assert server.viewer.max_owed_s <= MAX_OWED_S + 1e-12
    live.speed = math.nan  # nor freeze
    time.sleep(0.1)
    t = live.rig.time_s
    time.sleep(0.3)
    assert live.rig.time_s == t  # a NaN speed owes nothing: the twin waits
    live.enqueue("speed", 1.0)


@pytest.mark.slow
def test_handshakes_from_elsewhere_are_refused(server: Server, capfd: pytest.CaptureFixture[str]) -> None:
    port = server.port
    own = f"http://127.0.0.1:{port}"
    refused = server.viewer.refused_connections
    cases = [
        (f"127.0.0.1:{port}", "http://evil.example"),  # another site in the user's browser
        (f"127.0.0.1:{port}", None),
        (f"127.0.0.1:{port}", "null"),  # a sandboxed frame or a file
        (f"evil.example:{port}", f"http://evil.example:{port}"),  # DNS rebinding
        (f"127.0.0.1:{port}", f"http://127.0.0.1:{port + 1}"),
    ]
    for host, origin in cases:
        assert _handshake(port, host, origin) == "HTTP/1.1 403 Forbidden", (host, origin)
    assert _handshake(port, f"evil.example:{port}", None, websocket=False) == "HTTP/1.1 403 Forbidden"
    assert server.viewer.refused_connections == refused + len(cases) + 1
    # The page's own origin, localhost, and an allowed extra origin are accepted; the page is served.
    assert _handshake(port, f"127.0.0.1:{port}", own) == "HTTP/1.1 101 Switching Protocols"
    assert (
        _handshake(port, f"localhost:{port}", f"http://localhost:{port}")
        == "HTTP/1.1 101 Switching Protocols"
    )
    assert (
        _handshake(port, f"127.0.0.1:{port}", "https://twin.lab.example")
        == "HTTP/1.1 101 Switching Protocols"
    )
    assert _handshake(port, f"127.0.0.1:{port}", None, websocket=False) == "HTTP/1.1 200 OK"
    with pytest.raises(websockets.exceptions.InvalidStatus, match="403"):
        Client(server, origin="http://evil.example")
    for garbage in [b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03" + bytes(300), b"GET / HTTP/1.1\r\nHost"]:
        with socket.create_connection(("127.0.0.1", port), timeout=10) as s:  # TLS on http; a cut request
            s.sendall(garbage)
            s.shutdown(socket.SHUT_WR)
            s.recv(4096)
    time.sleep(0.2)
    assert "Traceback" not in capfd.readouterr().err
    server.assert_alive_and_ticking()


def test_a_host_other_than_loopback_is_served_with_a_warning(capfd: pytest.CaptureFixture[str]) -> None:
    serve(registry, host="0.0.0.0", port=_free_port(), duration_s=0.1, announce=False)
    err = capfd.readouterr().err
    assert "warning: serving on every interface" in err and "anyone" in err and "no authentication" in err
    serve(registry, port=_free_port(), duration_s=0.1, announce=False)
    assert "warning" not in capfd.readouterr().err


@pytest.mark.slow
def test_thesis_sf_overflowing_fails_its_run_and_the_view_goes_on() -> None:
    """The printed chapter 5 state feedback's observer overflows after 214 s (a minute at ×4). It diverges the
    same way on the reference plant with ideal sensors, which is four times faster to run."""
    live = LiveTwin(Parameters(), registry, "thesis-sf", 0, 4.0, plant="reference", ideal_sensors=True)
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(11_000):
            live.tick()
            if live.error is not None:
                break
    assert live.error is not None and "thesis-sf" in live.error and "tick k = " in live.error
    for key in ("x_est", "err_xdot"):
        assert not np.isinf(live.history.array(key)).any()  # the plots get gaps, not infinities


def test_a_lost_ball_pauses_the_run_until_reset() -> None:
    """The printed chapter 5 state feedback loses the ball within seconds: the run pauses itself with the
    ball where it left, the status says so, and Reset starts again with the ball on the beam."""
    live = LiveTwin(Parameters(), CATALOGUE, "thesis-sf", 0, 1.0, plant="reference", ideal_sensors=True)
    for _ in range(500):
        if live.running:
            live.tick()
    assert live.rig.ball_lost and live.lost_paused and not live.running
    left = live.rig.true_state()
    assert "Reset starts again" in live.status_markdown()
    live.enqueue("reset")
    live.apply_actions()
    assert not live.rig.ball_lost and not live.lost_paused
    assert abs(left[0]) > 0.3


@pytest.mark.quick
def test_a_setpoint_for_a_controller_without_one_is_refused_and_not_kept() -> None:
    """The greyed setpoint slider's number box still sends values: for a controller that declares no setpoint
    (appendix-clp) the value is refused with the reason, and the next controller with one starts from the
    setpoint it had, not from the refused value."""
    live = LiveTwin(Parameters(), CATALOGUE, "appendix-clp", 0, 1.0)
    before = live.reference_x_m
    live.apply("reference", 0.1)
    assert live.refusals[-1].reason == live.setpoint_reason and "declares no setpoint" in live.setpoint_reason
    assert live.reference_x_m == before


@pytest.mark.slow
@pytest.mark.realtime
def test_after_every_hostile_case_the_view_keeps_its_pace(server: Server) -> None:
    """The last test of the file (a file runs on one worker, in order): the module's server took every case
    above, each ending alive and ticking, and its simulated time still advances at 50 Hz ± 1 % (×1)."""
    server.assert_paced()
