"""Motor torque at the beam: eq 3.3.2, τ = 0.016383·(V − 0.154·θ̇), from MuJoCo's dcmotor."""

import mujoco
import numpy as np
import pytest

from twin.dcmotor import beam_torque_nm
from twin.parameters import Parameters
from twin.plant import Plant


def _joint_torque(plant: Plant, volts: float, thetadot: float) -> float:
    plant.reset(theta_rad=0.0, thetadot_rad_s=thetadot)
    plant.data.ctrl[0] = volts
    mujoco.mj_forward(plant.model, plant.data)
    return plant.motor_torque_nm()


def test_joint_torque_follows_eq_3_3_2_over_the_operating_range(params: Parameters) -> None:
    plant = Plant(params)
    worst = 0.0
    for volts in np.linspace(-12.0, 12.0, 13):
        for thetadot in np.linspace(-10.0, 10.0, 11):
            expected = 0.016383 * (volts - 0.154 * thetadot)
            got = _joint_torque(plant, float(volts), float(thetadot))
            assert got == pytest.approx(expected, rel=0.005, abs=1e-9)
            assert beam_torque_nm(params.motor, params.amplifier, volts, thetadot) == pytest.approx(
                expected, rel=0.005, abs=1e-9
            )
            if abs(expected) > 1e-6:
                worst = max(worst, abs(got / expected - 1.0))
    assert worst < 1e-4  # 0.016383 is the thesis's rounding of 7·0.022/9.4 = 0.0163830


@pytest.mark.parametrize(("command", "rail"), [(20.0, 12.0), (-20.0, -12.0)])
def test_commands_beyond_the_rails_give_the_rail_torque(
    params: Parameters, command: float, rail: float
) -> None:
    plant = Plant(params)
    assert _joint_torque(plant, command, 0.0) == pytest.approx(0.016383 * rail, rel=1e-4)
    assert beam_torque_nm(params.motor, params.amplifier, command, 0.0) == pytest.approx(
        0.016383 * rail, rel=1e-4
    )
