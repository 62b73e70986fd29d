"""The compiled screening kernel (twin.screen.plant) on a beam driven otherwise than the thesis's: the end lever
(exact four-bar closure) or the pivot, turned by a hobby servo or the thesis's geared motor. Each run has its own
servo and linkage; the kernel must be ``ReferencePlant`` (its ``DriveLaw``) run alone, the thesis's rows in the
same batch bit for bit a thesis-only batch, and a part the kernel has no form for is refused by its field."""

from __future__ import annotations

import math

import numpy as np
import pytest

import twin.parts  # noqa: F401  (registers the parts)
from twin.parameters import Parameters
from twin.parts.linkage import Linkage, lever_shaft_angles
from twin.parts.servo import servo_drive
from twin.reference import ReferencePlant, drive_law
from twin.screen import advance_plant, plant_rows
from twin.screen.plant import KERNEL_PARTS, ReferenceBatchPhysics, derivatives, kernel_refusal

LEVER_SERVO = {"parts.beam_drive": "end_lever", "parts.actuator": "hobby_servo"}
PIVOT_SERVO = {"parts.beam_drive": "pivot", "parts.actuator": "hobby_servo"}
LEVER_MOTOR = {"parts.beam_drive": "end_lever", "parts.actuator": "escap_dc_motor"}
# Every other lever run mounts the servo beyond the attachment, its horn reaching back toward the pivot (dθ/dφ < 0):
# the closure's other sense (twin.parts.linkage's batch form uses the same mount).
FAR_SIDE = {"linkage.shaft_x_m": 0.175, "linkage.horn_neutral_rad": math.pi}


def _rigs(rig: dict[str, str], n: int, seed: int) -> list[Parameters]:
    """n rigs of the kind ``rig``, each with its own servo (stall torque, speed, supply, proportional band,
    armature, dead band: ±10 %) and, on a lever, its own linkage (±2 % of the base's five lengths, which keeps the
    closure clear of its dead points over the horn's ±60°; every other run the far-side mount)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        values: dict[str, object] = dict(rig)
        values.update(
            {
                "servo.stall_torque_nm": 0.1765 * rng.uniform(0.9, 1.1),
                "servo.no_load_speed_rad_s": 10.47 * rng.uniform(0.9, 1.1),
                "servo.supply_v": 5.0 * rng.uniform(0.9, 1.1),
                "servo.saturation_error_rad": math.radians(5.0) * rng.uniform(0.9, 1.1),
                "servo.armature_kgm2": 1.5e-4 * rng.uniform(0.9, 1.1),
                "servo.deadband_us": 10.0 * rng.uniform(0.9, 1.1),
                # B_m, reflected as B_m·N² in the lever's law of the geared motor
                "motor.viscous_damping_nm_s_per_rad": 1e-6 * rng.uniform(0.5, 1.5),
            }
        )
        if rig["parts.beam_drive"] == "end_lever":
            base = Linkage(**{k.partition(".")[2]: v for k, v in FAR_SIDE.items()}) if i % 2 else Linkage()
            for name in ("beam_arm_m", "rod_m", "crank_m", "shaft_x_m", "shaft_z_m"):
                values[f"linkage.{name}"] = getattr(base, name) * rng.uniform(0.98, 1.02)
            values["linkage.horn_neutral_rad"] = base.horn_neutral_rad
        out.append(Parameters().with_overrides(values, origin="test"))
    return out


def _pulses(rng: np.random.Generator, n: int, ticks: int, spread_us: float) -> np.ndarray:
    """Each run's servo pulses, one per 20 ms tick: a random walk about the 1.5 ms centre (steps within ±spread),
    some steps inside the servo's 10 µs dead band."""
    steps = rng.uniform(-spread_us, spread_us, (n, ticks))
    steps[:, ::3] *= 0.02  # every third step within the dead band: the target must not move
    return np.clip(1500.0 + np.cumsum(steps, axis=1), 900.0, 2100.0)


def _targets(params: list[Parameters], pulses: np.ndarray, steps_per_tick: int) -> np.ndarray:
    """The servo's ctrl (its target angle) of each run's pulses through its own dead band (``servo_drive``),
    held over each tick's physics steps."""
    ctrl = np.array(
        [
            [drive(u) for u in row]
            for drive, row in ((servo_drive(p), r) for p, r in zip(params, pulses, strict=True))
        ]
    )
    return np.repeat(ctrl, steps_per_tick, axis=1)


def _compare(params: list[Parameters], start: np.ndarray, ctrl: np.ndarray) -> set[str]:
    """The kernel over every run at once (in two calls, as a loop of ticks) against each run alone on
    ``ReferencePlant``: every state to 1e-12 and the step the ball was lost; the cases seen."""
    n, m = ctrl.shape
    states, lost = start.copy(), np.full(n, -1, dtype=np.int64)
    plant = plant_rows(params)
    half = m // 2
    advance_plant(plant, states, lost, ctrl[:, :half])
    advance_plant(plant, states, lost, ctrl[:, half:], step0=half)
    kinds = set()
    for i, p in enumerate(params):
        ref = ReferencePlant(p)
        ref.reset(*start[i])
        block = ref.advance(ctrl[i])
        assert np.max(np.abs(states[i] - ref.state())) <= 1e-12, i
        want = -1 if ref.ball_lost_time_s is None else round(ref.ball_lost_time_s / p.physics.timestep_s)
        assert lost[i] == want, i
        kinds.add("lost" if want >= 0 else "kept")
        law = drive_law(p)
        assert law is not None
        lo, hi = law.theta_limits_rad or (-math.inf, math.inf)
        if np.any((block.theta_rad <= lo) | (block.theta_rad >= hi)):
            kinds.add("drive stop")
    return kinds


@pytest.mark.quick
def test_the_lever_shafts_second_derivative_is_the_closures() -> None:
    """φ(θ) solved here from the closure by bisection (|A(θ) − C(φ)| = r, independent of the code), its second
    difference against the closed form φ″; and at level, by hand: horn horizontal, rod vertical, so φ′ = L/c and
    φ″ = 0 (both rod ends move vertically at the same speed, to first and second order by symmetry)."""
    for link in (Linkage(), Linkage(shaft_x_m=0.175, horn_neutral_rad=math.pi)):
        numbers = (link.beam_arm_m, link.rod_m, link.crank_m, link.shaft_x_m, link.shaft_z_m)
        sense = 1.0 if link.horn_neutral_rad == 0.0 else -1.0

        def closure(theta: float, phi: float, g: tuple[float, ...] = numbers) -> float:
            arm, rod, crank, sx, sz = g
            ax, az = arm * math.cos(theta), arm * math.sin(theta)
            cx, cz = sx + crank * math.cos(phi), sz + crank * math.sin(phi)
            return math.hypot(ax - cx, az - cz) - rod

        def phi_of(theta: float, neutral: float = link.horn_neutral_rad) -> float:
            # the rod's length changes monotonically over the horn's travel (no dead point): bisect within it
            a, b = neutral - math.pi / 3, neutral + math.pi / 3
            fa = closure(theta, a)
            for _ in range(200):
                mid = 0.5 * (a + b)
                if (closure(theta, mid) > 0.0) == (fa > 0.0):
                    a, fa = mid, closure(theta, mid)
                else:
                    b = mid
            return 0.5 * (a + b)

        for theta in (-0.1, -0.03, 0.0, 0.05, 0.12):
            phi, dphi, ddphi = (
                float(v) for v in lever_shaft_angles(theta, *numbers, sense, link.horn_neutral_rad)
            )
            h = 1e-4
            p0, pp, pm = phi_of(theta), phi_of(theta + h), phi_of(theta - h)
            assert phi == pytest.approx(p0 - link.horn_neutral_rad, abs=1e-12)
            assert dphi == pytest.approx((pp - pm) / (2 * h), rel=1e-5)
            assert ddphi == pytest.approx((pp - 2 * p0 + pm) / h**2, rel=1e-4, abs=1e-4)
    link = Linkage()
    _, dphi, ddphi = lever_shaft_angles(
        0.0, link.beam_arm_m, link.rod_m, link.crank_m, link.shaft_x_m, link.shaft_z_m, 1.0, 0.0
    )
    assert float(dphi) == pytest.approx(link.beam_arm_m / link.crank_m, rel=1e-12)
    assert float(ddphi) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.quick
@pytest.mark.parametrize("rig", [LEVER_SERVO, PIVOT_SERVO, LEVER_MOTOR])
def test_the_kernels_driven_derivative_is_the_reference_models(rig: dict[str, str]) -> None:
    """At random states and ctrls (servo targets or motor volts past the rails), some at the drive's stops and
    pushed into them, each run its own rig."""
    n = 200
    params = _rigs(rig, n, seed=1)
    rng = np.random.default_rng(2)
    states = np.column_stack(
        [rng.uniform(-0.3, 0.3, n), rng.uniform(-0.16, 0.16, n), rng.uniform(-1, 1, n), rng.uniform(-3, 3, n)]
    )
    states[:20, 3] = rng.uniform(-0.01, 0.01, 20)  # inside the dry friction's regularisation
    motor = rig["parts.actuator"] == "escap_dc_motor"
    ctrl = rng.uniform(-14, 14, n) if motor else rng.uniform(-1.6, 1.6, n)
    if rig["parts.beam_drive"] == "end_lever":  # within the horn's travel, some at its stops
        for i in range(n):
            law = drive_law(params[i])
            assert law is not None and law.theta_limits_rad is not None
            lo, hi = law.theta_limits_rad
            states[i, 1] = law.theta_limits_rad[i % 4 // 2] if i < 40 and i % 2 == 0 else rng.uniform(lo, hi)
    got = derivatives(plant_rows(params), states, ctrl)
    want = np.empty_like(got)
    for i, p in enumerate(params):
        ref = ReferencePlant(p)
        law = drive_law(p)
        assert law is not None
        want[i] = ref._driven_derivative(law)(*states[i].tolist(), float(ctrl[i]))
    assert np.max(np.abs(got - want) / np.maximum(1.0, np.abs(want))) <= 1e-12
    assert np.any(want[:, 1] == 0.0) == (rig["parts.beam_drive"] == "end_lever")  # a stop held the beam


@pytest.mark.parametrize(("rig", "spread_us"), [(LEVER_SERVO, 40.0), (PIVOT_SERVO, 15.0)])
def test_the_kernel_steps_a_servo_rig_as_the_reference_plant_for_every_run(
    rig: dict[str, str], spread_us: float
) -> None:
    """1.5 s of pulse sequences from random starts (some balls kept, some lost; the lever's horn into its stops),
    each run its own servo and linkage."""
    n = 16
    params = _rigs(rig, n, seed=3)
    rng = np.random.default_rng(4)
    start = np.column_stack(
        [rng.uniform(-0.2, 0.2, n), rng.uniform(-0.1, 0.1, n), rng.uniform(-0.2, 0.2, n), np.zeros(n)]
    )
    steps = round(0.02 / params[0].physics.timestep_s)
    pulses = _pulses(rng, n, 75, spread_us)
    if rig is LEVER_SERVO:
        pulses[:4, 10:] = np.where(np.arange(4)[:, None] % 2, 900.0, 2100.0)  # the horn driven into its stops
    kinds = _compare(params, start, _targets(params, pulses, steps))
    assert kinds >= ({"lost", "kept", "drive stop"} if rig is LEVER_SERVO else {"lost", "kept"})


@pytest.mark.parametrize("track", ["v_groove", "rod_and_strip", "tube"])
def test_the_kernel_runs_every_track_through_its_rolling_geometry(track: str) -> None:
    """A track enters the equations through its rolling radius and axis height alone (``Parameters.track_geometry``):
    the kernel runs a servo rig on each as ``ReferencePlant`` does, run for run."""
    n = 6
    params = [p.with_overrides({"parts.track": track}) for p in _rigs(PIVOT_SERVO, n, seed=5)]
    assert kernel_refusal(params[0]) is None
    rng = np.random.default_rng(6)
    start = np.column_stack(
        [rng.uniform(-0.1, 0.1, n), rng.uniform(-0.05, 0.05, n), np.zeros(n), np.zeros(n)]
    )
    steps = round(0.02 / params[0].physics.timestep_s)
    kinds = _compare(params, start, _targets(params, _pulses(rng, n, 50, 15.0), steps))
    assert kinds


@pytest.mark.quick
def test_the_kernel_steps_a_lever_turned_by_the_geared_motor_as_the_reference_plant() -> None:
    n = 8
    params = _rigs(LEVER_MOTOR, n, seed=5)
    rng = np.random.default_rng(6)
    start = np.column_stack([rng.uniform(-0.2, 0.2, n), rng.uniform(-0.1, 0.1, n), np.zeros(n), np.zeros(n)])
    volts = np.repeat(rng.uniform(-14.0, 14.0, (n, 50)), 20, axis=1)  # past the rails
    assert _compare(params, start, volts) >= {"lost", "drive stop"}


@pytest.mark.quick
def test_the_thesis_rows_are_bit_for_bit_a_thesis_batch_beside_driven_rows() -> None:
    """The kernel branches on each run's kind: thesis runs interleaved with lever and pivot servo runs give the
    thesis runs' bits of a batch of thesis runs alone, and those are the reference plant's to 1e-12."""
    rng = np.random.default_rng(7)
    n, m = 12, 600
    thesis = [Parameters().with_overrides({"beam.pivot_friction_nm": 1e-3 * (i + 1)}) for i in range(n)]
    driven = _rigs(LEVER_SERVO, n // 2, seed=8) + _rigs(PIVOT_SERVO, n // 2, seed=9)
    mixed = [p for pair in zip(thesis, driven, strict=True) for p in pair]
    start = np.column_stack(
        [rng.uniform(-0.2, 0.2, 2 * n), rng.uniform(-0.1, 0.1, 2 * n), np.zeros(2 * n), np.zeros(2 * n)]
    )
    volts = np.repeat(rng.uniform(-3.0, 3.0, (2 * n, m // 20)), 20, axis=1)
    volts[1::2] = np.repeat(rng.uniform(-0.5, 0.5, (n, m // 20)), 20, axis=1)  # the servos' targets (rad)
    states, lost = start.copy(), np.full(2 * n, -1, dtype=np.int64)
    advance_plant(plant_rows(mixed), states, lost, volts)
    alone, alone_lost = start[::2].copy(), np.full(n, -1, dtype=np.int64)
    advance_plant(plant_rows(thesis), alone, alone_lost, volts[::2])
    assert np.array_equal(states[::2], alone) and np.array_equal(lost[::2], alone_lost)
    for i, p in enumerate(thesis):
        ref = ReferencePlant(p)
        ref.reset(*start[2 * i])
        ref.advance(volts[2 * i])
        assert np.max(np.abs(alone[i] - ref.state())) <= 1e-12


@pytest.mark.quick
def test_the_batch_physics_runs_a_servo_rig_and_refuses_a_part_without_a_kernel_form(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    params = _rigs(LEVER_SERVO, 3, seed=10)
    physics = ReferenceBatchPhysics(params, np.array([0.0, 0.1, -0.1]), np.array([0.0, 0.05, -0.05]), 1)
    block = physics.advance(np.arange(3), np.zeros((3, 20)))
    assert block.theta_rad.shape == (3, 21)
    # a part the kernel has no form for, whichever role: refused naming the field and the part
    assert kernel_refusal(params[0]) is None
    monkeypatch.setitem(KERNEL_PARTS, "actuator", ("escap_dc_motor",))
    refusal = kernel_refusal(params[0])
    assert refusal is not None and refusal.startswith("parts.actuator = 'hobby_servo'")
    with pytest.raises(ValueError, match=r"run 0: parts\.actuator = 'hobby_servo': the fast engine"):
        ReferenceBatchPhysics(params, np.zeros(3), np.zeros(3), 1)


@pytest.mark.quick
def test_the_screening_policy_falls_back_to_mujoco_for_a_rig_the_fast_engine_refuses(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from twin.app.commands.common import resolve_engine
    from twin.parameters import ParameterError
    from twin.rigs.backends import BackendError, engine_policy

    rig = _rigs(LEVER_SERVO, 1, seed=11)[0]
    assert engine_policy("screen", params=rig).screened  # the servo lever is screened
    assert resolve_engine(None, "twin", "screen", params=rig) == "screen"
    monkeypatch.setitem(KERNEL_PARTS, "beam_drive", ("pivot",))  # as a part with no kernel form yet
    with pytest.raises(BackendError, match=r"--engine fast: parts\.beam_drive = 'end_lever'"):
        engine_policy("fast", params=rig)
    alone = engine_policy("screen", params=rig, strict=False)  # a job's settings: MuJoCo decides every run
    assert alone.screen is None and alone.confirm == "twin" and alone.decider_label() == "mujoco"
    assert resolve_engine(None, "twin", "screen", params=rig) == "mujoco"  # the default falls back
    with pytest.raises(ParameterError, match=r"parts\.beam_drive = 'end_lever'.*--engine mujoco"):
        resolve_engine("screen", "twin", "screen", params=rig)  # asked for explicitly: refused, naming it
    assert engine_policy("screen").screened  # without a rig, as before


@pytest.mark.quick
def test_a_beam_hinged_off_its_tracks_centre_is_a_hinged_row() -> None:
    """The reference model's beam hinged elsewhere than under its track (``beam.track_offset_m``) is run, not
    refused, as a hinged row (tests/test_screen_hinged.py holds it to the reference plant)."""
    from twin.screen.plant import HINGED, OFFSET

    rig = Parameters().with_overrides({**LEVER_SERVO, "beam.track_offset_m": 0.05})
    assert kernel_refusal(rig) is None
    row = plant_rows([rig]).rows[0]
    assert row[HINGED] == 1.0 and row[OFFSET] == 0.05


@pytest.mark.quick
def test_the_parts_registered_without_a_kernel_form_are_refused_by_name() -> None:
    """Each registered part of a plant role the kernel has no form for (a stepper, another track): refused naming
    ``parts.<role>`` and the part, and the screening policy runs such a rig on MuJoCo alone."""
    from twin.parameters import ParameterError
    from twin.rigs.backends import engine_policy

    others: list[tuple[str, str]] = []  # the stepper has its kernel form now (tests/test_screen_stepper.py)
    tried = 0
    for role, name in others:
        try:
            rig = Parameters().with_overrides({f"parts.{role}": name})
        except ParameterError:  # not registered in this tree
            continue
        tried += 1
        refusal = kernel_refusal(rig)
        assert refusal is not None and refusal.startswith(f"parts.{role} = {name!r}: the fast engine")
        assert engine_policy("screen", params=rig, strict=False).screen is None
    assert kernel_refusal(Parameters()) is None
    if tried == 0:
        pytest.skip("no part without a kernel form is registered")
