"""Live browser view of the twin (viser): the rig in 3D at 50 Hz, controls, and live plots.

The simulation loop owns the twin and the controller. GUI callbacks run on viser's thread pool and only
enqueue actions, which the loop applies between ticks; each frame's scene updates are sent together.
"""

from __future__ import annotations

import math
import queue
import socket
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
import trimesh
import viser
import viser.uplot

from twin import converters
from twin.engine import Catalogue, ClosedLoop, ControllerError
from twin.interface import DaqSample
from twin.parameters import Parameters
from twin.plant import Plant
from twin.rig import PlantKind, make_rig

__all__ = ["LiveTwin", "ViewerError", "serve"]

FRAME_S = 0.02  # scene updates at 50 Hz (the rig's tick)
PLOT_EVERY_FRAMES = 10  # plots and status at 5 Hz: enough for the eye, a tenth of the traffic
HISTORY_S = 10.0  # live plots show the last 10 s
MAX_CATCH_UP_S = 0.25  # after a stall longer than this the pacing restarts instead of racing to catch up
DEFAULT_CONTROLLER = "appendix-clp"

# Live plots: title, then (legend label, history key, colour) per trace.
PLOTS = (
    (
        "Ball position (m)",
        (
            ("x true", "x_true", "#1f77b4"),
            ("x measured", "x_meas", "#ff7f0e"),
            ("x estimated", "x_est", "#2ca02c"),
        ),
    ),
    ("Beam angle (rad)", (("θ true", "th_true", "#1f77b4"), ("θ measured", "th_meas", "#ff7f0e"))),
    ("Motor voltage (V)", (("motor V", "volts", "#d62728"),)),
    (
        "Observer error (estimate − true)",
        (("ẋ error (m/s)", "err_xdot", "#9467bd"), ("θ̇ error (rad/s)", "err_thdot", "#8c564b")),
    ),
)


class ViewerError(RuntimeError):
    """The viewer cannot start (port taken, bad host, …)."""


@dataclass
class History:
    """Bounded histories for the live plots (the last ``HISTORY_S`` seconds at 50 Hz)."""

    size: int = int(HISTORY_S / FRAME_S)
    columns: dict[str, deque] = field(default_factory=dict)

    def append(self, **values: float) -> None:
        for key, value in values.items():
            self.columns.setdefault(key, deque(maxlen=self.size)).append(value)

    def array(self, key: str) -> np.ndarray:
        # float32: plenty for a plot, half the bytes on the wire.
        return np.asarray(self.columns.get(key, ()), dtype=np.float32)

    def clear(self) -> None:
        self.columns.clear()


class LiveTwin:
    """The simulation side of the viewer: a closed loop (twin.engine), and the actions the GUI asks for.

    Everything here runs on the loop's thread; ``enqueue`` is the only method other threads call. The
    controllers come from the catalogue the application hands in (the core never imports them)."""

    def __init__(
        self,
        params: Parameters,
        catalogue: Catalogue,
        controller: str,
        seed: int,
        speed: float,
        *,
        plant: PlantKind = "twin",
        ideal_sensors: bool = False,
    ) -> None:
        self.params = params
        self.catalogue = catalogue
        self.seed = seed
        self.speed = speed
        self.plant: PlantKind = plant
        self.ideal_sensors = ideal_sensors
        self.x0_m, self.theta0_rad = 0.15, 0.1
        self.noise = params.ball_sensor.noise_enabled
        self.reference_x_m = 0.0
        self.running = True
        self.error: str | None = None
        self.history = History()
        self.actions: queue.Queue[tuple[str, Any]] = queue.Queue()
        self.runs = 0  # runs started (each reset or controller change starts one)
        self._select(controller)

    # --- called from any thread ---------------------------------------------------------------------
    def enqueue(self, action: str, value: Any = None) -> None:
        self.actions.put((action, value))

    # --- loop thread --------------------------------------------------------------------------------
    def _select(self, name: str) -> None:
        self.controller_name = name
        self._restart()

    def _restart(self) -> None:
        """A fresh run from the set initial state: new controller, rig held at (x0, θ0), then released."""
        self.runs += 1
        self.error = None
        controller = self.catalogue.make(self.controller_name, self.params)
        params = self.params.with_overrides({"ball_sensor.noise_enabled": self.noise})
        self.rig = make_rig(params, plant=self.plant, ideal_sensors=self.ideal_sensors, seed=self.seed)
        self.rig.reset(self.x0_m, self.theta0_rad)
        self.loop = ClosedLoop(self.rig, controller, record=False)
        self._apply_reference()
        self.history.clear()
        self._guarded(self.loop.start)
        self._record()

    @property
    def controller(self) -> Any:
        return self.loop.controller

    @property
    def last_sample(self) -> DaqSample | None:
        return self.loop.last_sample

    @property
    def supports_reference(self) -> bool:
        return hasattr(getattr(self.controller, "law", None), "ref_x_m")

    def _apply_reference(self) -> None:
        if self.supports_reference:
            self.controller.law.ref_x_m = self.reference_x_m

    def _guarded(self, step: Any) -> None:
        """Run one step of the loop; a failing controller pauses the run with its message."""
        try:
            step()
        except ControllerError as exc:
            self.error = str(exc)
            self.running = False
            print(f"ballbeam view: {exc}", flush=True)

    def apply_actions(self) -> None:
        while True:
            try:
                action, value = self.actions.get_nowait()
            except queue.Empty:
                return
            print(
                f"ballbeam view: t = {self.rig.time_s:.2f} s: {action} {'' if value is None else value}",
                flush=True,
            )
            if action == "controller":
                self._select(str(value))
            elif action == "reset":
                self._restart()
            elif action == "run":
                self.running = bool(value) and self.error is None
            elif action == "step":
                self.running = False
                self.tick()
            elif action == "initial":
                self.x0_m, self.theta0_rad = float(value[0]), float(value[1])
            elif action == "flick":
                self.rig.kick_ball(float(value))
            elif action == "noise":
                self.noise = bool(value)
                self.rig.set_noise(self.noise)
            elif action == "speed":
                self.speed = float(value)
            elif action == "reference":
                self.reference_x_m = float(value)
                self._apply_reference()

    def tick(self) -> None:
        """One 20 ms frame of simulated time: as many control periods as fit in it."""
        if self.error is not None:
            return
        n = max(1, int(round(FRAME_S / self.rig.period_s)))
        for _ in range(n):
            self._guarded(self.loop.tick)
        self._record()

    def _record(self) -> None:
        x, theta, xdot, thetadot = self.rig.true_state()
        est = self.controller.telemetry.estimate
        s = self.last_sample
        sw = self.rig.params.software
        x_meas = converters.ball_position_m(s.ball_v, sw) if s is not None else float("nan")
        th_meas = converters.beam_angle_rad(s.angle_v, sw) if s is not None else float("nan")
        self.history.append(
            t=self.rig.time_s,
            x_true=x,
            x_meas=x_meas,
            x_est=est[0],
            th_true=theta,
            th_meas=th_meas,
            volts=self.rig.motor_volts_v,
            err_xdot=est[2] - xdot,
            err_thdot=est[3] - thetadot,
        )

    def status_markdown(self) -> str:
        state = "running" if self.running else "paused"
        ball = (
            f"**ball lost** at {self.rig.ball_lost_time_s:.2f} s"
            if self.rig.ball_lost
            else "ball on the beam"
        )
        error = f"  \n**controller failed**: {self.error}" if self.error else ""
        return (
            f"run {self.runs} · **t = {self.rig.time_s:.2f} s** · {state} · controller: "
            f"**{self.controller_name}** · {ball}  \n"
            f"noise {'on' if self.noise else 'off'} · speed ×{self.speed:g} · "
            f"motor {self.rig.motor_volts_v:+.2f} V{error}"
        )


# --- scene ------------------------------------------------------------------------------------------------
def _rgb(model: mujoco.MjModel, geom: int) -> tuple[int, int, int]:
    mat = model.geom_matid[geom]
    rgba = model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[geom]
    r, g, b = (int(round(255 * c)) for c in rgba[:3])
    return r, g, b


def build_scene(server: viser.ViserServer, model: mujoco.MjModel) -> dict[int, Any]:
    """Every geom of the MuJoCo model as a viser node under a frame per body; returns body id → frame."""
    frames: dict[int, Any] = {}
    for body in range(model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body) or "world"
        frames[body] = server.scene.add_frame(f"/{name}", show_axes=False)
    for g in range(model.ngeom):
        body = model.geom_bodyid[g]
        body_name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body) or "world"
        name = f"/{body_name}/{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)}"
        px, py, pz = (float(v) for v in model.geom_pos[g])
        qw, qx, qy, qz = (float(v) for v in model.geom_quat[g])
        position, wxyz = (px, py, pz), (qw, qx, qy, qz)
        size, color, kind = model.geom_size[g], _rgb(model, g), model.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_PLANE:
            server.scene.add_box(
                name,
                color=color,
                dimensions=(2 * size[0], 2 * size[1], 0.002),
                position=(px, py, -0.001),
                wxyz=wxyz,
            )
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            sx, sy, sz = (float(2 * v) for v in size)
            server.scene.add_box(name, color=color, dimensions=(sx, sy, sz), position=position, wxyz=wxyz)
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            server.scene.add_icosphere(
                name, radius=float(size[0]), color=color, subdivisions=3, position=position, wxyz=wxyz
            )
        elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            server.scene.add_cylinder(
                name,
                radius=float(size[0]),
                height=float(2 * size[1]),
                color=color,
                position=position,
                wxyz=wxyz,
            )
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            mesh = trimesh.creation.capsule(height=float(2 * size[1]), radius=float(size[0]), count=[12, 12])
            server.scene.add_mesh_simple(
                name,
                vertices=np.asarray(mesh.vertices, dtype=np.float32),
                faces=np.asarray(mesh.faces, dtype=np.uint32),
                color=color,
                position=position,
                wxyz=wxyz,
            )
    return frames


def _free_port_or_raise(host: str, port: int) -> None:
    """viser moves silently to the next free port; a taken port is an error here instead."""
    if not 1 <= port <= 65535:
        raise ViewerError(f"--port {port} is not a TCP port (1–65535)")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise ViewerError(f"--host {host!r} cannot be resolved: {exc}") from None
    family, _, _, _, address = infos[0]
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(address)
        except OSError as exc:
            raise ViewerError(
                f"port {port} on {host} is taken ({exc.strerror}); choose another with --port"
            ) from None


# --- server -----------------------------------------------------------------------------------------------
class Viewer:
    """viser server + GUI around a ``LiveTwin``, paced by the wall clock."""

    def __init__(self, live: LiveTwin, host: str, port: int) -> None:
        _free_port_or_raise(host, port)
        self.live = live
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        if self.server.get_port() != port:
            self.server.stop()
            raise ViewerError(f"port {port} on {host} is taken; choose another with --port")
        self.host, self.port = host, port
        self.server.gui.configure_theme(show_share_button=False, control_width="large")
        self.server.initial_camera.position = (0.16, -0.58, 0.36)
        self.server.initial_camera.look_at = (0.16, 0.0, 0.25)
        # The reference model has no geometry: a MuJoCo model of the same rig shows its state.
        self._display = Plant(live.params)
        self.frames = build_scene(self.server, self._display.model)
        self._build_gui()
        self._frame_count = 0

    def _build_gui(self) -> None:
        gui, live = self.server.gui, self.live
        self.status = gui.add_markdown(live.status_markdown())
        with gui.add_folder("Run"):
            controller = gui.add_dropdown(
                "Controller", options=live.catalogue.NAMES, initial_value=live.controller_name
            )
            run = gui.add_button("Pause")
            step = gui.add_button("Step 20 ms")
            reset = gui.add_button("Reset")
            speed = gui.add_slider("Speed", min=0.1, max=4.0, step=0.1, initial_value=live.speed)
            noise = gui.add_checkbox("Sensor noise", initial_value=live.noise)
        with gui.add_folder("Initial state"):
            x0 = gui.add_slider("x0 (m)", min=-0.3, max=0.3, step=0.01, initial_value=live.x0_m)
            th0 = gui.add_slider("θ0 (rad)", min=-0.7, max=0.7, step=0.01, initial_value=live.theta0_rad)
        with gui.add_folder("Disturb"):
            kick = gui.add_slider("Flick (m/s)", min=0.02, max=0.5, step=0.01, initial_value=0.1)
            flick_left = gui.add_button("Flick ◀")
            flick_right = gui.add_button("Flick ▶")
            reference = gui.add_slider(
                "Setpoint x (m)",
                min=-0.2,
                max=0.2,
                step=0.01,
                initial_value=0.0,
                disabled=not live.supports_reference,
            )
        self.reference_slider = reference
        self.run_button = run

        controller.on_update(lambda _: live.enqueue("controller", controller.value))
        run.on_click(lambda _: live.enqueue("run", not live.running))
        step.on_click(lambda _: live.enqueue("step"))
        reset.on_click(lambda _: live.enqueue("reset"))
        speed.on_update(lambda _: live.enqueue("speed", speed.value))
        noise.on_update(lambda _: live.enqueue("noise", noise.value))
        x0.on_update(lambda _: live.enqueue("initial", (x0.value, th0.value)))
        th0.on_update(lambda _: live.enqueue("initial", (x0.value, th0.value)))
        flick_left.on_click(lambda _: live.enqueue("flick", -kick.value))
        flick_right.on_click(lambda _: live.enqueue("flick", kick.value))
        reference.on_update(lambda _: live.enqueue("reference", reference.value))

        scales: dict[str, viser.uplot.Scale] = {"x": {"time": False, "auto": True}}
        self.plots = []
        with gui.add_folder("Plots (last 10 s)"):
            for title, traces in PLOTS:
                series = [viser.uplot.Series(label="t (s)")] + [
                    viser.uplot.Series(label=label, stroke=colour) for label, _, colour in traces
                ]
                data = tuple(np.zeros(2) for _ in series)
                handle = gui.add_uplot(data, tuple(series), title=title, aspect=2.0, scales=scales)
                self.plots.append((handle, [key for _, key, _ in traces]))

    def publish(self) -> None:
        """Send one frame: body poses (and every tenth frame the plots and status), as one batch."""
        live = self.live
        physics = live.rig.physics
        if isinstance(physics, Plant):
            model, data = physics.model, physics.data
        else:
            x, theta = (float(v) for v in live.rig.true_state()[:2])
            p = live.params
            model, data = self._display.model, self._display.data
            self._display.reset(
                float(np.clip(x, -p.track.half_length_m, p.track.half_length_m)),
                float(np.clip(theta, -p.beam.stop_angle_rad, p.beam.stop_angle_rad)),
            )
        mujoco.mj_kinematics(model, data)  # poses of the current state (mj_step leaves xpos one step behind)
        self._frame_count += 1
        with self.server.atomic():
            for body, frame in self.frames.items():
                if body == 0:
                    continue
                frame.position = tuple(data.xpos[body])
                frame.wxyz = tuple(data.xquat[body])
            if self._frame_count % PLOT_EVERY_FRAMES == 0 or not live.running:
                h = live.history
                t = h.array("t")
                if t.size >= 2:
                    for handle, keys in self.plots:
                        handle.data = (t, *(h.array(key) for key in keys))
                self.status.content = live.status_markdown()
                # Only send what changed: re-sending a button's props re-renders it under the user's click.
                label = "Pause" if live.running else "Start"
                if self.run_button.label != label:
                    self.run_button.label = label
                if self.reference_slider.disabled == live.supports_reference:
                    self.reference_slider.disabled = not live.supports_reference

    def loop(self, duration_s: float | None, stop: threading.Event) -> dict[str, float]:
        """Run until ``stop`` is set or ``duration_s`` of wall time passed; return pacing figures."""
        live = self.live
        start = time.perf_counter()
        cpu_start = time.process_time()
        sim_ticks = 0
        next_frame = start
        owed_s = 0.0  # simulated time owed to the wall clock at the current speed
        while not stop.is_set():
            now = time.perf_counter()
            if duration_s is not None and now - start >= duration_s:
                break
            live.apply_actions()
            if live.running:
                owed_s += FRAME_S * live.speed
                while owed_s >= FRAME_S - 1e-12:
                    live.tick()
                    sim_ticks += 1
                    owed_s -= FRAME_S
            self.publish()
            next_frame += FRAME_S
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
    controller: str = DEFAULT_CONTROLLER,
    speed: float = 1.0,
    seed: int = 0,
    duration_s: float | None = None,
    params: Parameters | None = None,
    plant: PlantKind = "twin",
    ideal_sensors: bool = False,
    announce: bool = True,
) -> dict[str, float]:
    """Start the live view and block until interrupted (or ``duration_s`` of wall time passed)."""
    if not (math.isfinite(speed) and 0 < speed <= 10):
        raise ViewerError(f"--speed = {speed!r} must be in (0, 10]")
    if controller not in catalogue.NAMES:
        raise ViewerError(f"unknown controller {controller!r}; known: {', '.join(catalogue.NAMES)}")
    live = LiveTwin(
        params or Parameters(), catalogue, controller, seed, speed, plant=plant, ideal_sensors=ideal_sensors
    )
    viewer = Viewer(live, host, port)
    if announce:
        print(
            f"ballbeam view: http://{host}:{viewer.server.get_port()} (controller {controller}, speed ×{speed:g})",
            flush=True,
        )
    stop = threading.Event()
    try:
        return viewer.loop(duration_s, stop)
    except KeyboardInterrupt:
        return {}
    finally:
        viewer.server.stop()
