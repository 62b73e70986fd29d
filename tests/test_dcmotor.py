"""Motor torque at the beam: eq 3.3.2, τ = 0.016383·(V − 0.154·θ̇), from MuJoCo's dcmotor."""

import numpy as np
import pytest

from twin.dcmotor import beam_torque_nm
from twin.parameters import Parameters
from twin.rigs import measurements


@pytest.mark.quick
def test_joint_torque_follows_eq_3_3_2_over_the_operating_range(params: Parameters) -> None:
    grid = measurements.motor_torque_grid(params)  # 13 volts in ±12 V × 11 rates in ±10 rad/s
    np.testing.assert_array_equal(grid.volts_v, np.linspace(-12.0, 12.0, 13))
    np.testing.assert_array_equal(grid.thetadot_rad_s, np.linspace(-10.0, 10.0, 11))
    worst = 0.0
    for i, volts in enumerate(grid.volts_v):
        for j, thetadot in enumerate(grid.thetadot_rad_s):
            expected = 0.016383 * (volts - 0.154 * thetadot)
            got = grid.torque_nm[i, j]
            assert got == pytest.approx(expected, rel=0.005, abs=1e-9)
            assert beam_torque_nm(params.motor, params.amplifier, volts, thetadot) == pytest.approx(
                expected, rel=0.005, abs=1e-9
            )
            if abs(expected) > 1e-6:
                worst = max(worst, abs(got / expected - 1.0))
    assert worst < 1e-4  # 0.016383 is the thesis's rounding of 7·0.022/9.4 = 0.0163830


@pytest.mark.quick
@pytest.mark.parametrize(("command", "rail"), [(20.0, 12.0), (-20.0, -12.0)])
def test_commands_beyond_the_rails_give_the_rail_torque(
    params: Parameters, command: float, rail: float
) -> None:
    assert measurements.motor_torque_nm(params, command, 0.0) == pytest.approx(0.016383 * rail, rel=1e-4)
    assert beam_torque_nm(params.motor, params.amplifier, command, 0.0) == pytest.approx(
        0.016383 * rail, rel=1e-4
    )
