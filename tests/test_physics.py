"""The physics backends' shared contract (twin.physics): the initial states a rig takes, and the block both
backends hand the sensor chains."""

import math

import numpy as np
import pytest

from twin.physics import PhysicsBlock, check_initial_state
from twin.plant import Plant
from twin.reference import ReferencePlant


@pytest.mark.quick
def test_initial_states_on_the_track_and_within_the_stops_are_taken_the_rest_refused(params) -> None:
    half, stop = params.track.half_length_m, params.beam.stop_angle_rad
    check_initial_state(params, half, -stop, 0.0, 0.0)  # the ends of the track and the stops are allowed
    check_initial_state(params, -half, stop, 1.0, -1.0)
    with pytest.raises(ValueError, match="off the track"):
        check_initial_state(params, math.nextafter(half, 1.0), 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="beyond the stops"):
        check_initial_state(params, 0.0, -math.nextafter(stop, 1.0), 0.0, 0.0)
    for bad in (math.nan, math.inf, "0.1", None):
        with pytest.raises(ValueError, match="not a finite number"):
            check_initial_state(params, 0.0, 0.0, bad, 0.0)  # type: ignore[arg-type]


@pytest.mark.quick
@pytest.mark.parametrize("backend", [Plant, ReferencePlant], ids=["twin", "reference"])
def test_both_backends_give_a_block_of_n_plus_one_states_one_step_apart(params, backend) -> None:
    physics = backend(params)
    physics.reset(0.05, 0.0)
    block = physics.advance_held(0.0, 10)
    assert isinstance(block, PhysicsBlock)
    assert len(block.time_s) == len(block.x_m) == len(block.theta_rad) == len(block.on_track) == 11
    np.testing.assert_allclose(np.diff(block.time_s), physics.timestep_s, rtol=1e-9)
    assert block.x_m[0] == 0.05 and block.on_track.all()
    # Released level with zero volts the ball starts from rest: ten steps move it by far less than a mm.
    assert abs(block.x_m[-1] - 0.05) < 1e-3
