"""The compiled screening kernel (twin.screen.plant) on a beam hinged off its track's centre (``beam.track_offset_m``,
``beam.cog_along_m``: Open Ball & Beam, BB01): the kernel must be ``ReferencePlant`` (its
``_hinged_off_centre_derivative`` and ``_driven_boundary``) run alone, bit for bit.

Bit for bit, not to an ulp: the kernel compiles the reference plant's own functions (``twin.reference``,
``twin.drive_equations``) and calls them in the same order on IEEE doubles, numba without fastmath (no
reassociation, no fused multiply-add), and its sin, cos, arccos and hypot are the C library's that CPython's
``math`` and numpy call. So each step's arithmetic is the same sequence of correctly ordered operations."""

from __future__ import annotations

import math

import numpy as np
import pytest

import twin.parts  # noqa: F401  (registers the parts)
from twin.parameters import Parameters
from twin.parts.description import preset
from twin.parts.servo import servo_drive
from twin.reference import ReferencePlant, drive_law, hinged_beam_terms
from twin.screen import advance_plant, plant_rows
from twin.screen.plant import ReferenceBatchPhysics, derivatives, kernel_refusal

# The thesis's pivot and geared motor, its beam hinged 0.1 m behind its track's centre, its centre of gravity 0.05 m
# out from the pivot; J_BP raised past M_B·(h² + x_g²) (the parallel-axis bound Beam refuses below).
THESIS_HINGED = {"beam.track_offset_m": 0.1, "beam.cog_along_m": 0.05, "beam.inertia_pivot_kgm2": 0.006}


def _obb() -> Parameters:
    return preset("open-ball-and-beam")


def _thesis_hinged() -> Parameters:
    return Parameters().with_overrides(THESIS_HINGED, origin="test")


def _compare(params: list[Parameters], start: np.ndarray, ctrl: np.ndarray) -> set[str]:
    """The kernel over every run at once (in two calls, as a loop of ticks, recording x and θ) against each run
    alone on ``ReferencePlant``: every recorded x and θ, the final state and the step the ball was lost, all bit
    for bit; the cases seen ("kept", "lost", "drive stop": the horn's travel; "beam stop": the beam's own)."""
    n, m = ctrl.shape
    states, lost = start.copy(), np.full(n, -1, dtype=np.int64)
    plant = plant_rows(params)
    half = m // 2
    first = advance_plant(plant, states, lost, ctrl[:, :half], record=True)
    second = advance_plant(plant, states, lost, ctrl[:, half:], step0=half, record=True)
    assert first is not None and second is not None
    xs = np.hstack([first[0], second[0][:, 1:]])
    thetas = np.hstack([first[1], second[1][:, 1:]])
    kinds = set()
    for i, p in enumerate(params):
        ref = ReferencePlant(p)
        ref.reset(*start[i])
        block = ref.advance(ctrl[i])
        assert np.array_equal(states[i], ref.state()), i
        assert np.array_equal(xs[i], block.x_m) and np.array_equal(thetas[i], block.theta_rad), i
        want = -1 if ref.ball_lost_time_s is None else round(ref.ball_lost_time_s / p.physics.timestep_s)
        assert lost[i] == want, i
        kinds.add("lost" if want >= 0 else "kept")
        law = drive_law(p)
        assert law is not None
        lo, hi = law.theta_limits_rad or (-math.inf, math.inf)
        if np.any((block.theta_rad <= lo) | (block.theta_rad >= hi)):
            kinds.add("drive stop")
        if np.any(np.abs(block.theta_rad) >= p.beam.stop_angle_rad):
            kinds.add("beam stop")
    return kinds


@pytest.mark.quick
def test_the_hinged_beams_terms_are_the_pivots_distance_and_the_beams_weight() -> None:
    """By hand: the ball 0.03 m past the track's centre, the centre 0.1 m out from the pivot, is 0.13 m from it;
    a 0.2 kg beam with its centre of gravity 0.05 m out loads the drive with 0.2·9.81·0.05 = 0.0981 N·m at
    level, 0.0981·cos 0.1 at θ = 0.1."""
    along, torque = hinged_beam_terms(0.03, math.cos(0.1), 0.5, 0.1, 0.2 * 9.81 * 0.05)
    assert along == pytest.approx(0.13, abs=1e-15)
    assert torque == pytest.approx(0.5 - 0.0981 * 0.9950041652780258, abs=1e-15)


@pytest.mark.quick
def test_the_kernel_holds_a_hinged_beam_level_with_the_static_torque_and_drops_it_without() -> None:
    """The thesis's motor at the pivot of a beam hinged 0.1 m off centre, at rest at θ = 0 with the ball at
    x = 0.03 m (0.13 m from the pivot). By hand (moments about the pivot): the drive holds it with
    τ* = m·g·(x + d) + M_B·g·x_g, so V* = τ*/k_τ gives ẍ = θ̈ = 0. At 0 V the beam starts to fall with
    θ̈ = −(1 + k₁)·τ*/((1 + k₁)·J + (k₂ + c)·k₁·m·h*) (eq 3.1.26/27 at rest, θ = 0: ẍ = (k₂ + c)·θ̈/(1 + k₁)
    into k₁·m·h*·ẍ + J·θ̈ = −τ*), where
    J = J_BP + J_m·N² − k₂·m·h* + m·(x + d)² is the beam's inertia about the pivot with the ball's and the
    reflected rotor's."""
    p = _thesis_hinged()
    assert kernel_refusal(p) is None
    m, r, g = p.ball.mass_kg, p.ball.radius_m, p.physics.gravity_m_s2
    rs, hs = p.rolling_radius_m, p.rolling_axis_height_m
    x, d, x_g = 0.03, 0.1, 0.05
    tau = m * g * (x + d) + p.beam.mass_kg * g * x_g
    k_tau = p.motor.torque_per_volt_nm_per_v
    k1, k2, c = 2 * r**2 / (5 * rs**2), 2 * r**2 / (5 * rs), p.ball_centre_height_m
    inertia = (
        p.beam.inertia_pivot_kgm2
        + p.motor.rotor_inertia_kgm2 * p.motor.gear_ratio**2
        - k2 * m * hs
        + m * (x + d) ** 2
    )
    thdd = -(1 + k1) * tau / ((1 + k1) * inertia + (k2 + c) * k1 * m * hs)
    states = np.array([[x, 0.0, 0.0, 0.0], [x, 0.0, 0.0, 0.0]])
    got = derivatives(plant_rows([p, p]), states, np.array([tau / k_tau, 0.0]))
    assert got[0] == pytest.approx([0.0, 0.0, 0.0, 0.0], abs=1e-12)
    assert got[1, 3] == pytest.approx(thdd, rel=1e-12)
    assert got[1, 2] == pytest.approx((k2 + c) * thdd / (1 + k1), rel=1e-12)


@pytest.mark.quick
@pytest.mark.parametrize("rig", ["open-ball-and-beam", "thesis-motor-hinged"])
def test_the_kernels_hinged_derivative_is_the_reference_models_bit_for_bit(rig: str) -> None:
    """At random states and ctrls (servo targets or motor volts past the rails), a quarter of the lever's at its
    horn's stops and pushed into them (``drive_stop_derivative`` with the pivot's distance)."""
    n = 200
    p = _obb() if rig == "open-ball-and-beam" else _thesis_hinged()
    law = drive_law(p)
    assert law is not None
    lo, hi = law.theta_limits_rad or (-p.beam.stop_angle_rad, p.beam.stop_angle_rad)
    rng = np.random.default_rng(11)
    half = p.track.half_length_m
    states = np.column_stack(
        [rng.uniform(-half, half, n), rng.uniform(lo, hi, n), rng.uniform(-1, 1, n), rng.uniform(-3, 3, n)]
    )
    states[:50:2, 1], states[1:50:2, 1] = lo, hi
    states[:20, 3] = rng.uniform(-0.01, 0.01, 20)  # inside the dry friction's regularisation
    ctrl = rng.uniform(-1.6, 1.6, n) if rig == "open-ball-and-beam" else rng.uniform(-14, 14, n)
    got = derivatives(plant_rows([p] * n), states, ctrl)
    ref = ReferencePlant(p)
    want = np.array(
        [
            ref.derivative(x, th, xd, thd, u)
            for (x, th, xd, thd), u in zip(states.tolist(), ctrl.tolist(), strict=True)
        ]
    )
    assert np.array_equal(got, want)
    if rig == "open-ball-and-beam":
        assert np.any(want[:, 1] == 0.0)  # the horn's stop held the beam


def _obb_runs(n: int, seed: int) -> tuple[list[Parameters], np.ndarray, np.ndarray]:
    """n Open Ball & Beam runs of 1.5 s: pulses wandering about the 1500 µs centre through the servo's dead band,
    the first four driven to 1000 µs or 2000 µs (past the horn's travel, 1040…1960 µs: into its stops)."""
    p = _obb()
    law = drive_law(p)
    assert law is not None and law.theta_limits_rad is not None
    lo, hi = law.theta_limits_rad
    rng = np.random.default_rng(seed)
    start = np.column_stack(
        [rng.uniform(-0.09, 0.09, n), rng.uniform(lo, hi, n), rng.uniform(-0.1, 0.1, n), np.zeros(n)]
    )
    ticks, steps = 75, round(0.02 / p.physics.timestep_s)  # the preset's 20 ms loop
    pulses = np.clip(1500.0 + np.cumsum(rng.uniform(-40.0, 40.0, (n, ticks)), axis=1), 1000.0, 2000.0)
    pulses[:4, 10:] = np.where(np.arange(4)[:, None] % 2, 1000.0, 2000.0)
    ctrl = np.array([[drive(u) for u in row] for drive, row in ((servo_drive(p), r) for r in pulses)])
    return [p] * n, start, np.repeat(ctrl, steps, axis=1)


@pytest.mark.quick
def test_the_kernel_steps_open_ball_and_beam_as_the_reference_plant_bit_for_bit() -> None:
    """The preset over 12 starts: balls kept and lost off the track's ends, the horn into its stops."""
    params, start, ctrl = _obb_runs(12, seed=12)
    assert _compare(params, start, ctrl) >= {"kept", "lost", "drive stop"}


@pytest.mark.quick
def test_the_kernel_steps_a_thesis_motor_beam_hinged_off_centre_as_the_reference_plant_bit_for_bit() -> None:
    """The thesis's motor on a beam hinged 0.1 m off centre, 1 s of volts past the rails from 10 starts: the beam
    into its stops, balls kept and lost."""
    p = _thesis_hinged()
    n = 10
    rng = np.random.default_rng(13)
    start = np.column_stack(
        [rng.uniform(-0.25, 0.25, n), rng.uniform(-0.3, 0.3, n), np.zeros(n), np.zeros(n)]
    )
    volts = np.repeat(rng.uniform(-14.0, 14.0, (n, 50)), 20, axis=1)
    volts[0], volts[1] = 14.0, -14.0  # driven into the stops
    volts[2] = 0.0
    assert _compare([p] * n, start, volts) >= {"kept", "lost", "beam stop"}


@pytest.mark.quick
def test_the_thesis_rows_beside_hinged_rows_are_bit_for_bit_a_thesis_batch() -> None:
    """The thesis's rows interleaved with hinged rows (both kinds) give the bits of a batch of thesis runs alone:
    the hinge is a hinged row's branch only."""
    rng = np.random.default_rng(14)
    n, m = 6, 400
    thesis = [Parameters()] * n
    hinged = [_obb(), _thesis_hinged()] * (n // 2)
    mixed = [p for pair in zip(thesis, hinged, strict=True) for p in pair]
    start = np.column_stack(
        [rng.uniform(-0.08, 0.08, 2 * n), rng.uniform(-0.05, 0.05, 2 * n), np.zeros(2 * n), np.zeros(2 * n)]
    )
    volts = np.repeat(rng.uniform(-3.0, 3.0, (2 * n, m // 20)), 20, axis=1)
    # the servo's targets (rad)
    volts[1::4] = np.repeat(rng.uniform(-0.5, 0.5, (n // 2, m // 20)), 20, axis=1)
    states, lost = start.copy(), np.full(2 * n, -1, dtype=np.int64)
    advance_plant(plant_rows(mixed), states, lost, volts)
    alone, alone_lost = start[::2].copy(), np.full(n, -1, dtype=np.int64)
    advance_plant(plant_rows(thesis), alone, alone_lost, volts[::2])
    assert np.array_equal(states[::2], alone) and np.array_equal(lost[::2], alone_lost)


@pytest.mark.quick
def test_the_batch_physics_runs_open_ball_and_beam_as_the_reference_plant() -> None:
    """``ReferenceBatchPhysics`` (the fast engine's plant) on the preset: checked starts, the kernel's blocks the
    reference plant's, the lost time its clock's."""
    p = _obb()
    x0, th0 = np.array([0.0, 0.1, -0.1]), np.array([0.0, 0.05, -0.1])
    physics = ReferenceBatchPhysics([p] * 3, x0, th0, 1)
    ctrl = np.repeat(np.array([[0.0], [0.3], [-0.3]]), 300, axis=1)
    block = physics.advance(np.arange(3), ctrl)
    for i in range(3):
        ref = ReferencePlant(p)
        ref.reset(float(x0[i]), float(th0[i]))
        want = ref.advance(ctrl[i])
        assert np.array_equal(block.x_m[i], want.x_m) and np.array_equal(block.theta_rad[i], want.theta_rad)
        assert np.array_equal(block.on_track[i], want.on_track)
    with pytest.raises(ValueError, match="beyond"):
        ReferenceBatchPhysics([p], np.array([0.0]), np.array([0.2]), 1)  # past the horn's reach
