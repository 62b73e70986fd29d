"""The vector of rigs (twin.rigs.vector, BallBeam-v0's vector env): each rig of the batch reads what its own
``SimRig`` reads, bit for bit."""

import numpy as np
import pytest

from twin.rigs.sim import SimRig
from twin.rigs.vector import VectorRig


@pytest.mark.quick
def test_each_rig_of_the_vector_is_its_single_rig(params) -> None:
    x0, th0, seeds = np.array([0.1, -0.05]), np.array([0.0, 0.2]), np.array([3, 4])
    vector = VectorRig(2, params, nthread=1)
    start, first = vector.reset([0, 1], [params, params], x0, th0, seeds)
    singles = [SimRig(params, seed=int(s)) for s in seeds]
    for rig, x, th in zip(singles, x0, th0, strict=True):
        rig.reset(float(x), float(th))
    for blocks in (start, first):
        reads = [rig.read() for rig in singles]
        np.testing.assert_array_equal(blocks.ball_v, [r.ball_v for r in reads])
        np.testing.assert_array_equal(blocks.angle_v, [r.angle_v for r in reads])
        np.testing.assert_array_equal(blocks.time_s, [r.time_s for r in reads])
    for command in ([2.5, 2.5], [3.0, 1.5], [1.0, 4.0]):
        blocks = vector.step([0, 1], np.array(command))
        for rig, c in zip(singles, command, strict=True):
            rig.write(c)
        reads = [rig.read() for rig in singles]
        np.testing.assert_array_equal(blocks.ball_v, [r.ball_v for r in reads])
        np.testing.assert_array_equal(blocks.angle_v, [r.angle_v for r in reads])
    with pytest.raises(ValueError, match="at least one rig"):
        VectorRig(0, params)
