"""The live view's memory stays bounded under a flood of GUI messages.

What grew (303 → 465 MB over 55 600 messages): each tick of "Shadow the rig" started a new shadow worker, a
thread building a band of the twin's own runs (tens of seconds of a core and the band's memory each), while
unticking only queued a stop that the builder read once its band was done; so a flood of toggles piled
builders up. Now a stop abandons the build at its next progress report, and a tick before the stopped worker
has ended takes the stop back: one builder at most. A refused download click (the last file still on its way)
no longer shows a notification per click, which a browser that reads nothing would hold one of per click.

The quick tests count the builders and the notifications; the slow one floods a real ``ballbeam view`` over
its websocket (the controls' own messages, refused and accepted values, the shadow toggled, downloads
clicked) and bounds the growth of the view's resident memory after a warm-up flood."""

from __future__ import annotations

import math
import os
import random
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import msgspec
import pytest
import viser
import websockets.exceptions
import websockets.sync.client
import zstandard
from test_viewer_hostile import CAMERA

import twin.viewer.gui as gui
from controllers import registry
from twin.parameters import Parameters
from twin.viewer import LiveTwin

ROOT = Path(__file__).resolve().parent.parent


class _Monitor:
    """A monitor that never scores a window (the builds are what is counted here)."""

    threshold = 7.0
    alarmed = False

    def add(self, *sample: Any) -> None:
        pass

    def new_session(self) -> None:
        pass

    def pending(self) -> int:
        return 0

    def process(self) -> list[Any]:
        return []


class _Factory:
    """A shadow factory whose band takes until ``done`` is set to build; it counts the builds started and
    running. With ``reports`` it takes ``progress`` and reports every 5 ms, as ``view_monitor``'s does."""

    def __init__(self, reports: bool) -> None:
        self.done = threading.Event()
        self.started = 0
        self.running = 0
        self._lock = threading.Lock()
        self.reports = reports

    def _build(self, progress: Any) -> _Monitor:
        with self._lock:
            self.started += 1
            self.running += 1
        try:
            while not self.done.wait(0.005):
                if progress is not None:
                    progress(0.5)
            return _Monitor()
        finally:
            with self._lock:
                self.running -= 1

    def make(self) -> Any:
        if self.reports:
            return lambda _p, progress=None: self._build(progress)
        return lambda _p: self._build(None)


def _wait(condition: Any, what: str, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


@pytest.mark.quick
@pytest.mark.parametrize("reports", [True, False], ids=["progress", "no-progress"])
def test_a_flood_of_shadow_toggles_builds_one_band_at_a_time(reports: bool) -> None:
    """1000 toggles of the shadow while its band builds: one builder (each used to start its own: 500)."""
    factory = _Factory(reports)
    live = LiveTwin(Parameters(), registry, "appendix-sf", 0, 1.0, monitor=factory.make())
    try:
        for i in range(1000):
            live.apply("shadow", i % 2 == 0)
            assert factory.running <= 2, f"{factory.running} bands building after {i + 1} toggles"
        assert live.shadow is None
        assert factory.started <= (50 if reports else 1), f"{factory.started} builds started"
        if reports:  # switched off: the build is abandoned at its next progress report
            _wait(lambda: factory.running == 0, "the stopped build to end")
        live.apply("shadow", True)
        assert factory.running <= 1
        factory.done.set()
        shadow = live.shadow
        assert shadow is not None
        _wait(lambda: shadow.snapshot().ready, "the shadow to be built")
        assert shadow.alive
    finally:
        factory.done.set()
        live.close()


@pytest.mark.quick
def test_refused_download_clicks_show_a_notification_at_most_twice_a_second(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """1000 clicks while the last file waits for the browser: each is counted, one notification shows (one per
    click piled up in the buffer of a browser that reads nothing)."""
    shown: list[str] = []
    client = SimpleNamespace(
        add_notification=lambda title, body, **_kw: shown.append(body),
        send_file_download=lambda *a, **kw: pytest.fail("a file was sent while the last one waits"),
    )
    monkeypatch.setattr(gui, "download_bytes_queued", lambda _client: 3_000_000)
    now = [100.0]
    monkeypatch.setattr(gui, "time", SimpleNamespace(monotonic=lambda: now[0]))  # a clock of the test's
    panels = gui.Panels.__new__(gui.Panels)  # only what _send_download uses, no viser server
    panels.downloads_refused = 0
    panels._last_download_notice = -math.inf
    for _ in range(1000):
        panels._send_download(client, "run.mat", b"data")
    assert panels.downloads_refused == 1000
    assert shown == ["the previous download is still being sent"]
    now[0] += gui.NOTIFY_EVERY_S  # half a second later: the next click shows one again
    for _ in range(1000):
        panels._send_download(client, "run.mat", b"data")
    assert len(shown) == 2 and panels.downloads_refused == 2000


# --- a real `ballbeam view` flooded over its websocket ------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no VmRSS for process {pid}")


class _Browser:
    """A websocket speaking viser's protocol from the page's origin; it drains every frame and learns each
    control's uuid from the messages that add it (by label)."""

    def __init__(self, port: int) -> None:
        self.ws = websockets.sync.client.connect(
            f"ws://127.0.0.1:{port}",
            origin=f"http://127.0.0.1:{port}",  # type: ignore[arg-type]
            subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
            proxy=None,
            compression=None,
            max_size=None,
            open_timeout=30,
        )
        self.uuids: dict[str, str] = {}
        threading.Thread(target=self._drain, daemon=True).start()
        self.send(CAMERA)  # what a browser tab sends first

    def _drain(self) -> None:
        try:
            for frame in self.ws:
                assert isinstance(frame, bytes)
                size, compressed = int.from_bytes(frame[:8], "little"), int.from_bytes(frame[8:16], "little")
                inner = zstandard.ZstdDecompressor().decompress(
                    frame[16 : 16 + compressed], max_output_size=size
                )
                for message in msgspec.msgpack.decode(inner)["messages"]:
                    props = message.get("props")
                    if isinstance(props, dict) and isinstance(props.get("label"), str) and "uuid" in message:
                        self.uuids.setdefault(props["label"], message["uuid"])
        except websockets.exceptions.ConnectionClosed:
            pass

    def send(self, message: dict[str, Any]) -> None:
        self.ws.send(msgspec.msgpack.encode(message))

    def close(self) -> None:
        self.ws.close()


# (control label, the values sent, one picked at random each time): accepted and refused values of every
# control, the buttons clicked, and the shadow ticked and unticked (a third of the flood).
FLOOD = [
    ("Speed", [1e9, math.nan, -1.0, 1.0, 2.0]),
    ("x0 (m)", [5.0, 0.1, -0.1, math.nan]),
    ("θ0 (rad)", [2.0, 0.05]),
    ("Setpoint x (m)", [1.0, 0.05, math.nan]),
    ("Flick (m/s)", [0.1, 1e300]),
    ("Flick ◀", [True]),
    ("Flick ▶", [True]),
    ("Reset", [True]),
    ("Step 20 ms", [True]),
    ("Sensor noise", [True, False]),
    ("Controller", ["lqr", "appendix-clp", "no-such-controller"]),
    ("Rig drift: motor R (+%)", [5.0, 500.0]),
    ("Download .mat", [True]),
    ("Download CSV", [True]),
    *[("Shadow the rig", [True, False])] * 7,
]
WARM_UP = 10_000  # messages before the baseline: every controller built, the first shadow band started
FLOOD_MESSAGES = 30_000
# Measured on this 2-core machine (loaded by other work), the view's RSS over the 30 000 messages after the
# warm-up: +3.3 and +4.2 MiB (about 0.13 KB a message; threads 37 → 37) with one builder at a time; +26.1 MiB
# and 22 more threads when each tick started a builder (the audit's 120 s flood: +162 MB, ~3 KB a message).
GROWTH_BOUND_MIB = 15.0


def _flood(browser: _Browser, n: int, rng: random.Random) -> None:
    """``n`` GUI messages in bursts of 100, 50 ms apart (about 2 000 a second: more than the loop applies)."""
    for i in range(n):
        label, values = rng.choice(FLOOD)
        browser.send(
            {
                "type": "GuiUpdateMessage",
                "uuid": browser.uuids[label],
                "updates": {"value": rng.choice(values)},
            }
        )
        if i % 100 == 99:
            time.sleep(0.05)


@pytest.mark.slow
def test_a_gui_flood_leaves_the_views_memory_bounded(tmp_path: Path) -> None:
    port = _free_port()
    log_path = tmp_path / "view.log"
    with open(log_path, "w") as log:
        view = subprocess.Popen(
            [sys.executable, "-m", "twin.app.cli", "view", "--port", str(port), "--duration", "900"],
            stdout=log,
            stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            cwd=tmp_path,
        )
    browser = None
    try:
        _wait(
            lambda: "ballbeam view: http://" in log_path.read_text() or view.poll() is not None,
            "the view",
            120,
        )
        assert view.poll() is None, log_path.read_text()
        browser = _Browser(port)
        _wait(lambda: all(label in browser.uuids for label, _ in FLOOD), "the controls", 60)
        rng = random.Random(0)
        _flood(browser, WARM_UP, rng)
        time.sleep(5.0)  # the queue drained
        before, threads_before = _rss_mib(view.pid), len(os.listdir(f"/proc/{view.pid}/task"))
        _flood(browser, FLOOD_MESSAGES, rng)
        time.sleep(5.0)
        after = _rss_mib(view.pid)
        threads = len(os.listdir(f"/proc/{view.pid}/task"))
        print(
            f"view RSS {before:.1f} → {after:.1f} MiB over {FLOOD_MESSAGES} messages; "
            f"threads {threads_before} → {threads}"
        )
        assert view.poll() is None, log_path.read_text()[-2000:]
        assert after - before < GROWTH_BOUND_MIB, (
            f"the view's memory grew {after - before:.1f} MiB over {FLOOD_MESSAGES} GUI messages "
            f"({before:.1f} → {after:.1f} MiB, {threads} threads)"
        )
        assert threads <= threads_before + 2, f"threads {threads_before} → {threads}"  # one shadow builder
    finally:
        if browser is not None:
            browser.close()
        view.terminate()
        view.wait(timeout=30)
