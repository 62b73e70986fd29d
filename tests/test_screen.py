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


def _same_as_single_runs(name: str, x0, theta0, seeds, duration_s: float, params=None, **kw) -> list:
    from twin.screen.plant import ReferenceBatchPhysics

    batched = []  # the runs the compiled kernel took (not the single-run path)
    start = ReferenceBatchPhysics.__init__

    def spy(self, params, *args):
        batched.extend(params)
        return start(self, params, *args)

    ReferenceBatchPhysics.__init__ = spy  # type: ignore[method-assign]
    try:
        runs = _compare_with_single_runs(name, x0, theta0, seeds, duration_s, params, **kw)
    finally:
        ReferenceBatchPhysics.__init__ = start  # type: ignore[method-assign]
    assert len(batched) == len(x0)
    return runs


def _compare_with_single_runs(name: str, x0, theta0, seeds, duration_s: float, params=None, **kw) -> list:
    """run_batch(plant="reference") (the compiled kernel under the batch engine's chain) against each run
    alone on the reference plant (ReferencePlant under SimRig): every log array and the verdict."""
    from controllers import registry
    from tests.test_batch import _assert_same_run
    from twin.rigs.batch import run_batch
    from twin.rigs.sim import run_closed_loop

    runs = run_batch(
        registry, name, x0_m=x0, theta0_rad=theta0, seeds=seeds, duration_s=duration_s, params=params,
        plant="reference", record=True, **kw,
    )  # fmt: skip
    for i, batched in enumerate(runs):
        p = params[i] if isinstance(params, list) else params
        single = run_closed_loop(
            registry.make(name, p), x0_m=float(x0[i]), theta0_rad=float(theta0[i]), duration_s=duration_s,
            seed=int(seeds[i]), params=p, plant="reference", **kw,
        )  # fmt: skip
        _assert_same_run(single, batched, f"{name} run {i} (x0 = {x0[i]}, θ0 = {theta0[i]}, seed {seeds[i]})")
    return runs


@pytest.mark.quick
def test_the_fast_engine_is_the_reference_plant_run_alone_bit_for_bit() -> None:
    """Full sensor chain, noise on: hardware starts, a lost ball and the origin, three seeds each."""
    x0 = np.tile([0.14, -0.13, 0.25, 0.0], 3)
    theta0 = np.tile([-0.2, 0.29, -0.7, 0.0], 3)
    runs = _same_as_single_runs("appendix-sf", x0, theta0, np.repeat([0, 1, 2], 4), 2.0)
    assert any(r.verdict.ball_lost for r in runs) and not all(r.verdict.ball_lost for r in runs)


@pytest.mark.parametrize(
    ("name", "kw"),
    [
        ("appendix-clp", {"stop_when_lost": False}),
        ("lqr", {"ideal_sensors": True}),
        ("clp", {"noise": False}),
    ],
)
def test_the_fast_engine_runs_each_controller_and_rig_as_alone(name: str, kw: dict) -> None:
    x0 = np.array([0.14, -0.13, 0.25, 0.0, 0.3])
    theta0 = np.array([-0.2, 0.29, -0.7, 0.0, 0.6])
    _same_as_single_runs(name, x0, theta0, np.arange(5), 3.0, **kw)


def test_the_fast_engine_runs_a_spreads_rigs_each_as_alone() -> None:
    base = Parameters().with_overrides({"start.free_run_s": 0.02})
    spread = load_spread("docs/examples/spread.toml", base)
    params, _ = sample_parameters(base, spread, 8, seed=5)
    rng = np.random.default_rng(2)
    x0, theta0 = rng.uniform(-0.3, 0.3, 8), rng.uniform(-0.6, 0.6, 8)
    _same_as_single_runs("appendix-clp", x0, theta0, np.arange(8), 3.0, params=params)
