"""The twin behind the Rig interface: block semantics, latency, seeds, and what the sensors read."""

import numpy as np
import pytest

from twin import converters
from twin.daq import adc_lsb_v
from twin.parameters import Parameters
from twin.rig import RigError, TwinRig
from twin.sensors import TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V


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


def test_blocks_are_stamped_at_their_last_sample() -> None:
    rig = TwinRig(noise=False)
    times = [rig.read().time_s for _ in range(5)]
    np.testing.assert_allclose(times, [0.02, 0.04, 0.06, 0.08, 0.10], atol=1e-12)
    assert rig.time_s == pytest.approx(0.10)


def test_nan_command_is_refused() -> None:
    rig = TwinRig(noise=False)
    with pytest.raises(ValueError, match="command_v = nan"):
        rig.write(float("nan"))


@pytest.mark.parametrize(("x_m", "volts"), list(zip(TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V)))
def test_ball_at_rest_reads_table_6_3(x_m: float, volts: float) -> None:
    """Ball placed at each measured position, noise off: the first block reads the table within 1 LSB."""
    rig = TwinRig(noise=False)
    rig.reset(x_m=float(x_m))
    sample = rig.read()
    assert abs(sample.ball_v - volts) <= adc_lsb_v(rig.params.daq)


@pytest.mark.parametrize("theta_rad", [-0.4, -0.1, 0.0, 0.05, 0.3])
def test_beam_angle_reads_back_to_one_count(theta_rad: float) -> None:
    rig = TwinRig(noise=False)
    rig.reset(theta_rad=theta_rad)
    angle = converters.beam_angle_rad(rig.read().angle_v)
    # One count is 2π/(256·7) = 3.5 mrad (eq 6.2.1); the beam moves < 1 mrad in the first 20 ms.
    assert angle == pytest.approx(theta_rad, abs=2 * np.pi / (256 * 7) + 1e-3)


def test_zeroing_error_shifts_the_reading() -> None:
    """Fig 7.20: the counter zeroed with the beam 0.05 rad off level reads the level beam as −0.05 rad."""
    rig = TwinRig(Parameters().with_overrides({"angle_sensor.zeroing_error_rad": 0.05}), noise=False)
    angle = converters.beam_angle_rad(rig.read().angle_v)
    assert angle == pytest.approx(-0.05, abs=2 * np.pi / (256 * 7))


def test_output_latency_delays_the_motor_within_the_tick(params: Parameters) -> None:
    """Full positive command from rest: the beam's rate after one tick scales with the time the volts acted."""
    rates = {}
    for latency in (0.0, 0.01):
        rig = TwinRig(params.with_overrides({"daq.output_latency_s": latency}), noise=False)
        rig.read()
        rig.write(3.75)
        rig.read()
        rates[latency] = rig.true_state()[3]
    assert rates[0.01] / rates[0.0] == pytest.approx(0.5, rel=0.03)


def _readings(seed: int, noise: bool = True, ticks: int = 300) -> np.ndarray:
    rig = TwinRig(seed=seed, noise=noise)
    rig.reset(x_m=0.1, theta_rad=0.02)
    out = []
    for _ in range(ticks):
        s = rig.read()
        rig.write(2.5 + 0.5 * np.sin(s.time_s))
        out.append((s.time_s, s.ball_v, s.angle_v))
    return np.array(out)


def test_same_seed_same_readings_different_seed_different_noise() -> None:
    a, b, c = _readings(11), _readings(11), _readings(12)
    assert np.array_equal(a, b)
    assert not np.array_equal(a[:, 1], c[:, 1])
    np.testing.assert_array_equal(a[:, 2], c[:, 2])  # the angle channel has no random source


def test_noise_off_has_no_dropouts_and_can_be_switched_mid_run() -> None:
    rig = TwinRig(seed=5, noise=False)
    for _ in range(500):
        rig.read()
    assert rig.dropout_count == 0
    rig.set_noise(True)
    for _ in range(500):  # 10 s at the default 5 contact losses per second
        rig.read()
    assert rig.dropout_count > 20
