"""The live view on a rig from parts (twin.viewer.channels): its plots name each channel by its part and the
board's unit (a VL53L0X's mm over I²C, an HC-SR04's echo in µs, analogRead's counts, a servo pulse's µs, a
stepper's target), the thesis's view is the thesis's, the ball's plotted reading is the board's reading on a tick,
"measured x" is the ball sensor's own conversion of it, and the ranging sensor's beam is drawn as long as its
reading says. Expected values are written out by hand or computed here from the data sheets' laws."""

from __future__ import annotations

import math
import socket
import warnings
from collections.abc import Iterator

import numpy as np
import pytest
import viser
from viewer_stubs import StubCatalogue

from twin import converters
from twin.interface import Controller, DaqSample
from twin.parameters import Parameters
from twin.parts import rig_parts
from twin.parts.description import preset
from twin.parts.vl53l0x import Vl53l0x
from twin.viewer.channels import PLOTS, part_plots, plot_aspect, rig_channels, sensor_beam
from twin.viewer.gui import PLOT_PANEL_PX, Panels
from twin.viewer.scene import CAMERAS, Scene, rig_cameras
from twin.viewer.session import LiveTwin

# The HC-SR04's speed of sound at the preset's 20 °C, written out: c = 331.3·√(1 + T/273.15) m/s (ideal gas).
C_20C_M_S = 331.3 * math.sqrt(1.0 + 20.0 / 273.15)

THESIS_TITLES = ["x (m)", "θ (rad)", "θ̇ (rad/s)", "I/O card (V)", "motor (V)"]
# Each chart: its y axis (the unit the board reads or writes) and its traces, the channels' named by the part.
EXPECTED_CHARTS = {
    "open-ball-and-beam": [
        ("x (m)", ["x true", "measured", "estimated", "setpoint"]),
        ("θ (rad)", ["θ true", "estimated"]),  # no angle sensor: nothing measured, no angle chart
        ("θ̇ (rad/s)", ["θ̇ true", "estimated"]),
        ("mm", ["vl53l0x reading"]),  # RangeMilliMeter over I²C
        ("µs", ["arduino_uno output"]),  # writeMicroseconds
        ("rad", ["hobby_servo control"]),  # the servo's target angle
    ],
    "arduino-stepper-ultrasonic": [
        ("x (m)", ["x true", "measured", "estimated", "setpoint"]),
        ("θ (rad)", ["θ true", "measured", "estimated"]),
        ("θ̇ (rad/s)", ["θ̇ true", "estimated"]),
        ("µs", ["hcsr04 reading"]),  # pulseIn's echo width
        ("counts", ["as5600 reading"]),  # RAW ANGLE over I²C
        ("microsteps", ["arduino_uno output", "stepper control"]),  # moveTo's target, one unit: one chart
    ],
}


class Hold(Controller):
    """Writes the actuator's rest command (a servo's centre pulse, a stepper's 0 target) and nudges it by a
    sine, so that the board's output moves: a controller designed in no time (rig-lqg's design takes seconds)."""

    name = "hold"

    def __init__(self, params: Parameters | None) -> None:
        super().__init__()
        p = params or Parameters()
        self.rest = rig_parts(p).actuator.rest_command(p)
        self.k = 0

    def start(self, sample: DaqSample) -> None:
        pass

    def update(self, sample: DaqSample) -> float:
        self.k += 1
        return self.rest + 7.3 * math.sin(0.3 * self.k)  # 7.3 µs or microsteps about the rest: not whole


def _live(params: Parameters, controller: str = "hold") -> LiveTwin:
    catalogue = StubCatalogue({"hold": Hold})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the held rig's first write may clamp (a warning, not this test's)
        return LiveTwin(params, catalogue, controller, seed=0, speed=1.0)  # type: ignore[arg-type]


def _titles(params: Parameters) -> list[str]:
    return [title for title, _ in part_plots(params)]


def _charts(params: Parameters) -> list[tuple[str, list[str]]]:
    return [(title, [name for name, _, _ in traces]) for title, traces in part_plots(params)]


@pytest.fixture
def server() -> Iterator[viser.ViserServer]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    yield server
    server.stop()


# --- the plots' names and units ------------------------------------------------------------------------------
@pytest.mark.quick
def test_the_thesis_rig_keeps_the_thesis_plots_and_status() -> None:
    params = preset("thesis")
    assert part_plots(params) is PLOTS and part_plots(Parameters()) is PLOTS
    assert _titles(params) == THESIS_TITLES
    assert [name for name, _, _ in PLOTS[3][1]] == ["ball ADC", "angle ADC", "DAC out"]
    channels = rig_channels(params)
    assert channels.control_text(1.234) == "motor +1.23 V"
    assert channels.output_of(2.3456) == 2.3456  # the thesis's "DAC out" is the command as given
    # Its measured x and θ: the thesis software's eq 6.3.1 and 6.2.10, as before.
    sw = params.software
    for volts in (-3.0, 0.5, 2.2):
        assert channels.x_measured_m(volts) == float(converters.ball_position_m(volts, sw))
        assert channels.theta_measured_rad(volts) == float(converters.beam_angle_rad(volts, sw))
    # A parameter changed is still the thesis's rig (its parts are).
    assert part_plots(params.with_overrides({"motor.resistance_ohm": 10.0})) is PLOTS


@pytest.mark.quick
@pytest.mark.parametrize("name", sorted(EXPECTED_CHARTS))
def test_a_presets_plots_are_named_from_its_parts_in_the_boards_units(name: str) -> None:
    params = preset(name)
    assert _charts(params) == EXPECTED_CHARTS[name]
    # Every trace's key is one the session records on a tick.
    live = _live(params)
    live.tick()
    keys = {key for _, traces in part_plots(params) for _, key, _ in traces}
    assert keys <= set(live.history.columns)


@pytest.mark.quick
@pytest.mark.parametrize(
    ("overrides", "ball", "angle"),
    [
        # analog sensors read through the board's ADC: analogRead's counts on an Uno, volts on the PCI-1712
        (
            {"parts.ball_sensor": "gp2y0a21", "parts.angle_sensor": "potentiometer"},
            ("counts", ["gp2y0a21 reading"]),
            ("counts", ["potentiometer reading"]),
        ),
        (
            {"parts.ball_sensor": "gp2y0a21", "parts.io_board": "pci1712"},
            ("V", ["gp2y0a21 reading"]),
            ("counts", ["as5600 reading"]),
        ),
        # the AS5600 on its analog OUT pin is read by the ADC; over I²C it is counts on any board
        (
            {"parts.io_board": "pci1712", "as5600.analog_output": True},
            ("µs", ["hcsr04 reading"]),
            ("V", ["as5600 reading"]),
        ),
        ({"as5600.analog_output": True}, ("µs", ["hcsr04 reading"]), ("counts", ["as5600 reading"])),
        # the thesis's wire has no unit of its own (the contract's default): the board's
        (
            {"parts.ball_sensor": "resistive_wire"},
            ("counts", ["resistive_wire reading"]),
            ("counts", ["as5600 reading"]),
        ),
    ],
)
def test_an_analog_sensor_reads_in_its_boards_unit(overrides: dict, ball: tuple, angle: tuple) -> None:
    params = preset("arduino-stepper-ultrasonic").with_overrides(overrides)
    assert _charts(params)[3:5] == [ball, angle]


@pytest.mark.quick
def test_more_charts_share_the_thesis_charts_height() -> None:
    """Seven charts, legends included, are as tall as the thesis's five: 7·(w/a + 24) = 5·(w/3.4 + 24)."""
    w = float(PLOT_PANEL_PX)
    assert plot_aspect(5, w) == 3.4 and plot_aspect(3, w) == 3.4
    a = plot_aspect(7, w)
    assert 7 * (w / a + 24.0) == pytest.approx(5 * (w / 3.4 + 24.0), rel=1e-12)


@pytest.mark.quick
def test_the_panel_draws_the_rigs_charts(server: viser.ViserServer) -> None:
    live = _live(preset("arduino-stepper-ultrasonic"))
    panels = Panels(server, live)
    labels = [handle.axes[1]["label"] for handle, _ in panels.plots]
    legends = [[s["label"] for s in handle.series[1:]] for handle, _ in panels.plots]
    assert list(zip(labels, legends, strict=True)) == EXPECTED_CHARTS["arduino-stepper-ultrasonic"]
    assert all(handle.aspect == plot_aspect(6, PLOT_PANEL_PX) for handle, _ in panels.plots)
    assert "stepper +0 microsteps" in live.status_markdown()  # the held rig's rest target, in its unit


def _obb_curve_m(params: Parameters) -> tuple[float, float, np.ndarray, np.ndarray]:
    """The OBB preset's VL53L0X: its mount, the ball's radius (m), and its measured table (true distance mm,
    mean reading mm), the inputs of the hand computations below."""
    s = params.of(Vl53l0x)
    assert (
        s.crosstalk_offset_mm == 0.0 and len(s.curve_distance_mm) >= 2
    )  # the preset reads through its table
    return s.mount_x_m, params.ball.radius_m, np.array(s.curve_distance_mm), np.array(s.curve_reading_mm)


def _distance_mm(reading_mm: float, table_d: np.ndarray, table_r: np.ndarray) -> float:
    """The table read backwards between its points (a broken line): the distance a reading means."""
    assert table_r[0] <= reading_mm <= table_r[-1]  # within the table: no extrapolation to check
    return float(np.interp(reading_mm, table_r, table_d))


# --- what is plotted on a tick -------------------------------------------------------------------------------
@pytest.mark.quick
def test_the_vl53l0x_reading_plotted_is_the_boards_and_x_is_its_conversion() -> None:
    params = preset("open-ball-and-beam").with_overrides({"ball_sensor.noise_enabled": False})
    live = _live(params)
    mount_m, r_m, table_d, table_r = _obb_curve_m(params)
    steepest = float(np.max(np.diff(table_r) / np.diff(table_d)))  # reading mm per true mm
    for _ in range(30):
        live.tick()
        sample = live.last_sample
        assert sample is not None
        h = live.history
        reading = float(h.array("ball_v")[-1])
        assert reading == sample.ball_v  # the board's reading, as it reads it (whole mm)
        assert reading == round(reading)
        assert float(h.array("ball_read")[-1]) == reading  # its chart's trace: a range, no gap
        # the table at the ball's near surface, within what it rolled over the range's budget and its age
        # (two 20 ms budgets at most) and the whole-mm rounding
        x_true, xdot = float(h.array("x_true")[-1]), float(h.array("xdot_true")[-1])
        rolled_mm = 1000.0 * (abs(xdot) + 0.05) * 0.04
        expected = float(np.interp(1000.0 * (mount_m - x_true - r_m), table_d, table_r))
        assert abs(reading - expected) <= 0.5 + steepest * rolled_mm
        # measured x: the part's software conversion, x = mount − r − distance(reading)
        x_meas = mount_m - r_m - _distance_mm(reading, table_d, table_r) / 1000.0
        assert float(h.array("x_meas")[-1]) == pytest.approx(x_meas, abs=1e-7)
        assert np.isnan(h.array("th_meas")[-1])  # no angle sensor: nothing measured
        # the board's output: writeMicroseconds' whole µs of the command (16 MHz: the pulse is the int)
        command = live.loop.command_v
        assert float(h.array("dac_v")[-1]) == float(min(max(math.trunc(command), 544), 2400))


@pytest.mark.quick
def test_the_hcsr04_echo_plotted_is_the_boards_and_x_is_its_conversion() -> None:
    params = preset("arduino-stepper-ultrasonic").with_overrides({"ball_sensor.noise_enabled": False})
    live = _live(params)
    mount_m, r_m = 0.22, 0.01905
    for _ in range(25):
        live.tick()
        h = live.history
        echo_us = float(h.array("ball_v")[-1])
        assert live.last_sample is not None and echo_us == live.last_sample.ball_v
        # x = mount − r − echo·c/2, the preset's 20 °C: float32 history, 1e-6 m
        assert float(h.array("x_meas")[-1]) == pytest.approx(
            mount_m - r_m - echo_us * 1e-6 * C_20C_M_S / 2.0, abs=1e-6
        )
        # the AS5600's counts through its conversion: within a few counts (2π/4096 rad each) of the truth
        theta_true, theta_meas = float(h.array("th_true")[-1]), float(h.array("th_meas")[-1])
        assert abs(theta_meas - theta_true) < 8 * 2.0 * math.pi / 4096
        # moveTo's target: the command truncated toward zero
        assert float(h.array("dac_v")[-1]) == float(math.trunc(live.loop.command_v))


# --- the sensor's beam ---------------------------------------------------------------------------------------
@pytest.mark.quick
def test_the_thesis_wire_draws_no_beam(server: viser.ViserServer) -> None:
    live = _live(Parameters())
    scene = Scene(server, live)
    assert scene.beam is None and scene.beam_node is None
    scene.update()


@pytest.mark.quick
def test_the_vl53l0x_beam_is_as_long_as_its_reading(server: viser.ViserServer) -> None:
    params = preset("open-ball-and-beam")
    live = _live(params)
    mount_m, _, table_d, table_r = _obb_curve_m(params)
    scene = Scene(server, live)
    assert scene.beam is not None and scene.beam.site == "vl53l0x_aperture" and scene.beam.body == "beam"
    x_ap, _, z_ap = scene.beam.aperture_m
    assert x_ap == pytest.approx(mount_m, abs=1e-12)  # the preset's mount, in the beam's frame
    seen = set()
    for _ in range(15):
        live.tick()
        scene.update()
        assert live.last_sample is not None
        reading_mm = live.last_sample.ball_v
        node = scene.beam_node
        assert node.visible
        length_m = _distance_mm(reading_mm, table_d, table_r) / 1000.0  # the table's distance, mm → m
        assert node.height == pytest.approx(length_m, abs=1e-12)
        x_mid, _, z_mid = node.position
        assert x_mid == pytest.approx(x_ap - 0.5 * length_m, abs=1e-12)  # from the aperture toward −x
        assert z_mid == pytest.approx(z_ap, abs=1e-12)
        seen.add(reading_mm)
    assert len(seen) > 3  # it follows the reading
    # The out-of-range code (8190 mm) carries no distance: the beam is hidden.
    assert math.isnan(scene.beam.length_m(8190.0))


@pytest.mark.quick
def test_the_hcsr04_beam_is_the_echos_distance_and_a_lost_echo_hides_it() -> None:
    params = preset("arduino-stepper-ultrasonic")
    model = rig_parts(params).build_spec(params).compile()
    beam = sensor_beam(params, model)
    assert beam is not None and beam.site == "hcsr04_aperture"
    for echo_us in (300.0, 942.0, 1500.0):
        assert beam.length_m(echo_us) == pytest.approx(echo_us * 1e-6 * C_20C_M_S / 2.0, abs=1e-12)
    assert math.isnan(beam.length_m(0.0))  # pulseIn's 0: no echo


@pytest.mark.quick
def test_a_vl53l0x_on_its_linear_law_draws_its_range_in_metres() -> None:
    """Without a measured table the range is the distance less the crosstalk: the beam is (range + crosstalk)/1000."""
    params = preset("arduino-stepper-ultrasonic").with_overrides(
        {"parts.ball_sensor": "vl53l0x", "vl53l0x.mount_x_m": 0.22, "vl53l0x.crosstalk_offset_mm": 5.0}
    )
    beam = sensor_beam(params, rig_parts(params).build_spec(params).compile())
    assert beam is not None and beam.site == "vl53l0x_aperture"
    for range_mm in (20.0, 150.0, 390.0):
        assert beam.length_m(range_mm) == pytest.approx((range_mm + 5.0) / 1000.0, abs=1e-12)
    assert math.isnan(beam.length_m(8190.0))  # the out-of-range code: no distance, the beam hidden


@pytest.mark.quick
def test_a_reading_without_a_position_is_a_gap_in_its_chart() -> None:
    """The VL53L0X's out-of-range code (8190 mm) and pulseIn's 0 (no echo) carry no position: gaps, not spikes
    that flatten the chart; the thesis's wire volts are plotted as read, whatever they are."""
    obb = rig_channels(preset("open-ball-and-beam"))
    assert math.isnan(obb.ball_shown(8190.0)) and obb.ball_shown(75.0) == 75.0
    stepper = rig_channels(preset("arduino-stepper-ultrasonic"))
    assert math.isnan(stepper.ball_shown(0.0)) and stepper.ball_shown(942.0) == 942.0
    assert rig_channels(Parameters()).ball_shown(-4.9) == -4.9


@pytest.mark.quick
@pytest.mark.parametrize(
    ("name", "shift_m", "scale"),
    [
        ("thesis", 0.0, 1.0),
        # hinged at its back end: the track's middle 115 mm out; 1.25·105 mm of half track: at most half as near
        ("open-ball-and-beam", 0.115, 0.5),
        ("arduino-stepper-ultrasonic", 0.0, 1.25 * 0.2 / 0.323),  # 0.2 m of half track and a quarter more
    ],
)
def test_the_cameras_look_at_the_rigs_track(name: str, shift_m: float, scale: float) -> None:
    cameras = rig_cameras(preset(name))
    if name == "thesis":
        assert cameras is CAMERAS
    assert list(cameras) == list(CAMERAS)
    for key, (position, look_at, up) in cameras.items():
        t_position, t_look_at, t_up = CAMERAS[key]
        assert up == t_up
        assert look_at == pytest.approx((t_look_at[0] + shift_m, t_look_at[1], t_look_at[2]), abs=1e-12)
        ours, theirs = np.subtract(position, look_at), np.subtract(t_position, t_look_at)
        np.testing.assert_allclose(ours, scale * theirs, atol=1e-12)  # the same direction, nearer


def test_the_status_lines_peak_is_the_actuators_control_in_its_unit() -> None:
    """On a servo rig the verdict's peak control is the servo's target angle (rad), not motor volts at rails."""
    from controllers.rig_lqg import rig_lqg
    from twin.rigs.sim import run_closed_loop
    from twin.viewer.channels import rig_channels
    from twin.viewer.session import verdict_text

    rig = preset("open-ball-and-beam")
    result = run_closed_loop(rig_lqg(rig), x0_m=0.05, theta0_rad=0.0, duration_s=6.0, params=rig)
    text = verdict_text(result.verdict, channels=rig_channels(rig))
    peak = result.verdict.peak_motor_voltage_v
    assert f"peak hobby_servo {peak:.4g} rad" in text and "rails" not in text
    assert "% at the rails" in verdict_text(result.verdict)  # the thesis's line, as it always was
