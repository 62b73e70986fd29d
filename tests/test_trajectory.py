"""MuJoCo and the reference model agree over the same 1 s voltage profile (1 mm in x, 5 mrad in θ)."""

import numpy as np
import pytest
import scipy.signal

from twin.plant import Plant
from twin.reference import ReferenceModel


def _stabilising_profile(reference: ReferenceModel, x0: np.ndarray, ticks: int) -> np.ndarray:
    """Volts that keep the reference near the origin for 1 s (computed in closed loop on the reference, then
    replayed open loop on both models: the open-loop plant is unstable, so a random profile would diverge)."""
    a, b = reference.linearize("voltage")
    gain = scipy.signal.place_poles(a, b, [-2.0, -3.0, -4.0, -5.0]).gain_matrix[0]
    state, volts = x0.copy(), []
    for _ in range(ticks):
        u = float(-gain @ state)
        volts.append(u)
        state = reference.simulate(state, [u], 0.02, samples_per_hold=1)[1][-1]
    return np.array(volts)


@pytest.mark.parametrize("x0", [(0.15, 0.1, 0.0, 0.0), (-0.2, 0.3, 0.0, 0.0)])
def test_same_voltage_profile_same_trajectory(reference: ReferenceModel, params, x0) -> None:
    x0 = np.array(x0)
    volts = _stabilising_profile(reference, x0, 50)
    assert np.max(np.abs(volts)) < 12.0  # stays inside the rails: no clipping difference between models
    _, ref_states = reference.simulate(x0, volts, 0.02, samples_per_hold=20)
    plant = Plant(params)
    plant.reset(*x0)
    twin_states = [plant.state()]
    for u in volts:
        for _ in range(20):
            plant.step(float(u))
            twin_states.append(plant.state())
    twin_states = np.array(twin_states)
    assert np.max(np.abs(twin_states[:, 0] - ref_states[:, 0])) < 1e-3
    assert np.max(np.abs(twin_states[:, 1] - ref_states[:, 1])) < 5e-3
