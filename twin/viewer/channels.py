"""What the live view shows of a rig's board and parts: its plots (each channel in the board's unit, named from
the part that reads or writes it), the software's conversions of the readings to the ball's x and the beam's
angle (the parts' own: ``BallSensorPart.position_of``, ``AngleSensorPart.angle_of``), the status line's
actuator, and the ranging sensor's beam (drawn from its aperture toward the ball, as long as its reading).

The thesis's rig keeps the thesis's plots (``PLOTS``): the PCI-1712's volts in one chart, the motor's volts.
A rig from other parts gets one chart per channel: the ball sensor's reading (a VL53L0X's mm over I²C, an
HC-SR04's echo in µs, ``analogRead``'s counts), the angle sensor's (none when the rig measures no angle), the
board's output (a servo pulse's µs, a stepper's target) and the actuator's control (a servo's target angle)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import mujoco

from twin.model import BEAM_BODY
from twin.parameters import Parameters
from twin.parts import is_thesis_rig, rig_parts

__all__ = [
    "PLOTS",
    "PlotGroup",
    "RigChannels",
    "SensorBeam",
    "Trace",
    "part_plots",
    "plot_aspect",
    "rig_channels",
    "sensor_beam",
]

Trace = tuple[str, str, str]  # legend label, history key (twin.viewer.session.LiveTwin._record), colour
PlotGroup = tuple[str, tuple[Trace, ...]]  # the y axis's label (the quantity and its unit), the traces

# The thesis rig's live plots: title, then (legend label, history key, colour) per trace. Estimated = the
# controller's own estimate (its observer or differentiator); measured = the raw readings through the software's
# converters.
PLOTS: tuple[PlotGroup, ...] = (
    (
        "x (m)",
        (
            ("x true", "x_true", "#1f77b4"),
            ("measured", "x_meas", "#ff7f0e"),
            ("estimated", "x_est", "#2ca02c"),
            ("setpoint", "x_ref", "#000000"),
        ),
    ),
    (
        "θ (rad)",
        (
            ("θ true", "th_true", "#1f77b4"),
            ("measured", "th_meas", "#ff7f0e"),
            ("estimated", "th_est", "#2ca02c"),
        ),
    ),
    ("θ̇ (rad/s)", (("θ̇ true", "thdot_true", "#1f77b4"), ("estimated", "thdot_est", "#2ca02c"))),
    (
        "I/O card (V)",
        (
            ("ball ADC", "ball_v", "#ff7f0e"),
            ("angle ADC", "angle_v", "#8c564b"),
            ("DAC out", "dac_v", "#9467bd"),
        ),
    ),
    ("motor (V)", (("motor volts", "volts", "#d62728"),)),
)
THESIS_PLOT_ASPECT = 3.4  # wide and low: the thesis's five plots fit the height of a 900 px window
LEGEND_PX = 24.0  # a chart's static legend below it (one line)


def part_plots(params: Parameters) -> tuple[PlotGroup, ...]:
    """The plots of the rig ``params.parts`` names: the thesis's (``PLOTS``) for the thesis's parts; for any
    other, x, θ and θ̇ (θ measured only if the rig has an angle sensor, x measured only if the ball sensor gives
    its software's conversion), then one chart per channel the board reads or writes: its y axis the unit the
    board reads or writes it in (a chart is too low for more), its trace named by the part. The ball sensor's
    readings that carry no position (a VL53L0X's out-of-range code, ``pulseIn``'s 0) are gaps in its chart: a
    code of 8190 mm would flatten every range beside it. The board's output and the actuator's control share a
    chart when they share a unit."""
    parts = rig_parts(params)
    if is_thesis_rig(parts):
        return PLOTS
    x_traces: tuple[Trace, ...] = (("x true", "x_true", "#1f77b4"),)
    if parts.ball_sensor.position_of is not None:
        x_traces += (("measured", "x_meas", "#ff7f0e"),)
    x_traces += (("estimated", "x_est", "#2ca02c"), ("setpoint", "x_ref", "#000000"))
    theta_traces: tuple[Trace, ...] = (("θ true", "th_true", "#1f77b4"),)
    measures_angle = parts.angle_sensor.measures_angle
    if measures_angle and parts.angle_sensor.angle_of is not None:
        theta_traces += (("measured", "th_meas", "#ff7f0e"),)
    theta_traces += (("estimated", "th_est", "#2ca02c"),)
    plots: list[PlotGroup] = [("x (m)", x_traces), ("θ (rad)", theta_traces), PLOTS[2]]
    ball, angle, board, actuator = parts.ball_sensor, parts.angle_sensor, parts.io_board, parts.actuator
    plots.append((ball.reading_unit(params), ((f"{ball.name} reading", "ball_read", "#ff7f0e"),)))
    if measures_angle:
        plots.append((angle.reading_unit(params), ((f"{angle.name} reading", "angle_v", "#8c564b"),)))
    output: Trace = (f"{board.name} output", "dac_v", "#9467bd")
    control: Trace = (f"{actuator.name} control", "volts", "#d62728")
    out_unit = board.output_range(params).unit
    if (
        actuator.control_unit == out_unit
    ):  # a stepper's target is the board's: one chart (it is the same number)
        plots.append((out_unit, (output, control)))
    else:
        plots.append((out_unit, (output,)))
        plots.append((actuator.control_unit, (control,)))
    return tuple(plots)


def plot_aspect(count: int, width_px: float) -> float:
    """The charts' width/height for ``count`` of them in a panel ``width_px`` wide: the thesis's 3.4 for five or
    fewer; more share the five's height (legends included), so that they all fit the same window."""
    if count <= len(PLOTS):
        return THESIS_PLOT_ASPECT
    height = len(PLOTS) * (width_px / THESIS_PLOT_ASPECT + LEGEND_PX) / count - LEGEND_PX
    return width_px / height


@dataclass(frozen=True)
class RigChannels:
    """What the session records and shows of a run on the rig: ``plots`` (``part_plots``); ``position_of`` and
    ``angle_of`` the software's conversions of the board's readings (None: the part gives none, the trace is a
    gap); ``board_output`` what the board puts out for a command (its ``dac_writer``: a pulse on the servo's
    4 µs-class grid, a stepper's whole target; None: the command as the controller gave it, the thesis's "DAC
    out"); ``control_name``/``control_unit`` the actuator's control in the status line; ``thesis`` whether the
    rig is the thesis's (its plots and status line as they always were)."""

    plots: tuple[PlotGroup, ...]
    position_of: Callable[[float], float] | None
    angle_of: Callable[[float], float] | None
    board_output: Callable[[float], float] | None
    control_name: str
    control_unit: str
    thesis: bool = False

    def x_measured_m(self, reading: float) -> float:
        """The ball's x (m) the software makes of a reading; NaN without a conversion or for a reading that
        carries no position (a lost echo)."""
        return float(self.position_of(reading)) if self.position_of is not None else math.nan

    def ball_shown(self, reading: float) -> float:
        """The ball sensor's reading as its chart shows it: NaN (a gap) for a reading that carries no position
        (its ``position_of`` says NaN) on a rig from parts; the reading itself otherwise."""
        if self.thesis or self.position_of is None:
            return reading
        return reading if math.isfinite(self.x_measured_m(reading)) else math.nan

    def theta_measured_rad(self, reading: float) -> float:
        """The beam's angle (rad) the software makes of a reading; NaN for a rig that measures no angle."""
        return float(self.angle_of(reading)) if self.angle_of is not None else math.nan

    def output_of(self, command: float) -> float:
        """The board's output for the controller's ``command`` (its unit: µs, microsteps, volts)."""
        return float(self.board_output(command)) if self.board_output is not None else command

    def control_text(self, value: float) -> str:
        """The actuator's control for the status line: ``motor +1.23 V`` on the thesis's rig."""
        if self.thesis:
            return f"motor {value:+.2f} V"
        return f"{self.control_name} {value:+.4g} {self.control_unit}"


def rig_channels(params: Parameters) -> RigChannels:
    """The channels of the rig ``params.parts`` names (see ``RigChannels``)."""
    parts = rig_parts(params)
    ball, angle = parts.ball_sensor, parts.angle_sensor
    thesis = is_thesis_rig(parts)
    return RigChannels(
        plots=part_plots(params),
        position_of=ball.position_of(params) if ball.position_of is not None else None,
        angle_of=angle.angle_of(params) if angle.measures_angle and angle.angle_of is not None else None,
        board_output=None if thesis else parts.io_board.dac_writer(params),
        control_name="motor" if thesis else parts.actuator.name,
        control_unit=parts.actuator.control_unit,
        thesis=thesis,
    )


# --- the ranging sensor's beam --------------------------------------------------------------------------
@dataclass(frozen=True)
class SensorBeam:
    """A ranging ball sensor's beam of light or sound as the view draws it: from its aperture (``aperture_m``,
    the site its MJCF fragment adds, in the beam body's frame) toward −x along the beam, as long as the distance
    its reading gives (``length_m``)."""

    site: str
    body: str
    aperture_m: tuple[float, float, float]
    radius_m: float
    position_of: Callable[[float], float]

    def length_m(self, reading: float) -> float:
        """The distance (m) the reading gives from the aperture to the ball's near surface: the aperture's x less
        the ball's radius less the x the software makes of it (the inverse of the sensor's law: a VL53L0X's mm
        / 1000, an HC-SR04's echo·c/2); NaN for a reading that carries no position or a distance not ahead."""
        x_m = self.position_of(reading)
        distance = self.aperture_m[0] - self.radius_m - x_m
        return float(distance) if math.isfinite(distance) and distance > 0.0 else math.nan


def sensor_beam(params: Parameters, model: mujoco.MjModel) -> SensorBeam | None:
    """The beam of the ball sensor ``params.parts`` names, if it ranges: its MJCF fragment owns a site (its
    aperture, ``twin.parts.ranging.add_housing``) on the beam and it gives its software's conversion; None for a
    sensor on the track (the thesis's wire) or a model without the site."""
    ball = rig_parts(params).ball_sensor
    sites = [name for kind, name in ball.mjcf.elements if kind == "site"]
    if not sites or ball.position_of is None:
        return None
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, sites[0])
    if site < 0 or model.site_bodyid[site] != mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, BEAM_BODY):
        return None  # the distance is measured along the beam: a sensor mounted elsewhere draws none
    x, y, z = (float(v) for v in model.site_pos[site])
    return SensorBeam(sites[0], BEAM_BODY, (x, y, z), params.ball.radius_m, ball.position_of(params))
