"""The live view's panels: controls (their callbacks, on viser's threads, only enqueue actions for the session;
the loop applies each through its handler, twin.viewer.actions, which checks the control's value and calls the
session's typed commands), status, notifications and the live plots. A value refused puts its control back."""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import viser
import viser.uplot

from twin.parameters import Parameters
from twin.physics import beam_travel_rad
from twin.viewer.channels import PLOTS as PLOTS  # the thesis's plots, where the view's tests import them
from twin.viewer.channels import THESIS_PLOT_ASPECT as PLOT_ASPECT
from twin.viewer.channels import plot_aspect
from twin.viewer.common import DRIFT, FLICK, SETPOINT, SPEED, THETA0, X0, _markdown_text, _show
from twin.viewer.scene import CAMERAS, on_camera, rig_cameras
from twin.viewer.security import download_bytes_queued, send_uplot_data
from twin.viewer.session import RECORD_LIMIT_S, LiveTwin, Refusal

NOTIFY_EVERY_S = 0.5  # at most two refusal notifications a second (a flood shows as a count)
# The live plots: the thesis rig's ``PLOTS``, a rig from other parts its own (twin.viewer.channels.part_plots).

# The shadow's tab: the last predicted spans (measured and predicted), and the drift test's sums against h.
SHADOW_PLOTS = (
    ("x (m)", (("measured", "#ff7f0e"), ("predicted", "#17becf"))),
    ("θ (rad)", (("measured", "#ff7f0e"), ("predicted", "#17becf"))),
    ("CUSUM (sd)", (("ball", "#1f77b4"), ("angle", "#d62728"), ("alarm at h", "#000000"))),
)


def _series(name: str, colour: str) -> viser.uplot.Series:
    """A trace of a live chart. An estimate is dashed: where it equals the measurement (appendix-clp's x is
    its reading), the measurement drawn beneath it still shows."""
    if name == "estimated":
        return viser.uplot.Series(label=name, stroke=colour, width=1.5, dash=(6.0, 4.0))
    return viser.uplot.Series(label=name, stroke=colour, width=1.5)


PLOT_AXIS_PX = 58  # room for a y value such as "−0.005" with its minus sign (uPlot's default clips it)
PLOT_PANEL_PX = 460


def uplot_data(t: np.ndarray, series: Sequence[np.ndarray]) -> tuple[np.ndarray | list[float | None], ...]:
    """A chart's columns as uPlot draws them: a series without a gap as a typed array (viser sends numpy
    arrays as binary); one with NaN (a controller without an estimate, a diverged observer) as a list with
    None there, which uPlot draws as a gap: a NaN in a typed array would empty the whole chart's scale."""
    columns: list[np.ndarray | list[float | None]] = [t]
    for values in series:
        finite = np.isfinite(values)
        if finite.all():
            columns.append(values)
        else:
            columns.append(
                [float(v) if ok else None for v, ok in zip(values.tolist(), finite.tolist(), strict=True)]
            )
    return tuple(columns)


def parameter_changes(params: Parameters) -> list[str]:
    """``group.name = value`` for every parameter that differs from the defaults."""
    ours, defaults = params.to_dict(), Parameters().to_dict()
    changes = []
    for group, values in ours.items():
        for name, value in values.items():
            if defaults.get(group, {}).get(name) != value:
                changes.append(f"{group}.{name} = {_show(value, 80)}")
    return changes


class Panels:
    """The controls, status and plots of one viser server around a ``LiveTwin``."""

    def __init__(self, server: viser.ViserServer, live: LiveTwin, params_source: str = "") -> None:
        self.server, self.live, self.params_source = server, live, params_source
        self.downloads_refused = 0  # clicks answered while the previous download was still on its way
        self._pending: list[Refusal] = []  # refusals not yet notified
        self._last_notify = -math.inf
        self._last_download_notice = -math.inf
        self._notified_error: str | None = None
        self._lost_run: int | None = None  # the run whose lost ball is notified
        self._lost_notices: list[Any] = []
        self._build()

    def _build(self) -> None:
        gui = self.server.gui
        self.banner = gui.add_html("", visible=False)
        self.status = gui.add_markdown(self.live.status_markdown())
        # viser lays elements out in creation order: the folders are built top to bottom, each wiring its
        # controls (registering a callback sends nothing to the browsers).
        self.controls: dict[str, Any] = {
            **self._add_run_folder(),
            **self._add_initial_state_folder(),
            **self._add_disturb_folder(),
            **self._add_shadow_folder(),
            **self._add_record_folder(),
            **self._add_camera_folder(),
        }
        with gui.add_folder("Parameters", expand_by_default=False):
            gui.add_markdown(self._parameters_markdown())
        self._add_plot_panel()

    def _add_run_folder(self) -> dict[str, Any]:
        gui, live = self.server.gui, self.live
        with gui.add_folder("Run"):
            controller = gui.add_dropdown(
                "Controller", options=live.catalogue.NAMES, initial_value=live.controller_name
            )
            run = gui.add_button("Pause")
            step = gui.add_button("Step 20 ms")
            reset = gui.add_button("Reset", hint="Start a new run from x0, θ0 (and re-place a lost ball)")
            speed = gui.add_slider(
                "Speed", min=SPEED.low, max=SPEED.high, step=SPEED.step, initial_value=live.speed
            )
            noise = gui.add_checkbox("Sensor noise", initial_value=live.noise)
        self.run_button = run
        controller.on_update(lambda _: live.enqueue("controller", controller.value))
        run.on_click(lambda _: live.enqueue("run", not live.running))
        step.on_click(lambda _: live.enqueue("step"))
        reset.on_click(lambda _: live.enqueue("reset"))
        speed.on_update(lambda _: live.enqueue("speed", speed.value))
        noise.on_update(lambda _: live.enqueue("noise", noise.value))
        return {
            "controller": controller,
            "run": run,
            "step": step,
            "reset": reset,
            "speed": speed,
            "noise": noise,
        }

    def _add_initial_state_folder(self) -> dict[str, Any]:
        gui, live, p = self.server.gui, self.live, self.live.params
        # The sliders stay inside the track and the beam's stops.
        x_max = min(X0.high, p.track.half_length_m)
        low, high = beam_travel_rad(p)  # the stops, or a lever's reach
        th_max = min(THETA0.high, -low, high)
        with gui.add_folder("Initial state (applies on Reset)"):
            x0 = gui.add_slider(
                "x0 (m)",
                min=-x_max,
                max=x_max,
                step=X0.step,
                initial_value=live.x0_m,
                hint="Where the ball is held before release; press Reset to apply",
            )
            th0 = gui.add_slider(
                "θ0 (rad)",
                min=-th_max,
                max=th_max,
                step=THETA0.step,
                initial_value=live.theta0_rad,
                hint="Where the beam is held before release; press Reset to apply",
            )
        x0.on_update(lambda _: live.enqueue("x0", x0.value))
        th0.on_update(lambda _: live.enqueue("theta0", th0.value))
        return {"x0": x0, "theta0": th0}

    def _add_disturb_folder(self) -> dict[str, Any]:
        gui, live = self.server.gui, self.live
        ref_max = min(SETPOINT.high, live.params.track.half_length_m)  # the setpoint stays on the track
        with gui.add_folder("Disturb"):
            kick = gui.add_slider(
                "Flick (m/s)", min=FLICK.low, max=FLICK.high, step=FLICK.step, initial_value=live.flick_m_s
            )
            flick_left = gui.add_button("Flick ◀")
            flick_right = gui.add_button("Flick ▶")
            reference = gui.add_slider(
                "Setpoint x (m)",
                min=-ref_max,
                max=ref_max,
                step=SETPOINT.step,
                initial_value=live.reference_x_m,
                disabled=not live.supports_reference,
                hint=live.setpoint_reason,
            )
            self.setpoint_note = gui.add_markdown(
                "" if live.supports_reference else f"*{_markdown_text(live.setpoint_reason)}*"
            )
        self.reference_slider = reference
        flick_left.on_click(lambda _: live.enqueue("flick_left", kick.value))
        flick_right.on_click(lambda _: live.enqueue("flick_right", kick.value))
        reference.on_update(lambda _: live.enqueue("reference", reference.value))
        return {"flick": kick, "flick_left": flick_left, "flick_right": flick_right, "setpoint": reference}

    def _add_shadow_folder(self) -> dict[str, Any]:
        gui, live = self.server.gui, self.live
        with gui.add_folder("Shadow (drift alarm)"):
            shadow = gui.add_checkbox(
                "Shadow the rig",
                initial_value=False,
                disabled=live.monitor_factory is None,
                hint="The twin at these parameters predicts each second of the run and raises a drift alarm "
                "when the rig stops behaving like it (ballbeam shadow); it first measures its band, tens of seconds "
                "(minutes on a loaded machine), its progress in the status",
            )
            drift = gui.add_slider(
                "Rig drift: motor R (+%)",
                min=DRIFT.low,
                max=DRIFT.high,
                step=DRIFT.step,
                initial_value=live.drift_pct,
                hint="A warm motor: the rig's resistance this much above the parameters' from the next Reset; "
                "the shadow keeps the parameters it started with",
            )
        shadow.on_update(lambda _: live.enqueue("shadow", shadow.value))
        drift.on_update(lambda _: live.enqueue("drift", drift.value))
        return {"shadow": shadow, "drift": drift}

    def _add_record_folder(self) -> dict[str, Any]:
        gui = self.server.gui
        with gui.add_folder("Record"):
            gui.add_markdown(
                f"Each run is recorded from its start (Reset) for up to {RECORD_LIMIT_S / 60:g} min of "
                "simulated time: the thesis software's `data_file.mat` variables and the twin's true state."
            )
            download_mat = gui.add_button("Download .mat")
            download_csv = gui.add_button("Download CSV")
        download_mat.on_click(lambda event: self._download(event.client, "mat"))
        download_csv.on_click(lambda event: self._download(event.client, "csv"))
        return {"download_mat": download_mat, "download_csv": download_csv}

    def _add_camera_folder(self) -> dict[str, Any]:
        gui = self.server.gui
        with gui.add_folder("Camera"):
            cameras = {name: gui.add_button(name) for name in CAMERAS}
        views = rig_cameras(self.live.params)  # the thesis's, or moved to the rig's track
        for name, button in cameras.items():
            button.on_click(functools.partial(on_camera, name, views))
        return {f"camera_{name}": button for name, button in cameras.items()}

    def _add_plot_panel(self) -> None:
        """The plots in their own panel, docked left of the view: all of them visible at 1400 × 900."""
        gui = self.server.gui
        # Compact: the quantity as the y-axis label (no title), a static legend, a low time axis.
        scales: dict[str, viser.uplot.Scale] = {"x": {"time": False, "auto": True}}
        legend: viser.uplot.Legend = {"live": False}
        self.plots = []
        self.plot_panel = gui.add_panel()
        groups = self.live.channels.plots  # the rig's channels in its board's units (PLOTS for the thesis's)
        aspect = plot_aspect(len(groups), PLOT_PANEL_PX)
        with self.plot_panel.add_tab("Plots (last 10 s, time in s)"):
            for label, traces in groups:
                colours = [(name, colour) for name, _, colour in traces]
                handle = self._add_plot(label, colours, scales, legend, aspect)
                self.plots.append((handle, [key for _, key, _ in traces]))
        self.shadow_plots = []
        with self.plot_panel.add_tab("Shadow (predicted vs measured)"):
            for shadow_label, shadow_traces in SHADOW_PLOTS:
                self.shadow_plots.append(self._add_plot(shadow_label, shadow_traces, scales, legend))
        self._shadow_alarms = 0
        self.plot_panel.dock_left()
        gui.main_panel.dock_right()  # the view between the two: nothing covers the rig
        self.plot_panel.set_width(PLOT_PANEL_PX)

    def _add_plot(
        self,
        label: str,
        traces: Sequence[tuple[str, str]],
        scales: dict[str, viser.uplot.Scale],
        legend: viser.uplot.Legend,
        aspect: float = PLOT_ASPECT,
    ) -> viser.GuiUplotHandle:
        """One live chart: time against ``traces`` (legend label, colour), ``label`` on its y axis."""
        series = [viser.uplot.Series(label="t (s)")] + [_series(name, colour) for name, colour in traces]
        axes: tuple[viser.uplot.Axis, ...] = (
            {"size": 26},
            {"size": PLOT_AXIS_PX, "label": label, "labelSize": 18},
        )
        data = tuple(np.zeros(2) for _ in series)
        return self.server.gui.add_uplot(
            data, tuple(series), aspect=aspect, scales=scales, axes=axes, legend=legend
        )

    def _download(self, client: Any, kind: str) -> None:
        """The loop builds the file (it owns the record) and hands it to the clicking browser's receiver."""
        if client is not None:
            self.live.enqueue("download", (kind, functools.partial(self._send_download, client)))

    def _send_download(self, client: Any, name: str, data: bytes) -> None:
        """On the loop's thread: send the file, unless the last one is still waiting for that browser to
        take it (then a notification, at most two a second: a browser that reads nothing would hold one per
        click): clicks never pile copies of the record up in memory."""
        if download_bytes_queued(client):
            self.downloads_refused += 1
            now = time.monotonic()
            if now - self._last_download_notice < NOTIFY_EVERY_S:
                return
            self._last_download_notice = now
            client.add_notification(
                "Download",
                "the previous download is still being sent",
                auto_close_seconds=4.0,
                color="yellow",
            )
            return
        client.send_file_download(name, data, save_immediately=True)

    def _parameters_markdown(self) -> str:
        """Where the parameters come from, and every value that differs from the thesis's defaults."""
        source = self.params_source or "the thesis's values (no --params, no --set)"
        changed = parameter_changes(self.live.params)
        lines = [f"parameters: **{_markdown_text(source)}**"]
        if changed:
            lines.append("changed from the defaults:")
            lines += [f"- `{_markdown_text(item)}`" for item in changed[:40]]
            if len(changed) > 40:
                lines.append(f"- … and {len(changed) - 40} more")
        else:
            lines.append("every value is the default (see `ballbeam params`)")
        return "  \n".join(lines[:2]) + ("\n\n" + "\n".join(lines[2:]) if len(lines) > 2 else "")

    def _resync(self, action: str) -> None:
        """Put a control whose value was refused back to the state the twin runs with."""
        live, c = self.live, self.controls
        values: dict[str, tuple[tuple[str, Any], ...]] = {
            "controller": (("controller", live.controller_name),),
            "speed": (("speed", live.speed),),
            "noise": (("noise", live.noise),),
            "x0": (("x0", live.x0_m),),
            "theta0": (("theta0", live.theta0_rad),),
            "initial": (("x0", live.x0_m), ("theta0", live.theta0_rad)),
            "reference": (("setpoint", live.reference_x_m),),
            "flick_left": (("flick", live.flick_m_s),),
            "shadow": (("shadow", live.shadow is not None),),
            "drift": (("drift", live.drift_pct),),
            "flick_right": (("flick", live.flick_m_s),),
        }
        for name, value in values.get(action, ()):
            c[name].value = value

    def report(self) -> None:
        """Refusals and failures to the browsers: controls put back, a notification (at most two a second)."""
        live = self.live
        while live.refusals:
            refusal = live.refusals.popleft()
            self._pending.append(refusal)
            self._resync(refusal.action)
        now = time.monotonic()
        if self._pending and now - self._last_notify >= NOTIFY_EVERY_S:
            last, more = self._pending[-1], len(self._pending) - 1
            body = last.reason + (f" (and {more} more refused)" if more else "")
            self._notify("Refused", body, "red")
            self._pending.clear()
            self._last_notify = now
        if live.error is not None and live.error != self._notified_error:
            self._notify("Run failed", live.error, "orange")
        self._notified_error = live.error
        # A lost ball stays on screen (the banner may be scrolled away) until the run it belongs to ends.
        lost = live.runs if live.rig.ball_lost else None
        if lost != self._lost_run:
            for handle in self._lost_notices:
                handle.remove()
            self._lost_notices = []
            if lost is not None:
                self._lost_notices = self._notify("Ball lost", live.lost_text(), "red", seconds=None)
            self._lost_run = lost

    def _update_shadow(self, snap: Any) -> None:
        """The shadow's tab, and a notification for each new drift alarm."""
        for handle, channel in zip(self.shadow_plots[:2], ("ball", "angle"), strict=True):
            t, measured, predicted = shadow_series(snap.windows, channel)
            if t.size >= 2:
                send_uplot_data(handle, uplot_data(t, [measured, predicted]))
        if snap.sums_t.size >= 2:
            h = np.full(snap.sums_t.size, snap.threshold)
            send_uplot_data(
                self.shadow_plots[2], uplot_data(snap.sums_t, [snap.sums["ball"], snap.sums["angle"], h])
            )
        for channel, at, run in snap.alarms[self._shadow_alarms :]:
            self._notify(
                "Drift alarm",
                f"at t = {at:.2f} s of run {run}: the {channel} no longer follows the twin",
                "red",
            )
        self._shadow_alarms = len(snap.alarms)

    def _notify(self, title: str, body: str, color: Any, seconds: float | None = 8.0) -> list[Any]:
        return [
            client.add_notification(title, body, auto_close_seconds=seconds, color=color)
            for client in self.server.get_clients().values()
        ]

    def update(self) -> None:
        """The plots, the status and the controls that follow the run (inside the caller's atomic batch)."""
        live = self.live
        h = live.history
        t = h.array("t")
        if t.size >= 2:
            for handle, keys in self.plots:
                send_uplot_data(handle, uplot_data(t, [h.array(key) for key in keys]))
        self.status.content = live.status_markdown()
        if live.shadow is not None:
            self._update_shadow(live.shadow.snapshot())
        # Only send what changed: re-sending a button's props re-renders it under the user's click.
        label = "Pause" if live.running else "Start"
        if self.run_button.label != label:
            self.run_button.label = label
        if self.reference_slider.disabled == live.supports_reference:
            self.reference_slider.disabled = not live.supports_reference
            self.reference_slider.hint = live.setpoint_reason
            note = "" if live.supports_reference else f"*{_markdown_text(live.setpoint_reason)}*"
            self.setpoint_note.content = note
        banner = live.lost_banner_html()
        if self.banner.content != banner:
            self.banner.content = banner
            self.banner.visible = bool(banner)


def shadow_series(windows: Sequence[Any], channel: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The predicted spans of ``windows`` end to end, NaN between them (a gap: each is its own prediction):
    (time, measured, predicted)."""
    t, measured, predicted = [], [], []
    for w in windows:
        t += [w.t_s, [w.t_s[-1] + 1e-6]]
        measured += [w.measured[channel], [math.nan]]
        predicted += [w.predicted[channel], [math.nan]]
    if not t:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return np.concatenate(t), np.concatenate(measured), np.concatenate(predicted)
