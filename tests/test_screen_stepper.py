"""The compiled screening kernel (twin.screen.plant) on the stepper rig (``arduino-stepper-ultrasonic``: a STEP/DIR
stepper at the pivot): the kernel must be ``ReferencePlant`` run alone, bit for bit, its law (the sine, detent and
damping torque at the shaft) and its sketch's speed ramp (per-run state s, v) included; the fast engine no longer
refuses the rig, and its screened map has brute force's classes.

The law's and the ramp's arithmetic lives in ``twin.drive_equations`` (the part, the reference model and the
kernel call it); the values checked by hand here come from the 17HS4401's data (twin.parts.stepper: 0.40 N·m
holding, 0.022 N·m detent, 1.5 Ω, 2.8 mH, 1.7 A at 12 V, 200 full steps, 16 microsteps) and AccelStepper's ramp
(2000 microsteps/s, 20000 microsteps/s²) at the rig's 1 ms step."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import twin.parts  # noqa: F401  (registers the parts)
from twin.drive_equations import (
    stepper_magnet_torque_nm,
    stepper_pullout_nm,
    stepper_ramp_acceleration,
    stepper_ramp_step,
    stepper_shaft_torque_nm,
    stepper_sketch_steps,
)
from twin.parameters import Parameters
from twin.parts.description import preset
from twin.parts.stepper import Stepper, stepper_kernel_numbers
from twin.reference import ReferencePlant, drive_law
from twin.screen import advance_plant, plant_rows
from twin.screen.plant import KERNEL_PARTS, ReferenceBatchPhysics, derivatives, kernel_refusal

PRESET = "arduino-stepper-ultrasonic"
MICROSTEP_RAD = 2.0 * math.pi / 3200.0  # 1.8° / 16
POLE_PAIRS = 50  # 200 full steps / 4


def _rig() -> Parameters:
    return preset(PRESET)


@pytest.mark.quick
def test_the_stepper_law_and_ramp_by_hand() -> None:
    """One full step (16 microsteps) of lag at rest pulls with the holding torque, T_hold·sin(p·16·μ) = T_hold·sin(π/2);
    a quarter full step off a detent the detent torque is T_det·sin(4p·4μ) = T_det·sin(π/2); at 100 rad/s the pull
    falls to T_hold·(V/I)/√(R² + (p·ω·L)²) and the damping takes b·ω. The ramp from rest toward 400 microsteps:
    its first step accelerates at a (v = a·h = 20/s, s = h·v = 0.02)."""
    p = _rig()
    level, microstep, hold, pairs, detent, r_ohm, l_h, z_ohm, damping = stepper_kernel_numbers(p)
    assert (microstep, hold, pairs, detent) == (pytest.approx(MICROSTEP_RAD), 0.40, POLE_PAIRS, 0.022)
    numbers = (level, microstep, hold, pairs, detent, r_ohm, l_h, z_ohm, damping)
    law = (stepper_magnet_torque_nm, stepper_pullout_nm)
    # the beam level, the target one full step ahead: the holding torque, no detent, no damping
    assert stepper_shaft_torque_nm(*law, 16.0, level, 0.0, *numbers) == pytest.approx(0.40, abs=1e-15)
    # a quarter full step ahead of the detent, commanded there: the detent's pull back alone
    quarter = level + 4 * MICROSTEP_RAD
    assert stepper_shaft_torque_nm(*law, 4.0, quarter, 0.0, *numbers) == pytest.approx(-0.022, abs=1e-15)
    # at 100 rad/s, past the 49.3 rad/s corner: 0.40·(12/1.7)/√(1.5² + (50·100·2.8e-3)²) less 1e-3·100
    pull = 0.40 * (12.0 / 1.7) / math.sqrt(1.5**2 + (50 * 100.0 * 2.8e-3) ** 2)
    assert pull == pytest.approx(0.2005, abs=1e-4)
    assert stepper_shaft_torque_nm(*law, 16.0, level, 100.0, *numbers) == pytest.approx(pull - 0.1, abs=1e-14)
    # the ramp: from rest toward 400 it heads for v_max at a, a·h = 20 microsteps/s after one 1 ms step
    s = p.of(Stepper)
    ramp = (s.max_speed_steps_s, s.acceleration_steps_s2, p.physics.timestep_s)
    assert stepper_ramp_acceleration(400.0, 0.0, 0.0, *ramp) == 20000.0
    position, speed = stepper_ramp_step(stepper_ramp_acceleration, 400.0, 0.0, 0.0, *ramp)
    assert (position, speed) == (pytest.approx(0.02, abs=1e-15), pytest.approx(20.0, abs=1e-12))
    # one microstep from the target it lands in one step (a speed of D/h), and the sketch's count rounds
    assert stepper_ramp_step(stepper_ramp_acceleration, 400.0, 399.99, 10.0, *ramp)[0] == pytest.approx(400.0)
    assert (stepper_sketch_steps(2.49), stepper_sketch_steps(2.5), stepper_sketch_steps(-2.51)) == (
        2.0,
        3.0,
        -3.0,
    )
    assert drive_law(p).ramp == (2000.0, 20000.0)  # type: ignore[union-attr]


@pytest.mark.quick
def test_the_fast_engine_no_longer_refuses_the_stepper_rig() -> None:
    from twin.rigs.backends import engine_policy

    rig = _rig()
    assert "stepper" in KERNEL_PARTS["actuator"]
    assert kernel_refusal(rig) is None
    assert engine_policy("screen", params=rig).screened
    assert kernel_refusal(Parameters().with_overrides({"parts.actuator": "stepper"})) is None


@pytest.mark.quick
def test_the_kernels_stepper_derivative_is_the_reference_models_bit_for_bit() -> None:
    """(ẋ, θ̇, ẍ, θ̈) at random states and commanded positions (the law's control), into the stops and out."""
    p = _rig()
    rng = np.random.default_rng(21)
    n = 200
    states = np.column_stack(
        [
            rng.uniform(-0.19, 0.19, n),
            rng.uniform(-0.4, 0.4, n),
            rng.uniform(-0.5, 0.5, n),
            rng.uniform(-5.0, 5.0, n),
        ]
    )
    ctrl = np.round(rng.uniform(-500.0, 500.0, n))
    got = derivatives(plant_rows([p] * n), states, ctrl)
    ref = ReferencePlant(p)
    want = np.array(
        [
            ref.derivative(x, th, xd, thd, c)
            for (x, th, xd, thd), c in zip(states.tolist(), ctrl.tolist(), strict=True)
        ]
    )
    assert np.array_equal(got, want)


def _compare(p: Parameters, start: np.ndarray, targets: np.ndarray) -> set[str]:
    """The kernel over every run at once (in two calls, the ramps carried between them, at 0.15 s and after,
    recording x and θ) against each run alone on ``ReferencePlant`` (in two advances): every recorded x and θ, the
    final state, the ramp's (s, v) and the step the ball was lost, bit for bit; the cases seen ("kept", "lost",
    "beam stop", "full speed": the ramp at v_max, "slipped": the rotor over half an electrical cycle from the
    sketch's commanded angle at the end, the steps it missed)."""
    n, m = targets.shape
    states, lost, ramps = start.copy(), np.full(n, -1, dtype=np.int64), np.zeros((n, 2))
    plant = plant_rows([p] * n)
    half = 150  # 0.15 s: a ramp from rest toward 400 microsteps cruises at v_max from 0.1 s to 0.2 s
    first = advance_plant(plant, states, lost, targets[:, :half], record=True, ramps=ramps)
    middle = ramps.copy()
    second = advance_plant(plant, states, lost, targets[:, half:], step0=half, record=True, ramps=ramps)
    assert first is not None and second is not None
    xs = np.hstack([first[0], second[0][:, 1:]])
    thetas = np.hstack([first[1], second[1][:, 1:]])
    level = stepper_kernel_numbers(p)[0]
    kinds = set()
    for i in range(n):
        ref = ReferencePlant(p)
        ref.reset(*start[i].tolist())
        a = ref.advance(targets[i, :half])
        assert np.array_equal(middle[i], ref._ramp_state), i  # the ramp carried across the calls
        b = ref.advance(targets[i, half:])
        assert np.array_equal(states[i], ref.state()), i
        assert np.array_equal(ramps[i], ref._ramp_state), i
        assert np.array_equal(xs[i], np.concatenate([a.x_m, b.x_m[1:]])), i
        assert np.array_equal(thetas[i], np.concatenate([a.theta_rad, b.theta_rad[1:]])), i
        want = -1 if ref.ball_lost_time_s is None else round(ref.ball_lost_time_s / p.physics.timestep_s)
        assert lost[i] == want, i
        kinds.add("lost" if want >= 0 else "kept")
        if np.any(np.abs(thetas[i]) >= p.beam.stop_angle_rad):
            kinds.add("beam stop")
        if max(abs(middle[i, 1]), abs(ramps[i, 1])) == pytest.approx(2000.0, abs=1e-9):
            kinds.add("full speed")
        commanded = level + MICROSTEP_RAD * stepper_sketch_steps(float(ramps[i, 0]))
        if abs(states[i, 1] - commanded) > math.pi / POLE_PAIRS:
            kinds.add("slipped")
    return kinds


@pytest.mark.quick
def test_the_kernel_steps_the_stepper_preset_as_the_reference_plant_bit_for_bit() -> None:
    """1.2 s from 10 starts: the rest target (the beam held level), targets jumping ±400 microsteps (the ramp at
    full speed, the beam into its stops, the rotor slipping cycles against them), and a random walk of the
    sketch's whole targets each 20 ms tick."""
    p = _rig()
    n, ticks, steps = 10, 60, round(0.02 / p.physics.timestep_s)
    rng = np.random.default_rng(22)
    start = np.column_stack(
        [rng.uniform(-0.15, 0.15, n), rng.uniform(-0.1, 0.1, n), np.zeros(n), np.zeros(n)]
    )
    start[0] = 0.0
    per_tick = np.round(np.cumsum(rng.uniform(-60.0, 60.0, (n, ticks)), axis=1))
    per_tick[0], per_tick[1], per_tick[2] = 0.0, 400.0, -400.0
    per_tick[3, 10:] = np.where(np.arange(ticks - 10) % 20 < 10, 300.0, -300.0)  # hard reversals
    kinds = _compare(p, start, np.repeat(per_tick, steps, axis=1))
    assert kinds >= {"kept", "lost", "beam stop", "full speed", "slipped"}


@pytest.mark.quick
def test_the_thesis_rows_beside_stepper_rows_are_bit_for_bit_a_thesis_batch() -> None:
    """The thesis's rows interleaved with stepper rows give the bits of a batch of thesis runs alone (the ramp is
    a stepper row's branch only, its state untouched on the thesis's rows)."""
    rng = np.random.default_rng(23)
    n, m = 4, 400
    thesis = [Parameters()] * n
    mixed = [q for pair in zip(thesis, [_rig()] * n, strict=True) for q in pair]
    start = np.column_stack(
        [rng.uniform(-0.08, 0.08, 2 * n), rng.uniform(-0.05, 0.05, 2 * n), np.zeros(2 * n), np.zeros(2 * n)]
    )
    volts = np.repeat(rng.uniform(-3.0, 3.0, (2 * n, m // 20)), 20, axis=1)
    volts[1::2] = np.repeat(np.round(rng.uniform(-200.0, 200.0, (n, m // 20))), 20, axis=1)  # microsteps
    states, lost, ramps = start.copy(), np.full(2 * n, -1, dtype=np.int64), np.zeros((2 * n, 2))
    advance_plant(plant_rows(mixed), states, lost, volts, ramps=ramps)
    alone, alone_lost = start[::2].copy(), np.full(n, -1, dtype=np.int64)
    advance_plant(plant_rows(thesis), alone, alone_lost, volts[::2])
    assert np.array_equal(states[::2], alone) and np.array_equal(lost[::2], alone_lost)
    assert np.all(ramps[::2] == 0.0) and np.all(ramps[1::2, 0] != 0.0)


@pytest.mark.quick
def test_the_batch_physics_carries_each_runs_ramp_across_its_blocks() -> None:
    """``ReferenceBatchPhysics`` (the fast engine's plant) on the preset, advanced in three blocks, one of them
    for a subset of runs: each run is ``ReferencePlant`` advanced over the same blocks, bit for bit."""
    p = _rig()
    x0, th0 = np.array([0.0, 0.1, -0.1]), np.array([0.0, 0.05, -0.05])
    physics = ReferenceBatchPhysics([p] * 3, x0, th0, 1)
    blocks = [
        (np.arange(3), np.repeat(np.array([[0.0], [150.0], [-150.0]]), 200, axis=1)),
        (np.array([0, 2]), np.repeat(np.array([[60.0], [-20.0]]), 200, axis=1)),
        (np.arange(3), np.repeat(np.array([[-60.0], [0.0], [20.0]]), 200, axis=1)),
    ]
    refs = [ReferencePlant(p) for _ in range(3)]
    for i, ref in enumerate(refs):
        ref.reset(float(x0[i]), float(th0[i]))
    for runs, ctrl in blocks:
        block = physics.advance(runs, ctrl)
        for j, i in enumerate(runs.tolist()):
            want = refs[i].advance(ctrl[j])
            assert np.array_equal(block.x_m[j], want.x_m) and np.array_equal(
                block.theta_rad[j], want.theta_rad
            )
            assert np.array_equal(block.on_track[j], want.on_track)
    for i, ref in enumerate(refs):
        assert np.array_equal(physics.ramps[i], ref._ramp_state)
    assert physics.ramps[1, 0] != physics.ramps[0, 0]  # run 1 sat the middle block out


@pytest.mark.slow
def test_the_stepper_presets_screened_map_is_the_brute_force_map() -> None:
    """rig-lqg on the stepper preset, a 7 × 7 map (x₀ ±0.1 m, θ₀ ±0.05 rad), 3 s runs: screened (the fast engine,
    MuJoCo near every class change and on an audit sample) and brute force (MuJoCo every start), each start's
    class brute force's and every start MuJoCo ran brute force's record."""
    from twin.app.sweep import Grid, SweepSettings, run_sweep, verdict_class

    rig = _rig()
    base = SweepSettings("rig-lqg", Grid(-0.1, 0.1, 7), Grid(-0.05, 0.05, 7), duration_s=3.0)
    brute = run_sweep(base, rig, nthread=2)
    classes = [verdict_class(q) for q in brute.points]
    assert len(set(classes)) > 1  # a map with a boundary: the screen has something to confirm
    screened = run_sweep(replace(base, engine="screen", screen_audit=8), rig, nthread=2)
    assert screened.complete and screened.screening is not None
    assert [verdict_class(q) for q in screened.points] == classes
    assert screened.screening["audit"]["mismatches"] == []
    for s, b in zip(screened.points, brute.points, strict=True):
        if s["engine"] == "mujoco":
            assert s == b
