"""The hobby servo (twin.parts.servo): its pulse map and torque law against the SG90 data sheet's numbers worked
on paper, its dead band, its step response in MuJoCo against an independent integration of the same ODE, and a
rig with the servo on the end lever whose beam settles where the linkage's exact closure puts it."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from twin.interface import CommandRange
from twin.model import build_model
from twin.parameters import GROUPS, ParameterError, Parameters
from twin.parts import BatchForm, IoBoardPart, MjcfFragment, part_named, rig_parts
from twin.parts.linkage import SERVO_SHAFT, Linkage
from twin.parts.servo import (
    HOBBY_SERVO,
    MG996R,
    Servo,
    apply_hobby_servo,
    servo_angle_rad,
    servo_drive,
    servo_pulse_us,
    servo_torque_nm,
)
from twin.rigs.sim import SimRig

# The SG90 data sheet's numbers at its rated 4.8 V, worked by hand: 1.8 kgf·cm = 1.8 × 9.80665 N × 0.01 m, and
# 60° in 0.1 s = (π/3)/0.1 rad/s. Fed 5 V, both scale by 5/4.8.
STALL_48_NM = 1.8 * 9.80665 * 0.01  # 0.17652 N·m
SPEED_48_RAD_S = (math.pi / 3) / 0.1  # 10.472 rad/s
STALL_5V_NM = STALL_48_NM * 5.0 / 4.8  # 0.18387 N·m
SPEED_5V_RAD_S = SPEED_48_RAD_S * 5.0 / 4.8  # 10.908 rad/s
SATURATION_RAD = math.radians(5.0)


def _torque(target: float, angle: float, speed: float) -> float:
    s = Servo()
    return float(
        servo_torque_nm(
            target, angle, speed, s.kp_nm_per_rad, s.stall_torque_at_supply_nm, s.damping_nm_s_per_rad
        )
    )


@pytest.mark.quick
def test_the_pulse_map_is_the_data_sheets() -> None:
    s = Servo()

    def angle(pulse: float) -> float:
        return float(
            servo_angle_rad(pulse, s.pulse_min_us, s.pulse_max_us, s.angle_at_min_rad, s.angle_at_max_rad)
        )

    # "−90" at ~1 ms, "0" at 1.5 ms, "90" at ~2 ms; held at the travel's ends
    assert angle(1000.0) == pytest.approx(-math.pi / 2)
    assert angle(1500.0) == pytest.approx(0.0, abs=1e-15)
    assert angle(2000.0) == pytest.approx(math.pi / 2)
    assert angle(1250.0) == pytest.approx(-math.pi / 4)
    assert angle(700.0) == pytest.approx(-math.pi / 2) and angle(2400.0) == pytest.approx(math.pi / 2)


@pytest.mark.quick
def test_the_torque_law_at_stall_no_load_and_half_speed() -> None:
    far = 1.0  # rad of error: far past the 5° at which the drive saturates
    assert _torque(far, 0.0, 0.0) == pytest.approx(STALL_5V_NM, rel=1e-12)  # stall
    assert _torque(far, 0.0, SPEED_5V_RAD_S) == pytest.approx(0.0, abs=1e-12)  # no load
    assert _torque(far, 0.0, SPEED_5V_RAD_S / 2) == pytest.approx(STALL_5V_NM / 2, rel=1e-12)  # half speed
    assert _torque(-far, 0.0, -SPEED_5V_RAD_S / 2) == pytest.approx(-STALL_5V_NM / 2, rel=1e-12)
    # inside the proportional band, at rest: k_p·e = τ_s·e/e_sat
    assert _torque(SATURATION_RAD / 4, 0.0, 0.0) == pytest.approx(STALL_5V_NM / 4, rel=1e-12)
    # an MG996R's override set: 9.4 kgf·cm and 60° in 0.17 s at 4.8 V, the same line through b = τ_s/ω₀
    mg = Parameters().with_overrides(MG996R).of(Servo)
    assert mg.stall_torque_at_supply_nm == pytest.approx(9.4 * 9.80665 * 0.01 * 5.0 / 4.8)
    assert mg.damping_nm_s_per_rad == pytest.approx(9.4 * 9.80665 * 0.01 / ((math.pi / 3) / 0.17))
    mg_map = (mg.pulse_min_us, mg.pulse_max_us, mg.angle_at_min_rad, mg.angle_at_max_rad)
    assert float(servo_angle_rad(2000.0, *mg_map)) == pytest.approx(math.radians(60.0))  # 60° each way


@pytest.mark.quick
def test_a_servo_group_that_cannot_be_is_refused_naming_its_fields() -> None:
    with pytest.raises(ParameterError, match=r"servo\.pulse_min_us.*servo\.pulse_max_us"):
        Parameters().with_overrides({"servo.pulse_min_us": 2100.0})
    with pytest.raises(ParameterError, match=r"servo\.angle_at_min_rad"):
        Parameters().with_overrides({"servo.angle_at_min_rad": 0.5, "servo.angle_at_max_rad": 0.5})
    with pytest.raises(ParameterError, match=r"servo\.supply_v"):
        Parameters().with_overrides({"servo.supply_v": -5.0})
    with pytest.raises(ParameterError, match=r"servo\.stall_torque_nm"):
        Parameters().with_overrides({"servo.stall_torque_nm": float("nan")})


@pytest.mark.quick
def test_the_dead_band_holds_small_pulse_changes_in_a_fresh_closure_each_run() -> None:
    params = Parameters()
    us = math.pi / 1000.0  # rad per µs of the SG90's map (180° over 1000 µs)
    drive = servo_drive(params)
    assert drive(1500.0) == pytest.approx(0.0, abs=1e-15)  # the first pulse is accepted
    assert drive(1509.0) == pytest.approx(0.0, abs=1e-15)  # 9 µs: inside the 10 µs dead band
    assert drive(1511.0) == pytest.approx(11 * us)  # 11 µs: accepted
    assert drive(1502.0) == pytest.approx(11 * us)  # 9 µs back: held
    assert drive(1500.0) == pytest.approx(0.0, abs=1e-15)  # 11 µs back: accepted
    assert servo_drive(params)(1509.0) == pytest.approx(9 * us)  # a new run starts without the old state


# A known load: a disc of 1e-4 kg·m² on a frictionless hinge named as the thesis's pivot (the servo's input joint
# for the pivot drive), no gravity.
_LOAD_KGM2 = 1e-4
_LOAD_XML = """
<mujoco>
  <option timestep="{timestep}" integrator="{integrator}" gravity="0 0 0"/>
  <worldbody>
    <body name="load">
      <joint name="beam_hinge" type="hinge" axis="0 -1 0"/>
      <inertial pos="0 0 0" mass="0.1" diaginertia="{load} {load} {load}"/>
    </body>
  </worldbody>
  <actuator><motor name="motor" joint="beam_hinge"/></actuator>
</mujoco>
"""


# RK4 at 0.1 ms: MuJoCo's integration error far below the comparison's (measured 3e-8 rad). The rig's own
# implicitfast at 1 ms: first order in the step against a 15 ms mechanical time constant (measured 2.0e-3 rad).
@pytest.mark.quick
@pytest.mark.parametrize(
    ("timestep", "integrator", "tolerance"), [(1e-4, "RK4", 1e-6), (1e-3, "implicitfast", 5e-3)]
)
def test_the_step_response_in_mujoco_is_the_odes(timestep: float, integrator: str, tolerance: float) -> None:
    params = Parameters()
    spec = mujoco.MjSpec.from_string(
        _LOAD_XML.format(timestep=timestep, integrator=integrator, load=_LOAD_KGM2)
    )
    apply_hobby_servo(spec, params)
    model = spec.compile()
    data = mujoco.MjData(model)
    target = 0.5  # rad, a 29° step from rest
    data.ctrl[0] = target

    # the same ODE written out: (J_load + J_rotor)·q̈ = clip(k_p·(target − q), ±τ_s) − b·q̇
    inertia = _LOAD_KGM2 + 1.5e-4
    kp, stall, b = STALL_5V_NM / SATURATION_RAD, STALL_5V_NM, STALL_48_NM / SPEED_48_RAD_S

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        drive = min(max(kp * (target - y[0]), -stall), stall)
        return [y[1], (drive - b * y[1]) / inertia]

    times = np.arange(1, 31) * 0.01  # every 10 ms for 0.3 s
    ode = solve_ivp(rhs, (0.0, 0.3), [0.0, 0.0], t_eval=times, rtol=1e-10, atol=1e-12, max_step=1e-4)
    simulated = []
    for _ in range(len(times)):
        for _ in range(round(0.01 / timestep)):
            mujoco.mj_step(model, data)
        simulated.append(data.qpos[0])
    np.testing.assert_allclose(simulated, ode.y[0], atol=tolerance)
    # on paper: it sets off at τ_s/J, turns near the no-load speed while saturated, and ends on its target
    mujoco.mj_resetData(model, data)
    data.ctrl[0] = target
    mujoco.mj_forward(model, data)
    assert data.qacc[0] == pytest.approx(STALL_5V_NM / inertia, rel=1e-9)
    assert max(ode.y[1]) < SPEED_5V_RAD_S
    assert ode.y[0][-1] == pytest.approx(target, abs=1e-4)


@pytest.mark.quick
def test_the_compiled_actuator_is_the_servo_on_the_drives_input_joint() -> None:
    for drive, joint in (("pivot", "beam_hinge"), ("end_lever", SERVO_SHAFT)):
        params = Parameters().with_overrides({"parts.beam_drive": drive, "parts.actuator": "hobby_servo"})
        model = build_model(params)
        assert model.joint(model.actuator_trnid[0, 0]).name == joint
        assert model.actuator_gainprm[0, 0] == pytest.approx(STALL_5V_NM / SATURATION_RAD)
        np.testing.assert_allclose(model.actuator_forcerange[0], [-STALL_5V_NM, STALL_5V_NM])
        assert model.actuator_damping[0] == pytest.approx(STALL_48_NM / SPEED_48_RAD_S)
        assert model.actuator_armature[0] == pytest.approx(1.5e-4)
        np.testing.assert_allclose(model.actuator_ctrlrange[0], [-math.pi / 2, math.pi / 2])
        assert not HOBBY_SERVO.mjcf.missing(model)


@pytest.mark.quick
def test_the_part_keeps_its_contract() -> None:
    assert part_named("actuator", "hobby_servo") is HOBBY_SERVO
    assert HOBBY_SERVO.batch.difference(np.random.default_rng(20261207), 24) <= HOBBY_SERVO.batch.tolerance


def _pulse_board() -> IoBoardPart:
    """A board whose output is the command itself, as a pulse width in µs (the rig's write, unquantized)."""

    def same(_params: Parameters) -> object:
        return lambda value: float(value)

    def single(_p: Parameters, row: np.ndarray) -> np.ndarray:
        return row.copy()

    def batch(_p: object, rows: np.ndarray) -> np.ndarray:
        return rows.copy()

    def inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
        return [Parameters()] * n, rng.uniform(1000.0, 2000.0, (n, 1))

    return IoBoardPart(
        name="pulse_out",
        source="test: the command written as the servo pulse",
        groups={"daq": GROUPS["daq"]},
        equations=(float,),
        mjcf=MjcfFragment(),
        batch=BatchForm(single, batch, inputs, "float"),
        dac_writer=same,  # type: ignore[arg-type]
        adc=same,  # type: ignore[arg-type]
        output_range=lambda _p: CommandRange(500.0, 2500.0, "µs", "the test's pulse", "the pulse's range"),
    )


@pytest.mark.quick
def test_the_rest_command_is_the_pulse_that_holds_the_beam_level() -> None:
    # the pivot: the servo's 0 at 1.5 ms; the default lever: the horn horizontal at level, the servo's 0 too;
    # a horn splined on 18° up (neutral 18°) needs the servo at −18° to hold the beam level: 1.5 ms − 100 µs
    assert HOBBY_SERVO.rest_command(Parameters().with_overrides({"parts.actuator": "hobby_servo"})) == 1500.0
    lever = Parameters().with_overrides({"parts.actuator": "hobby_servo", "parts.beam_drive": "end_lever"})
    assert HOBBY_SERVO.rest_command(lever) == pytest.approx(1500.0, abs=1e-9)
    tilted = lever.with_overrides({"linkage.horn_neutral_rad": math.radians(18.0)})
    assert HOBBY_SERVO.rest_command(tilted) == pytest.approx(1400.0, abs=1e-9)
    s = Servo()
    assert float(servo_pulse_us(math.pi / 4, 1000.0, 2000.0, -math.pi / 2, math.pi / 2)) == pytest.approx(
        1750.0
    )
    assert s.pulse_max_us == float(servo_pulse_us(3.0, 1000.0, 2000.0, -math.pi / 2, math.pi / 2))


@pytest.mark.quick
def test_a_rig_with_the_servo_on_the_lever_settles_where_the_closure_puts_the_beam() -> None:
    params = Parameters().with_overrides({"parts.beam_drive": "end_lever", "parts.actuator": "hobby_servo"})
    rig = SimRig(params, parts=rig_parts(params).replace(_pulse_board()))
    pulse = 1600.0
    # by hand: 1600 µs is 100 µs past centre, 90°/500 µs·100 µs = 18° of servo angle, the horn's neutral is 0°
    phi = math.radians(18.0)
    expected = float(Linkage().theta_rad(phi))
    assert expected == pytest.approx(0.0514, abs=1e-4)  # ≈ (c/L)·φ = φ/6 = 0.0524, less the closure's bend
    rig.reset(0.0, 0.0, 0.0, 0.0)
    for _ in range(30):  # 0.6 s: the servo settles in ~0.2 s, the ball rolls ~0.07 m
        rig.read()
        rig.write(pulse)
    x, theta = rig.true_state()[:2]
    assert not rig.ball_lost and abs(x) < 0.2
    # the ball's weight at x < 0.2 m (0.0188 kg·9.81·0.2 = 0.037 N·m at the beam, φ/6 of it at the horn: 6e-3 N·m)
    # bends the P-loop by at most 6e-3/(τ_s/e_sat = 2.1) = 3e-3 rad at the horn, 5e-4 rad at the beam
    assert theta == pytest.approx(expected, abs=5e-4)


@pytest.mark.quick
def test_a_pulse_past_the_linkages_travel_stalls_the_horn_at_its_stop() -> None:
    # 2000 µs asks the servo for +90°; the default lever's horn works ±60° (its dead point lies near +80°): the
    # horn stops at +60° and the beam at θ(60°) of the exact closure
    params = Parameters().with_overrides({"parts.beam_drive": "end_lever", "parts.actuator": "hobby_servo"})
    rig = SimRig(params, parts=rig_parts(params).replace(_pulse_board()))
    rig.reset(0.0, 0.0, 0.0, 0.0)
    for _ in range(20):
        rig.read()
        rig.write(2000.0)
    expected = float(Linkage().theta_rad(math.pi / 3))
    assert expected == pytest.approx(math.radians(8.064), abs=1e-4)
    assert rig.true_state()[1] == pytest.approx(expected, abs=2e-3)  # the stop's give under the stall torque
