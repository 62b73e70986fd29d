"""The stepper (twin.parts.stepper): its torque law against the 17HS4401's numbers worked by hand, its per-step law
on a MuJoCo joint against an independent integration of the same ODE (scipy), a slip of whole electrical cycles,
microstep resolution against a root-finder, the board's STEP/DIR output, a rig that holds the level beam, the law
fresh each run, and the batch engine's and the state laws' refusals."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from twin.parameters import Parameters
from twin.parts import rig_parts
from twin.parts.arduino import board_output_range, step_target_steps
from twin.parts.stepper import (
    STEPPER,
    Stepper,
    StepperLaw,
    apply_stepper,
    pullout_torque_nm,
    ramp_acceleration,
    rotor_missed_full_steps,
    stepper_torque_nm,
)
from twin.rigs.sim import SimRig

# The 17HS4401's data-sheet row, by hand: 40 N·cm, 2.2 N·cm detent, 54 g·cm², 1.8° (p = 200/4 = 50).
HOLD_NM, DETENT_NM, ROTOR_KGM2, P = 0.40, 0.022, 54e-7, 50
FULL_STEP_RAD = math.radians(1.8)
MICROSTEP_RAD = FULL_STEP_RAD / 16
PARAMS = Parameters().with_overrides({"parts.actuator": "stepper", "parts.io_board": "arduino_uno"})

_LOAD_XML = """
<mujoco>
  <option timestep="{timestep}" integrator="{integrator}" gravity="0 0 0"/>
  <worldbody>
    <body name="load">
      <joint name="beam_hinge" type="hinge" axis="0 1 0"/>
      <geom type="sphere" size="0.01" mass="1e-9"/>
      <inertial pos="0 0 0" mass="1" diaginertia="{load} {load} {load}"/>
    </body>
  </worldbody>
  <actuator><motor name="motor" joint="beam_hinge"/></actuator>
</mujoco>
"""


def _torque(commanded: float, angle: float, speed: float = 0.0) -> float:
    s = Stepper()
    return float(
        stepper_torque_nm(
            commanded, angle, speed, 0.0, s.holding_torque_nm, s.pole_pairs, s.detent_torque_nm,
            s.phase_resistance_ohm, s.phase_inductance_h, s.supply_impedance_ohm,
        )
    )  # fmt: skip


def _load_rig(
    load_kgm2: float, params: Parameters = PARAMS, timestep: float = 1e-3, integrator: str = "implicitfast"
) -> tuple[mujoco.MjModel, mujoco.MjData, StepperLaw]:
    """A load on the joint the stepper drives directly, and the run's law (φ₀ = 0: the pivot's hinge)."""
    spec = mujoco.MjSpec.from_string(
        _LOAD_XML.format(load=load_kgm2, timestep=timestep, integrator=integrator)
    )
    apply_stepper(spec, params)
    model = spec.compile()
    law = StepperLaw(params.with_overrides({"physics.timestep_s": timestep}))
    return model, mujoco.MjData(model), law


def _steps(model: mujoco.MjModel, data: mujoco.MjData, law: StepperLaw, target: float, n: int) -> None:
    """n physics steps, the law's torque the motor's ctrl before each (as SimRig steps it)."""
    for _ in range(n):
        data.ctrl[0] = law(target, float(data.qpos[0]), float(data.qvel[0]))
        mujoco.mj_step(model, data)


@pytest.mark.quick
def test_the_static_torque_curve_is_the_sine_law_by_hand() -> None:
    # one full step of lag is a quarter electrical cycle, p·Δφ = 50·π/100 = π/2: the holding torque; the detent
    # term, sin(4p·φ) = sin(2π), is zero there
    assert _torque(0.0, FULL_STEP_RAD) == pytest.approx(-HOLD_NM, abs=1e-12)
    assert _torque(FULL_STEP_RAD, 0.0) == pytest.approx(HOLD_NM, abs=1e-12)
    # half a full step: −0.4·sin(π/4) − 0.022·sin(π) = −0.28284
    assert _torque(0.0, FULL_STEP_RAD / 2) == pytest.approx(-0.4 * math.sqrt(0.5), abs=1e-12)
    # a quarter full step: −0.4·sin(π/8) − 0.022·sin(π/2) = −0.15307 − 0.022
    assert _torque(0.0, FULL_STEP_RAD / 4) == pytest.approx(-0.153073 - 0.022, abs=1e-6)
    # two full steps (half a cycle): the unstable balance, no magnetic torque
    assert _torque(0.0, 2 * FULL_STEP_RAD) == pytest.approx(0.0, abs=1e-12)
    # the same through the law and the compiled motor (gear 1, unclamped): the sketch one full step (16
    # microsteps) ahead of the rotor at 0, its ramp at rest on the target
    model, data, law = _load_rig(1e-3)
    for steps, torque in ((16.0, HOLD_NM), (8.0, 0.4 * math.sqrt(0.5))):  # and half a full step
        law.position_steps = steps
        data.ctrl[0] = law(steps, 0.0, 0.0)
        mujoco.mj_forward(model, data)
        assert data.actuator_force[0] == pytest.approx(torque, abs=1e-12)
        assert data.qfrc_actuator[0] == pytest.approx(torque, abs=1e-12)
        assert law.position_steps == steps and law.speed_steps_s == 0.0  # held there


@pytest.mark.quick
def test_the_pullout_torque_falls_past_the_supplys_corner() -> None:
    s = Stepper()

    def pull(w: float) -> float:
        args = (s.holding_torque_nm, s.pole_pairs, s.phase_resistance_ohm, s.phase_inductance_h)
        return float(pullout_torque_nm(w, *args, s.supply_impedance_ohm))

    # by hand: V/I = 12/1.7 = 7.0588 Ω; the corner where √(1.5² + (50·ω·2.8e-3)²) = 7.0588: ω = 6.8976/0.14
    corner = math.sqrt((12 / 1.7) ** 2 - 1.5**2) / (50 * 2.8e-3)
    assert corner == pytest.approx(49.27, abs=0.01)
    assert pull(0.0) == pull(0.9 * corner) == HOLD_NM
    # at 4× the corner: 0.4·7.0588/√(1.5² + (4·6.8976)²) = 0.4·7.0588/27.631 = 0.10219
    assert pull(4 * corner) == pytest.approx(0.4 * (12 / 1.7) / math.hypot(1.5, 4 * 6.8976), rel=1e-4)
    assert pull(-4 * corner) == pull(4 * corner)


# The law is held over each physics step (the rig computes it once a step, before mj_step): against the ODE the
# response is first order in the step (it leads by about half a step), measured 5.2e-4 rad at the rig's 1 ms and
# 5.1e-5 rad at 0.1 ms against the 1.6e-2 rad step over 0.2 s; against the same step written out by hand (the law
# held, implicitfast's damping implicit) 1e-17 rad.
@pytest.mark.quick
@pytest.mark.parametrize(("timestep", "tolerance"), [(1e-4, 6e-5), (1e-3, 6e-4)])
def test_a_small_step_in_mujoco_is_the_odes(timestep: float, tolerance: float) -> None:
    load = 4e-3  # the thesis beam's inertia about its pivot, turned directly
    model, data, law = _load_rig(load, timestep=timestep)
    n = 8  # the sketch half a full step on (p·Δφ = π/4), its ramp at rest on the target
    law.position_steps = float(n)
    inertia, b = load + ROTOR_KGM2, Stepper().damping_nm_s_per_rad
    commanded = n * MICROSTEP_RAD

    def torque(q: float) -> float:
        return -HOLD_NM * math.sin(P * (q - commanded)) - DETENT_NM * math.sin(4 * P * q)

    # the same ODE written out (speeds stay far below the 49 rad/s corner): J·q̈ = −T sin(p(q − φc)) − T_d sin(4pq) − bq̇
    def rhs(_t: float, y: np.ndarray) -> list[float]:
        return [y[1], (torque(y[0]) - b * y[1]) / inertia]

    times = np.arange(1, 21) * 0.01  # 0.2 s: two periods of the 11 Hz ringing
    ode = solve_ivp(rhs, (0.0, 0.2), [0.0, 0.0], t_eval=times, rtol=1e-10, atol=1e-13, max_step=1e-4)
    # the step by hand: the torque at the step's start, v' = v + h·(τ − b·v)/(J + h·b), q' = q + h·v'
    q = v = 0.0
    simulated, by_hand = [], []
    for _ in times:
        steps = round(0.01 / timestep)
        _steps(model, data, law, float(n), steps)
        for _ in range(steps):
            v += timestep * (torque(q) - b * v) / (inertia + timestep * b)
            q += timestep * v
        simulated.append(float(data.qpos[0]))
        by_hand.append(q)
    np.testing.assert_allclose(simulated, ode.y[0], atol=tolerance)
    np.testing.assert_allclose(simulated, by_hand, atol=1e-12)
    # on paper: it rings about φc at √(p·T_hold/J)/(2π) = √(20/0.0040054)/(2π) = 11.2 Hz, overshooting to ≈ 2φc
    assert max(ode.y[0]) == pytest.approx(2 * commanded, rel=0.02)
    assert law.position_steps == n and law.speed_steps_s == 0.0  # the ramp held the target


@pytest.mark.quick
def test_a_load_above_pullout_slips_whole_electrical_cycles() -> None:
    # a light load and a damped rotor (settles in ~0.2 s); a 1.5·T_hold push for 30 ms, then the rotor settles
    params = PARAMS.with_overrides({"stepper.damping_nm_s_per_rad": 0.05})
    model, data, law = _load_rig(1e-4, params)
    data.qfrc_applied[0] = 1.5 * HOLD_NM
    _steps(model, data, law, 0.0, 30)
    data.qfrc_applied[0] = 0.0
    _steps(model, data, law, 0.0, 1500)
    angle = float(data.qpos[0])
    cycles = round(angle / (4 * FULL_STEP_RAD))  # one electrical cycle: 4 full steps, 7.2°
    assert cycles >= 1
    # the rotor rests on an equilibrium whole cycles from the sketch's (detent and magnet agree there)
    assert angle == pytest.approx(cycles * 4 * FULL_STEP_RAD, abs=1e-6)
    assert law.position_steps == 0.0  # the sketch never moved: its count says 0
    assert rotor_missed_full_steps(law, model, data) == -4 * cycles


@pytest.mark.quick
def test_microsteps_move_the_rotor_by_the_detent_bent_fraction_of_a_step() -> None:
    params = PARAMS.with_overrides({"stepper.damping_nm_s_per_rad": 0.05})
    model, data, law = _load_rig(1e-4, params)
    for n in (1, 2, 3, 4, 16):
        law.position_steps, law.speed_steps_s = float(n), 0.0
        _steps(model, data, law, float(n), 1500)
        commanded = n * MICROSTEP_RAD

        # the balance written out: T sin(p(φc − φ)) = T_d sin(4pφ), the root within a full step of φc
        def balance(phi: float, c: float = commanded) -> float:
            return HOLD_NM * math.sin(P * (c - phi)) - DETENT_NM * math.sin(4 * P * phi)

        expected = brentq(balance, commanded - FULL_STEP_RAD / 2, commanded + FULL_STEP_RAD / 2, xtol=1e-14)
        assert data.qpos[0] == pytest.approx(expected, abs=1e-7)
        # bent by the detent at most asin(T_d/T)/p = asin(0.055)/50 = 1.1e-3 rad, 0.56 of a 0.1125° microstep;
        # exact on whole and half full steps, where the detent is zero
        assert abs(expected - commanded) < math.asin(DETENT_NM / HOLD_NM) / P < 0.57 * MICROSTEP_RAD
        if n % 8 == 0:
            assert expected == pytest.approx(commanded, abs=1e-12)


@pytest.mark.quick
def test_the_ramp_is_accelstepper_like() -> None:
    h, v_max, a = 1e-3, 2000.0, 20000.0
    # far from the target at rest: full acceleration; at full speed: none; within the braking distance
    # v²/(2a) = 100 steps at 2000 steps/s: brake
    assert ramp_acceleration(1000.0, 0.0, 0.0, v_max, a, h) == a
    assert ramp_acceleration(1000.0, 0.0, 2000.0, v_max, a, h) == 0.0
    assert ramp_acceleration(1000.0, 910.0, 2000.0, v_max, a, h) == -a
    assert ramp_acceleration(-1000.0, 0.0, 0.0, v_max, a, h) == -a


@pytest.mark.quick
def test_the_board_writes_a_moveto_target_within_the_sketchs_travel() -> None:
    assert step_target_steps(12.9, 3200) == 12.0 and step_target_steps(-12.9, 3200) == -12.0  # C's (long)
    assert step_target_steps(1e9, 3200) == 3200.0
    limits = board_output_range(PARAMS)
    assert (limits.low, limits.high, limits.unit) == (-3200.0, 3200.0, "microsteps")
    assert board_output_range(Parameters()).unit == "µs"  # a servo's rig keeps the pulse
    write = rig_parts(PARAMS).motor_volts_of(PARAMS)
    assert write(40.7) == 40.0


@pytest.mark.quick
def test_the_part_keeps_its_contract() -> None:
    from tests.test_parts import _check_part

    _check_part(STEPPER, seed=3)
    model = rig_parts(PARAMS).build_spec(PARAMS).compile()
    assert not STEPPER.mjcf.missing(model)
    assert STEPPER.batch.difference(np.random.default_rng(7), 64) == 0.0
    assert STEPPER.rest_command(PARAMS) == 0.0


@pytest.mark.quick
@pytest.mark.parametrize("plant", ["twin", "reference"])
@pytest.mark.parametrize("drive", ["pivot", "end_lever"])
def test_a_rig_holds_the_level_beam_with_the_ball_at_the_centre(plant: str, drive: str) -> None:
    # the parts' write path: ideal sensors would write the thesis's DAC volts
    rig = SimRig(PARAMS.with_overrides({"parts.beam_drive": drive}), plant=plant)
    rig.reset(0.0, 0.0, 0.0, 0.0)
    for _ in range(50):  # 1 s at 50 Hz, the sketch's target the rest command
        rig.read()
        rig.write(STEPPER.rest_command(PARAMS))
    x, theta, xdot, thetadot = rig.true_state()
    assert not rig.ball_lost
    # the pivot holds exactly (no torque at the level beam). On the lever MuJoCo's horn and push-rod weigh on the
    # shaft (7.4e-4 N·m, measured) against the magnetic spring p·T_hold = 20 N·m/rad: 3.7e-5 rad at the horn,
    # ~5e-6 rad at the beam, where the ball rolls ½·(5/7)·g·θ·t² ≈ 1.8e-5 m in 1 s
    tilt, roll = (1e-6, 1e-6) if drive == "pivot" else (1e-5, 3e-5)
    assert abs(theta) < tilt and abs(thetadot) < tilt and abs(x) < roll and abs(xdot) < roll
    if plant == "twin":
        assert isinstance(rig.step_law, StepperLaw)
        assert rotor_missed_full_steps(rig.step_law, rig.physics.model, rig.physics.data) == 0  # type: ignore[attr-defined]


# Measured (a 32-microstep, 0.5 Hz sine target, 2 s): the pivot 3.7e-4 rad and 8.7e-5 m apart, the lever 8.9e-4 rad
# and 2.0e-4 m (before the reference model ran the sketch's ramp: 5.4e-3 rad and 1.5e-3 m at the pivot). Both run
# the ramp and the law; the reference evaluates the law in each RK4 stage, MuJoCo holds it over a step.
@pytest.mark.quick
@pytest.mark.parametrize(
    ("drive", "theta_tol", "x_tol"), [("pivot", 1e-3, 3e-4), ("end_lever", 1.5e-3, 5e-4)]
)
def test_mujoco_and_the_reference_model_run_the_same_law(drive: str, theta_tol: float, x_tol: float) -> None:
    params = PARAMS.with_overrides({"parts.beam_drive": drive})
    runs = []
    for plant in ("twin", "reference"):
        rig = SimRig(params, plant=plant)
        rig.reset(0.0, 0.0, 0.0, 0.0)
        states = []
        for k in range(100):
            rig.read()
            rig.write(32.0 * math.sin(math.pi * 0.02 * k))
            states.append(rig.true_state()[:2].copy())
        runs.append(np.array(states))
    twin, reference = runs
    assert np.max(np.abs(twin[:, 1] - reference[:, 1])) < theta_tol
    assert np.max(np.abs(twin[:, 0] - reference[:, 0])) < x_tol
    if drive == "pivot":  # turned directly: the beam follows the 32 microsteps, 3.6°, on both
        assert np.max(np.abs(reference[:, 1])) == pytest.approx(32 * MICROSTEP_RAD, rel=0.1)


@pytest.mark.quick
def test_the_laws_ramp_runs_a_trapezoid_onto_the_target() -> None:
    # 400 microsteps from rest, v_max 2000/s, a 20000/s², h 1 ms, the rotor held at 0 (the ramp does not read it).
    # By hand, discretely: v_k = k·a·h reaches 2000 at k = 100, s_100 = a·h²·(1 + … + 100) = 0.02·5050 = 101;
    # continuously: 0.1 s up, 0.1 s cruising the middle 200, 0.1 s braking: on the target at 0.3 s. The braking
    # reads the distance before the step's move (h·v on): it overshoots by up to v_max·h/2 = 1 microstep (0.997
    # measured, the sketch's count one past) and lands back on the target 19 ms late (measured)
    law = StepperLaw(PARAMS)
    positions, speeds = [], []
    for _ in range(400):
        law(400.0, 0.0, 0.0)
        positions.append(law.position_steps)
        speeds.append(law.speed_steps_s)
    assert speeds[99] == pytest.approx(2000.0, abs=1e-9) and positions[99] == pytest.approx(101.0, abs=1e-9)
    assert max(speeds) == pytest.approx(2000.0, abs=1e-9)
    arrived = next(k for k, s in enumerate(positions) if s == 400.0) + 1  # steps to land on it exactly
    assert 300 <= arrived <= 320
    assert 400.0 < max(positions) < 400.0 + 2000.0 * 1e-3 / 2
    assert positions[-1] == 400.0 and speeds[-1] == 0.0 and law.sketch_position_steps == 400.0


def _sine_run(rig: SimRig) -> np.ndarray:
    rig.reset(0.0, 0.0, 0.0, 0.0)
    states = []
    for k in range(50):
        rig.read()
        rig.write(32.0 * math.sin(math.pi * 0.02 * k))
        states.append(rig.true_state())
    return np.array(states)


@pytest.mark.quick
def test_each_run_starts_a_fresh_law() -> None:
    rig = SimRig(PARAMS)
    first_law = rig.step_law
    first = _sine_run(rig)
    assert isinstance(rig.step_law, StepperLaw) and rig.step_law is not first_law
    assert rig.step_law.position_steps != 0.0  # the ramp moved during the run
    rig.reset(0.0, 0.0, 0.0, 0.0)
    assert isinstance(rig.step_law, StepperLaw) and rig.step_law.position_steps == 0.0
    np.testing.assert_array_equal(_sine_run(rig), first)  # the same run again, bit for bit
    np.testing.assert_array_equal(_sine_run(SimRig(PARAMS)), first)  # and on a new rig
    law = rig.step_law
    position = law.position_steps
    rig.kick_ball(0.01)  # a flick resets MuJoCo's data mid-run, not the sketch
    assert rig.step_law is law and law.position_steps == position
    assert SimRig(PARAMS, plant="reference").step_law is None  # the reference runs the ramp and law itself


@pytest.mark.quick
def test_the_batch_engine_and_the_state_laws_refuse_a_per_step_law() -> None:
    from twin.interface import RigError
    from twin.rigs.backends import backend
    from twin.rigs.batch import BatchRig

    zeros = np.zeros(2)
    physics = backend("twin").batch([PARAMS, PARAMS], zeros, zeros, 1)
    for ideal in (False, True):
        with pytest.raises(RigError, match=r"parts\.actuator = 'stepper'.*step_law.*batch engine"):
            BatchRig(
                [PARAMS, PARAMS],
                zeros,
                zeros,
                np.arange(2),
                physics=physics,
                ideal_sensors=ideal,
                record=False,
            )
    rig = SimRig(PARAMS)
    with pytest.raises(RigError, match=r"parts\.actuator = 'stepper'.*a law on the state"):
        rig.read_with_state_law(lambda state: 0.0, 0.001)


@pytest.mark.quick
def test_the_law_gets_the_boards_target_after_the_output_latency() -> None:
    # 5 ms of latency at 1 ms steps: a target written at a tick reaches the law at the 6th step of the next block
    rig = SimRig(PARAMS.with_overrides({"daq.output_latency_s": 0.005}))
    rig.reset(0.0, 0.0)
    law = rig.step_law
    assert law is not None
    seen: list[float] = []

    def recorded(target: float, angle: float, speed: float) -> float:
        seen.append(target)
        return law(target, angle, speed)

    rig.step_law = recorded
    for k in range(4):
        rig.read()
        rig.write(10.0 * (k + 1))
    rig.read()
    assert seen[-20:] == [30.0] * 5 + [40.0] * 15
