"""The compiled screening engine's plant (twin.screen): its derivative is the reference model's at random states
and volts to 1e-12, and its RK4 steps, stops and lost ball are ReferencePlant.advance's over random starts,
volts and parameter sets (each run its own)."""

from __future__ import annotations

import numpy as np
import pytest

from twin.app.montecarlo import load_spread, sample_parameters
from twin.parameters import Parameters
from twin.reference import ReferenceModel, ReferencePlant
from twin.screen import advance_plant, plant_rows
from twin.screen.plant import derivatives


@pytest.mark.quick
def test_the_kernels_derivative_is_the_reference_models() -> None:
    rng = np.random.default_rng(0)
    p = Parameters().with_overrides({"beam.pivot_friction_nm": 2e-3, "beam.pivot_damping_nm_s_per_rad": 1e-3})
    n = 2000
    states = np.column_stack(
        [
            rng.uniform(-0.32, 0.32, n),
            rng.uniform(-0.75, 0.75, n),
            rng.uniform(-2, 2, n),
            rng.uniform(-5, 5, n),
        ]
    )
    states[:50, 3] = rng.uniform(-0.01, 0.01, 50)  # inside the dry friction's regularisation
    volts = rng.uniform(-12, 12, n)
    got = derivatives(plant_rows([p] * n), states, volts)
    model = ReferenceModel(p)
    want = np.array([model.derivative(s, float(v)) for s, v in zip(states, volts, strict=True)])
    assert np.max(np.abs(got - want) / np.maximum(1.0, np.abs(want))) <= 1e-12


def test_the_kernels_steps_are_the_reference_plants_for_every_run() -> None:
    """Over 1.5 s of random volts from random starts (some run into the stops, some lose the ball), each run on
    its own parameter set drawn from the example spread."""
    rng = np.random.default_rng(1)
    base = Parameters()
    spread = load_spread("docs/examples/spread.toml", base)
    params, _ = sample_parameters(base, spread, 24, seed=3)
    n, m = len(params), 1500
    start = np.column_stack(
        [rng.uniform(-0.3, 0.3, n), rng.uniform(-0.7, 0.7, n), rng.uniform(-0.5, 0.5, n), np.zeros(n)]
    )
    volts = np.repeat(rng.uniform(-14, 14, (n, m // 20)), 20, axis=1)  # held per 20 ms tick, past the rails
    states, lost = start.copy(), np.full(n, -1, dtype=np.int64)
    plant = plant_rows(params)
    advance_plant(plant, states, lost, volts[:, :700])
    advance_plant(plant, states, lost, volts[:, 700:], step0=700)  # in two calls, as a loop of ticks
    kinds = set()
    for i, p in enumerate(params):
        ref = ReferencePlant(p)
        ref.reset(*start[i])
        ref.advance(volts[i])
        assert np.max(np.abs(states[i] - ref.state())) <= 1e-12, i
        want = -1 if ref.ball_lost_time_s is None else round(ref.ball_lost_time_s / p.physics.timestep_s)
        assert lost[i] == want, i
        kinds.add("lost" if want >= 0 else "kept")
        kinds.add("stops" if abs(abs(ref.state()[1]) - p.beam.stop_angle_rad) < 1e-15 else "free")
    assert kinds >= {"lost", "kept", "stops"}  # the cases the comparison covers
