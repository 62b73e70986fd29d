"""The live view's server: viser with the origin policy installed, the scene and the panels around a
``LiveTwin``, and the loop that paces the simulation by the wall clock (``serve``, the entry point)."""

from __future__ import annotations

import functools
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import viser

from twin.engine import Catalogue
from twin.parameters import Parameters
from twin.rigs.warm import warm
from twin.serving.server import DEFAULT_TIMEOUT_S, ServeError, Server, SessionSettings
from twin.viewer.common import (
    DEFAULT_CONTROLLER,
    FRAME_S,
    SPEED_MAX,
    SPEED_MIN,
    ViewerError,
    _log,
)
from twin.viewer.gui import Panels
from twin.viewer.monitor import MonitorFactory
from twin.viewer.scene import Scene, rig_cameras, set_initial_camera
from twin.viewer.security import (
    OriginPolicy,
    _is_wildcard,
    _WebsocketHook,
    free_port_or_raise,
    gui_update_refusal,
    harden_messages,
    is_loopback,
)
from twin.viewer.session import LiveTwin, owe
from twin.viewer.wire import WIRE_MARGIN_S, WireCatalogue
from twin.wire import protocol as p

PLOT_EVERY_FRAMES = 10  # plots and status at 5 Hz: enough for the eye, a tenth of the traffic
MAX_CATCH_UP_S = 0.25  # after a stall longer than this the pacing restarts instead of racing to catch up
SPEED_WINDOW_S = 2.0  # the achieved speed is measured over the last 2 s of wall time
# A wire client's frame that starts with less than this left is re-anchored: the client gets a whole frame
# to answer (the rig's time then falls behind the wall clock, as the rig's timer skips a missed callback).
WIRE_MIN_WAIT_S = 0.005


class Viewer:
    """viser server + scene + panels around a ``LiveTwin``, paced by the wall clock."""

    def __init__(
        self,
        live: LiveTwin,
        host: str,
        port: int,
        allowed_origins: Sequence[str] = (),
        params_source: str = "",
    ) -> None:
        free_port_or_raise(host, port)
        self.live = live
        self.policy = OriginPolicy.for_bind(host, port, allowed_origins)
        self.refused_connections = 0  # handshakes refused by the origin policy
        self.dropped_messages = 0  # GUI messages dropped before viser applied them
        self.owed_s = self.max_owed_s = 0.0  # the pacing's debt now and at most (seconds of simulated time)
        hook = _WebsocketHook(self.policy, self._refused_connection)
        with hook.installed_on_viser():
            self.server = viser.ViserServer(host=host, port=port, verbose=False)
        if not hook.installed:
            self.server.stop()
            raise ViewerError(
                f"viser {viser.__version__} builds its websocket server differently from 1.1: the Origin/Host "
                "check cannot be installed, so the live view does not start"
            )
        if self.server.get_port() != port:
            self.server.stop()
            raise ViewerError(f"port {port} on {host} is taken; choose another with --port")
        self.host, self.port = host, port
        harden_messages(self.server, lambda message: gui_update_refusal(self.server, message), self._dropped)
        self.server.gui.configure_theme(show_share_button=False, control_width="medium")
        set_initial_camera(self.server, rig_cameras(live.params))
        self.scene = Scene(self.server, live)
        self.panels = Panels(self.server, live, params_source)
        self.server.on_client_connect(lambda _client: live.enqueue("connected"))
        self._frame_count = 0
        self._last_loop_error = ""

    @property
    def controls(self) -> dict[str, Any]:
        return self.panels.controls

    def _refused_connection(self, reason: str) -> None:
        self.refused_connections += 1
        _log(f"refused a connection: {reason}", key="refused connection")

    def _dropped(self, reason: str) -> None:
        self.dropped_messages += 1
        _log(f"dropped a GUI message: {reason}", key="dropped message")

    def report(self) -> None:
        self.panels.report()

    def publish(self) -> None:
        """Send one frame: body poses (and every tenth frame the plots and status), as one batch."""
        self._frame_count += 1
        with self.server.atomic():
            self.scene.update()
            if self._frame_count % PLOT_EVERY_FRAMES == 0 or not self.live.running:
                self.panels.update()

    def _safely(self, step: Callable[[], None]) -> None:
        """The loop's last line of defence: whatever fails in a frame is one log line, never the server."""
        try:
            step()
        except Exception as exc:  # noqa: BLE001 - the live view keeps serving
            text = f"{getattr(step, '__name__', 'frame')} failed: {type(exc).__name__}: {exc}"
            if text != self._last_loop_error:
                _log(text, key="loop")
                self._last_loop_error = text

    def loop(self, duration_s: float | None, stop: threading.Event) -> dict[str, float]:
        """Run until ``stop`` is set or ``duration_s`` of wall time passed; return pacing figures."""
        live = self.live
        start = time.perf_counter()
        cpu_start = time.process_time()
        sim_ticks = 0
        next_frame = start
        owed_s = 0.0  # simulated time owed to the wall clock at the current speed (at most MAX_OWED_S)
        # Simulated time run against wall time over the last SPEED_WINDOW_S of running: the speed achieved.
        recent: deque[tuple[float, int]] = deque()
        while not stop.is_set():
            now = time.perf_counter()
            if live.running:
                recent.append((now, sim_ticks))
                while recent and now - recent[0][0] > SPEED_WINDOW_S:
                    recent.popleft()
                span = now - recent[0][0]
                live.achieved_speed = (
                    (sim_ticks - recent[0][1]) * FRAME_S / span if span > 0.5 * SPEED_WINDOW_S else None
                )
            else:
                recent.clear()
                live.achieved_speed = None
            if duration_s is not None and now - start >= duration_s:
                break
            self._safely(live.apply_actions)
            wire = live.wire is not None
            if live.running and not wire:
                owed_s = owe(owed_s, live.speed)
                self.owed_s, self.max_owed_s = owed_s, max(self.max_owed_s, owed_s)
                while owed_s >= FRAME_S - 1e-12 and live.running:
                    self._safely(live.tick)
                    sim_ticks += 1
                    owed_s -= FRAME_S
            self._safely(self.report)
            self._safely(self.publish)
            next_frame += FRAME_S
            if wire:
                # The wire client's tick comes last and fills the rest of the frame: SAMPLE k now, COMMAND k
                # awaited on the socket until the frame's end (twin.viewer.wire). One tick per frame, at ×1.
                if next_frame - time.perf_counter() < WIRE_MIN_WAIT_S:
                    next_frame = time.perf_counter() + FRAME_S  # fell behind: give the client a whole frame
                deadline = next_frame - WIRE_MARGIN_S
                if live.running:
                    self._safely(functools.partial(live.tick, deadline))
                    sim_ticks += 1
                else:
                    self._safely(functools.partial(live.service_wire, deadline))
            delay = next_frame - time.perf_counter()
            if delay > 0:
                stop.wait(delay)
            elif -delay > MAX_CATCH_UP_S:
                next_frame = time.perf_counter()
        wall = time.perf_counter() - start
        return {
            "wall_s": wall,
            "ticks": sim_ticks,
            "tick_rate_hz": sim_ticks / wall if wall else 0.0,
            "cpu_s_per_tick": (time.process_time() - cpu_start) / max(sim_ticks, 1),
            "sim_time_s": live.rig.time_s,
        }


def serve(
    catalogue: Catalogue,
    *,
    host: str = "127.0.0.1",
    port: int = 8080,
    controller: str | None = None,
    speed: float = 1.0,
    seed: int = 0,
    duration_s: float | None = None,
    params: Parameters | None = None,
    plant: str = "twin",
    ideal_sensors: bool = False,
    announce: bool = True,
    allowed_origins: tuple[str, ...] = (),
    params_source: str = "",
    wait_for_client: bool = True,
    stop: threading.Event | None = None,
    on_ready: Callable[[Viewer], None] | None = None,
    wire: tuple[str, int] | None = None,
    rig_name: str = "ballbeam-twin",
    monitor: MonitorFactory | None = None,
    initial: tuple[float, float] | None = None,
    wire_timeout_s: float = DEFAULT_TIMEOUT_S,
) -> dict[str, float]:
    """Start the live view and block until interrupted, ``stop`` is set or ``duration_s`` of wall time passed.

    Browsers connect from the page's own origin only; ``allowed_origins`` adds others (e.g.
    ``("https://twin.lab.example",)`` behind a reverse proxy). A host other than loopback is served with a
    warning on stderr: anyone who can reach it can drive the twin. ``on_ready(viewer)`` is called once the
    server listens (tests). The twin waits, paused, until the first browser connects (``wait_for_client``),
    so that a visitor sees the run from its start; ``params_source`` is shown in the panel.

    ``wire=(host, port)`` serves the twin on protocol 1 over UDP there (port 0: a free one) to a controller in
    any language (``ballbeam view --serve``): the menu's first entry, "wire client (udp://host:port)", the
    one started unless ``controller`` names another (twin.viewer.wire); ``rig_name`` is CONFIG's rig;
    ``wire_timeout_s`` how long the client's answer is awaited (its acknowledgement of the held sample, its
    answers to its repeats while the view waits to run, a command while it runs) before its session ends
    with STOP 3 and a new one waits, so that a vanished client does not keep the one session.
    ``monitor`` builds the shadow (twin.viewer.monitor) when the panel's "Shadow the rig" is ticked.
    ``initial``: the first run's (x0, θ0) (a replayed run's; default the panel's)."""
    if not (isinstance(speed, (int, float)) and math.isfinite(speed) and SPEED_MIN <= speed <= SPEED_MAX):
        raise ViewerError(
            f"--speed = {speed!r} must be within {SPEED_MIN:g} … {SPEED_MAX:g} (the speed slider)"
        )
    params = params or Parameters()
    wire_server: Server | None = None
    if wire is not None:
        settings = SessionSettings(
            params=params,
            plant=plant,
            ideal_sensors=ideal_sensors,
            mode=p.MODE_REALTIME,
            rig_name=rig_name,
            timeout_s=wire_timeout_s,
        )
        try:
            wire_server = Server(settings, wire[0], wire[1], log=_log)
        except ServeError as exc:
            raise ViewerError(f"--serve: {exc}") from None
        catalogue = WireCatalogue(catalogue, wire_server)
    try:
        return _serve(
            catalogue,
            wire_server,
            host=host,
            port=port,
            controller=controller,
            speed=speed,
            seed=seed,
            duration_s=duration_s,
            params=params,
            plant=plant,
            ideal_sensors=ideal_sensors,
            announce=announce,
            allowed_origins=allowed_origins,
            params_source=params_source,
            wait_for_client=wait_for_client,
            stop=stop,
            on_ready=on_ready,
            monitor=monitor,
            initial=initial,
        )
    finally:
        if wire_server is not None:
            wire_server.close()


def _serve(
    catalogue: Catalogue,
    wire_server: Server | None,
    *,
    host: str,
    port: int,
    controller: str | None,
    speed: float,
    seed: int,
    duration_s: float | None,
    params: Parameters,
    plant: str,
    ideal_sensors: bool,
    announce: bool,
    allowed_origins: tuple[str, ...],
    params_source: str,
    wait_for_client: bool,
    stop: threading.Event | None,
    on_ready: Callable[[Viewer], None] | None,
    monitor: MonitorFactory | None,
    initial: tuple[float, float] | None = None,
) -> dict[str, float]:
    if controller is None:
        controller = catalogue.NAMES[0] if wire_server is not None else DEFAULT_CONTROLLER
    if controller not in catalogue.NAMES:
        raise ViewerError(f"unknown controller {controller!r}; known: {', '.join(catalogue.NAMES)}")
    warm(params, plant=plant, ideal_sensors=ideal_sensors)  # before the view's clock: no tick stalls
    live = LiveTwin(
        params,
        catalogue,
        controller,
        seed,
        speed,
        plant=plant,
        ideal_sensors=ideal_sensors,
        wait_for_client=wait_for_client,
        monitor=monitor,
        initial=initial,
    )
    if isinstance(catalogue, WireCatalogue):  # a wire client that went: a new run (Reset) for the next one
        catalogue.on_vacant = functools.partial(live.enqueue, "reset")
    try:
        viewer = Viewer(live, host, port, allowed_origins, params_source)
    except BaseException:
        live.close()
        raise
    if not is_loopback(host):
        where = "every interface" if _is_wildcard(host) else host
        _log(
            f"warning: serving on {where} (port {port}): anyone who can reach this machine there can watch "
            "and drive the twin — there is no authentication. Serve on 127.0.0.1 (the default) unless that "
            "is what you want."
        )
    if announce:
        print(
            f"ballbeam view: http://{host}:{viewer.server.get_port()} (controller {controller}, speed ×{speed:g})",
            flush=True,
        )
        if wire_server is not None:
            print(f"ballbeam view: serving the twin on {wire_server.url} (protocol 1, real time)", flush=True)
    stop = stop if stop is not None else threading.Event()
    try:
        if on_ready is not None:
            on_ready(viewer)
        return viewer.loop(duration_s, stop)
    except KeyboardInterrupt:
        return {}
    finally:
        live.close()
        viewer.server.stop()
