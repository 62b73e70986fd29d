"""The twin behind the Rig interface: block semantics, latency, seeds, and what the sensors read."""

import numpy as np
import pytest
from thesis_data import TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V

from twin import converters
from twin.daq import adc_lsb_v
from twin.interface import RigError
from twin.parameters import Parameters
from twin.rigs import measurements
from twin.rigs.sim import ReferenceRig, SimRig, TwinRig

SW = Parameters().software


def test_period_must_be_whole_physics_steps() -> None:
    with pytest.raises(RigError, match="daq.period_s = 0.0205"):
        TwinRig(Parameters().with_overrides({"daq.period_s": 0.0205}))
    with pytest.raises(RigError, match="daq.output_latency_s = 0.0025"):
        TwinRig(
            Parameters().with_overrides(
                {
                    "daq.output_latency_s": 0.0025,
                    "physics.timestep_s": 0.002,
                    "physics.contact_timeconst_s": 0.004,
                }
            )
        )

    with pytest.raises(RigError, match="start.free_run_s = 0.0105"):
        TwinRig(Parameters().with_overrides({"start.free_run_s": 0.0105}))


@pytest.mark.parametrize("free_run_s", [0.0, 0.01, 0.02, 0.04])
def test_blocks_end_at_free_run_plus_whole_periods(free_run_s: float) -> None:
    """The start block ends one period before the first command, which reaches the motor at free_run."""
    rig = TwinRig(Parameters().with_overrides({"start.free_run_s": free_run_s}), noise=False)
    rig.reset(0.1, 0.2)
    times = [rig.read().time_s for _ in range(5)]
    np.testing.assert_allclose(times, free_run_s + 0.02 * np.arange(-1, 4), atol=1e-12)
    assert rig.time_s == pytest.approx(free_run_s + 0.06)


@pytest.mark.quick
@pytest.mark.parametrize("plant", ["twin", "reference"])
def test_a_free_run_longer_than_the_period_runs_the_rig_before_the_start_block(plant: str) -> None:
    """daq.period_s = 1 ms, free run 10 ms: start() reads the block (8, 9] ms of a rig released at 0; the
    state then equals 9 ms of free fall stepped without blocks."""
    params = Parameters().with_overrides({"daq.period_s": 0.001, "start.free_run_s": 0.01})
    rig = SimRig(params, noise=False, plant=plant)  # type: ignore[arg-type]
    rig.reset(0.1, 0.2)
    assert rig.read().time_s == pytest.approx(0.009, abs=1e-12)
    free = SimRig(params.with_overrides({"start.free_run_s": 0.0}), noise=False, plant=plant)  # type: ignore[arg-type]
    free.reset(0.1, 0.2)
    free.read()  # (−2, −1] ms held
    for _ in range(10):  # (−1, 0] held, then 9 blocks of 1 ms at 0 V
        free.read()
    np.testing.assert_array_equal(rig.true_state(), free.true_state())


@pytest.mark.quick
def test_the_rig_is_held_until_release_then_falls_freely() -> None:
    """free_run = 0.02 s: the start block (−0.02, 0] sees the held rig; the next one the rig falling at 0 V."""
    rig = TwinRig(Parameters().with_overrides({"start.free_run_s": 0.02}), noise=False)
    rig.reset(0.1, 0.2)
    rig.read()  # (−0.02, 0]: held
    assert rig.time_s == 0.0
    np.testing.assert_array_equal(rig.true_state(), [0.1, 0.2, 0.0, 0.0])
    rig.read()  # (0, 0.02]: released at 0 V; the beam falls under the ball's weight at x = 0.1
    x, theta, xdot, thetadot = rig.true_state()
    assert theta != 0.2 and thetadot != 0.0 and xdot < 0.0


@pytest.mark.quick
def test_nan_command_is_refused() -> None:
    rig = TwinRig(noise=False)
    with pytest.raises(ValueError, match="command_v = nan"):
        rig.write(float("nan"))


@pytest.mark.quick
def test_ball_at_rest_reads_table_6_3() -> None:
    """Ball placed at each measured position, noise off: the first block reads the table to the ADC's
    rounding, half an LSB (the curve passes through the table's points and the filter is at rest)."""
    table = measurements.ball_table_readings(Parameters())
    np.testing.assert_array_equal(table.position_m, TABLE_6_3_POSITION_M)
    np.testing.assert_array_equal(table.curve_v, TABLE_6_3_VOLTAGE_V)
    lsb = adc_lsb_v(Parameters().daq)
    # Measured: 0.49 LSB at worst.
    assert np.all(np.abs(table.reading_v - np.array(TABLE_6_3_VOLTAGE_V)) <= 0.5 * lsb + 1e-12)


@pytest.mark.parametrize("theta_rad", [-0.4, -0.1, 0.0, 0.05, 0.3])
def test_beam_angle_reads_back_to_one_count(theta_rad: float) -> None:
    rig = TwinRig(noise=False)
    rig.reset(theta_rad=theta_rad)
    angle = converters.beam_angle_rad(rig.read().angle_v, SW)
    # One count is 2π/(256·7) = 3.5 mrad (eq 6.2.1); the beam moves < 1 mrad in the first 20 ms.
    assert angle == pytest.approx(theta_rad, abs=2 * np.pi / (256 * 7) + 1e-3)


@pytest.mark.quick
def test_zeroing_error_shifts_the_reading() -> None:
    """Fig 7.20: the counter zeroed with the beam 0.05 rad off level reads the level beam as −0.05 rad."""
    rig = TwinRig(Parameters().with_overrides({"angle_sensor.zeroing_error_rad": 0.05}), noise=False)
    angle = converters.beam_angle_rad(rig.read().angle_v, SW)
    assert angle == pytest.approx(-0.05, abs=2 * np.pi / (256 * 7))


@pytest.mark.quick
def test_output_latency_delays_the_motor_within_the_tick(params: Parameters) -> None:
    """Full positive command from rest: the beam's rate after one tick scales with the time the volts acted."""
    rates = {}
    for latency in (0.0, 0.01):
        # Released exactly when the command is written, so the rates differ only by the latency.
        rig = TwinRig(
            params.with_overrides({"daq.output_latency_s": latency, "start.free_run_s": 0.02}), noise=False
        )
        rig.read()
        rig.write(3.75)
        rig.read()
        rates[latency] = rig.true_state()[3]
    assert rates[0.01] / rates[0.0] == pytest.approx(0.5, rel=0.03)


def test_same_seed_same_readings_different_seed_different_noise() -> None:
    seeds = measurements.seed_determinism(Parameters(), seed=11, other_seed=12)
    assert seeds.same_seed_identical
    assert seeds.other_seed_ball_differs
    assert seeds.other_seed_angle_identical  # the angle channel has no random source


def test_noise_off_has_no_dropouts_and_can_be_switched_mid_run() -> None:
    rig = TwinRig(seed=5, noise=False)
    for _ in range(500):
        rig.read()
    assert rig.dropout_count == 0
    rig.set_noise(True)
    for _ in range(500):  # 10 s at the default 5 contact losses per second
        rig.read()
    # Poisson: 50 expected, σ = √50 = 7.1; 4σ gives 22…78 (a fixed seed: measured 51).
    expected = rig.params.ball_sensor.dropout_rate_hz * 500 * rig.params.daq.period_s
    assert abs(rig.dropout_count - expected) <= 4 * np.sqrt(expected)


@pytest.mark.quick
@pytest.mark.parametrize("plant", ["twin", "reference"])
def test_ideal_sensors_read_the_exact_state_in_the_softwares_volts(plant: str) -> None:
    """No quantization, wiper curve, RC or noise: the software's converters give back the true x and θ."""
    rig = SimRig(seed=3, plant=plant, ideal_sensors=True)  # type: ignore[arg-type]
    rig.reset(0.17, -0.25)
    for _ in range(4):
        sample = rig.read()
        rig.write(2.9)
        x, theta, _, _ = rig.true_state()
        assert converters.ball_position_m(sample.ball_v, SW) == pytest.approx(x, abs=1e-15)
        assert converters.beam_angle_rad(sample.angle_v, SW) == pytest.approx(theta, abs=1e-14)
    # An exact DAC: 2.9 V is 9.6·0.4 = 3.84 V at the motor, not the 12-bit level's 3.8379 V.
    assert rig.motor_volts_v == pytest.approx(3.84, abs=1e-12)


def test_ideal_sensors_keep_the_zeroing_error() -> None:
    rig = ReferenceRig(Parameters().with_overrides({"angle_sensor.zeroing_error_rad": 0.05}))
    rig.reset(0.0, 0.1)
    assert converters.beam_angle_rad(rig.read().angle_v, SW) == pytest.approx(0.05, abs=1e-14)


def test_a_parameter_file_curve_changes_what_the_ball_channel_reads(tmp_path) -> None:
    path = tmp_path / "rig.toml"
    path.write_text("[ball_sensor]\ncurve_position_m = [-0.323, 0.323]\ncurve_volts_v = [-4.0, 4.0]\n")
    rig = TwinRig(Parameters.from_file(path), noise=False)
    rig.reset(0.1615, 0.0)
    assert rig.read().ball_v == pytest.approx(2.0, abs=adc_lsb_v(rig.params.daq))
    default = TwinRig(noise=False)
    default.reset(0.1615, 0.0)
    assert abs(default.read().ball_v - 2.0) > 0.1
