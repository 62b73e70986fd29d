"""Today's rig as parts: the thesis's ball, two wires, beam turned at its pivot, geared Escap motor with its
amplifier, resistive wire, encoder and counter, and PCI-1712 card, each one ``register``ed entry, and
``THESIS``, the rig they make (``twin.rigs.sim.SimRig``'s default, bit for bit the rig before parts).

Each part points at its parameter groups (``twin.parameters``), its equations' homes (``twin.sensors``,
``twin.dcmotor``, ``twin.daq``, ``twin.output_stage``, ``twin.reference``), its MJCF fragment (``twin.model``) and
its batch form: the plant's parts the fast engine's compiled kernel (``twin.screen``, imported when first
used: a single run never loads numba), the sensors and the output stage the batch rig's (``twin.rigs.batch``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType
from typing import Any

import numpy as np

from twin import model as mdl
from twin.converters import (
    ball_position_m,
    beam_angle_rad,
    dac_command_v,
    finite_input,
    motor_volts_from_command,
)
from twin.daq import (
    TickSchedule,
    adc_quantize_v,
    adc_quantizer,
    block_time_s,
    dac_quantize_v,
    dac_quantizer,
    software_block_reading_v,
)
from twin.dcmotor import beam_torque_nm, torque_nm, volts_for_torque_v
from twin.output_stage import amplifier_of, amplifier_volts, motor_volts, motor_volts_of
from twin.parameters import GROUPS, Ball, Daq, Parameters
from twin.parts.contract import (
    ActuatorPart,
    AngleSensorPart,
    BallSensorPart,
    BatchForm,
    BatchWrite,
    IoBoardPart,
    MjcfFragment,
    Part,
    RigParts,
    register,
    vary,
)
from twin.physics import PhysicsBlock
from twin.reference import EquationCoefficients, ReferencePlant, ball_beam_accelerations
from twin.sensors import (
    AngleChain,
    BallChainBatch,
    BallPositionChain,
    angle_block_mean_v,
    angle_block_means_v,
    counter_dac_v,
    counter_value,
    dropout_effects_v,
    equally_spaced,
    rc_end_v,
    rc_filter_end_v,
    wiper_static_v,
    wiper_v,
)

__all__ = [
    "ANGLE_SENSOR",
    "BALL",
    "BALL_SENSOR",
    "BEAM_DRIVE",
    "IO_BOARD",
    "MOTOR",
    "NOT_PART_GROUPS",
    "THESIS",
    "TRACK",
    "is_thesis_rig",
]


def _groups(*names: str) -> dict[str, type]:
    """The parameter table's groups by name: the part points at them (one source of truth)."""
    return {name: GROUPS[name] for name in names}


def _getter(prop: Any) -> Callable[..., Any]:
    """A derived value's home (a property of a parameter group): its getter."""
    assert isinstance(prop, property) and prop.fget is not None
    return prop.fget


def _wire_position_of(params: Parameters) -> Callable[[float], float]:
    """The rig software's eq 6.3.1 (``twin.converters.ball_position_m``)."""
    sw = params.software
    return lambda volts: float(ball_position_m(volts, sw))


def _encoder_angle_of(params: Parameters) -> Callable[[float], float]:
    """The rig software's eq 6.2.10 (``twin.converters.beam_angle_rad``)."""
    sw = params.software
    return lambda volts: float(beam_angle_rad(volts, sw))


def _motor_command_of(params: Parameters) -> Callable[[float], float]:
    """The software's command for motor volts (§6.4, ``twin.converters.dac_command_v``)."""
    sw = params.software
    return lambda volts: float(dac_command_v(volts, sw))


def _motor_control_of(params: Parameters) -> Callable[[float], float]:
    """The motor volts a command gives, as the software reckons them (``twin.converters.motor_volts_from_command``)."""
    sw = params.software
    return lambda command: float(motor_volts_from_command(command, sw))


def _card_volts_of(params: Parameters) -> Callable[[float], float]:
    """The PCI-1712 reads volts: its reading is the volts."""
    return float


# --- the plant's parts: the fast engine's kernel over N runs, each with its own part -------------------
# Physics steps of one batch-form case: enough for every RK4 stage to see the part's constants.
_PLANT_STEPS = 5


def _plant_single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One run of the reference plant (``ReferencePlant.advance``) from the row's state at its held volts."""
    plant = ReferencePlant(params)
    x, th, xd, thd, volts = row.tolist()
    plant.reset(x, th, xd, thd)
    plant.advance(np.full(_PLANT_STEPS, volts))
    return plant.state()


def _plant_batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every run at once in the fast engine's compiled kernel (``twin.screen.advance_plant``), each run with its
    own row of constants (``plant_rows``)."""
    from twin.screen import advance_plant, plant_rows  # numba: loaded by a batch only

    states = np.ascontiguousarray(rows[:, :4], dtype=float)
    lost = np.full(len(rows), -1, dtype=np.int64)
    advance_plant(plant_rows(params), states, lost, np.repeat(rows[:, 4:5], _PLANT_STEPS, axis=1))
    return states


def _plant_form(names: Sequence[str]) -> BatchForm:
    """The plant's batch form, each run with its own values of ``names`` (the part's parameters)."""

    def inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
        params = vary(Parameters(), names, rng, n)
        rows = np.column_stack(
            [
                rng.uniform(-0.25, 0.25, n),  # x (m), clear of the track's ends over the steps
                rng.uniform(-0.7, 0.7, n),  # θ (rad), some reaching a stop
                rng.uniform(-1.0, 1.0, n),
                rng.uniform(-3.0, 3.0, n),
                rng.uniform(-14.0, 14.0, n),  # volts, beyond the rails too
            ]
        )
        return params, rows

    # the reference plant and the kernel are held to each other to 1e-12 (tests/test_screen.py)
    return BatchForm(_plant_single, _plant_batch, inputs, "twin.screen.advance_plant", tolerance=1e-12)


BALL = register(
    Part(
        name="steel_ball",
        role="ball",
        source="Table 3.1: the steel ball (m, r), a solid sphere (eq 3.1.21)",
        groups=_groups("ball"),
        equations=(_getter(Ball.inertia_kgm2), EquationCoefficients),
        mjcf=MjcfFragment(
            (
                ("body", mdl.BALL_BODY),
                ("joint", mdl.BALL_JOINT),
                ("geom", mdl.BALL_GEOM),
                ("site", mdl.BALL_SITE),
                ("sensor", mdl.BALL_IN_BEAM),
            ),
            mdl.apply_ball,
        ),
        batch=_plant_form(("ball.mass_kg", "ball.radius_m")),
    )
)

TRACK = register(
    Part(
        name="two_wires",
        role="track",
        source="Table 3.1 (h*, d), §3: two wires, the ball's centre r* = √(r² − d²/4) above their contact line",
        groups=_groups("track"),
        equations=(
            _getter(Parameters.rolling_radius_m),
            _getter(Parameters.ball_centre_height_m),
            _getter(Parameters.rolling_inertia_ratio),
        ),
        mjcf=MjcfFragment(
            tuple(("geom", name) for name in mdl.WIRES) + tuple(("site", name) for name in mdl.TRACK_SITES),
            mdl.apply_track,
        ),
        batch=_plant_form(("track.contact_height_m", "track.contact_spacing_m", "track.half_length_m")),
    )
)

BEAM_DRIVE = register(
    Part(
        name="pivot",
        role="beam_drive",
        source="Table 3.1 (M_B, J_BP, h), §3: the beam turned at its pivot P, mechanical stops at ±43.4°",
        groups=_groups("beam"),
        equations=(ball_beam_accelerations, EquationCoefficients, ReferencePlant),
        mjcf=MjcfFragment(
            (("body", mdl.BEAM_BODY), ("joint", mdl.HINGE)) + tuple(("sensor", s) for s in mdl.HINGE_SENSORS),
            mdl.apply_beam_drive,
        ),
        batch=_plant_form(
            ("beam.mass_kg", "beam.inertia_pivot_kgm2", "beam.cog_height_m", "beam.stop_angle_rad")
        ),
    )
)


# --- the actuator: the amplifier and the geared motor ----------------------------------------------------
_MOTOR_VARIED = (
    "amplifier.gain_v_per_v",
    "motor.resistance_ohm",
    "motor.torque_constant_nm_per_a",
    "motor.backemf_constant_v_s_per_rad",
)


def _motor_inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    params = vary(Parameters(), _MOTOR_VARIED, rng, n)
    # commands beyond the DAC's 0…5 V too, beam rates of a fast swing
    return params, np.column_stack([rng.uniform(-0.5, 5.5, n), rng.uniform(-5.0, 5.0, n)])


def _motor_single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """The rig's per-tick write (``motor_volts_of``) and the torque at the beam (``beam_torque_nm``)."""
    command_v, rate = row.tolist()
    volts = motor_volts_of(params)(command_v)
    return np.array([volts, float(beam_torque_nm(params.motor, params.amplifier, volts, rate))])


def _motor_batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """The batch rig's write (``motor_volts``, each run's amplifier gain) and the kernel's torque law
    (``torque_nm`` on each run's constants, the volts within the rails)."""
    gains = np.array([p.amplifier.gain_v_per_v for p in params])
    volts = np.asarray(motor_volts(rows[:, 0], params[0], gains))
    rails = np.array([p.amplifier.rail_v for p in params])
    k_tau = np.array([p.motor.torque_per_volt_nm_per_v for p in params])
    k_b = np.array([p.motor.backemf_at_beam_v_s_per_rad for p in params])
    return np.column_stack([volts, torque_nm(np.clip(volts, -rails, rails), rows[:, 1], k_tau, k_b)])


def _motor_batch_drive(params: Sequence[Parameters]) -> BatchWrite:
    """The amplifier of N runs (``amplifier_volts`` on the DAC's volts, each run's gain; the batch shares the
    rest of the amplifier: ``twin.rigs.batch.PER_RUN_IO``): ``motor_volts`` after the card's ``batch_dac``."""
    amplifier = params[0].amplifier
    gains = np.array([p.amplifier.gain_v_per_v for p in params])

    def drive(runs: np.ndarray, dac_v: np.ndarray) -> np.ndarray:
        return np.asarray(amplifier_volts(dac_v, amplifier, gains[runs]))

    return drive


MOTOR = register(
    ActuatorPart(
        name="escap_dc_motor",
        source="Table 3.2, §3.3: Escap 26L18-216 through a 1:7 gearbox (eq 3.3.1); §6.4: amplifier 9.6 V/V, ±12 V",
        groups=_groups("motor", "amplifier"),
        equations=(torque_nm, beam_torque_nm, volts_for_torque_v, amplifier_volts, amplifier_of),
        mjcf=MjcfFragment(
            (("actuator", mdl.MOTOR), ("sensor", mdl.MOTOR_SENSOR)),
            mdl.apply_actuator,
        ),
        batch=BatchForm(_motor_single, _motor_batch, _motor_inputs, "twin.output_stage.motor_volts"),
        drive=amplifier_of,
        command_of=_motor_command_of,
        control_of=_motor_control_of,
        batch_drive=_motor_batch_drive,
    )
)


# --- the ball sensor: the resistive wire, its contact noise and RC filter -------------------------------
_BALL_BLOCKS = 6
_BALL_STEPS = 20  # physics steps per block (a 20 ms period at 1 ms)
# Contact losses often enough that a few blocks of a few runs hold one.
_NOISY = Parameters().with_overrides({"ball_sensor.dropout_rate_hz": 40.0})


def _ball_track(row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A ball rolling at constant speed: its times (shared) and positions over every block's knots."""
    dt = _NOISY.physics.timestep_s
    times = np.arange(_BALL_BLOCKS * _BALL_STEPS + 1) * dt
    return times, row[1] + row[2] * times


def _ball_inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    params = vary(_NOISY, ("ball_sensor.rc_resistance_ohm", "ball_sensor.dropout_rate_hz"), rng, n)
    seeds = rng.integers(0, 2**31, n).astype(float)
    # starts anywhere on the track, speeds that cross the curve's points and, for some, the track's end
    return params, np.column_stack([seeds, rng.uniform(-0.3, 0.3, n), rng.uniform(-1.0, 1.0, n)])


def _ball_single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One run's chain (``BallPositionChain``), as the rig starts and advances it."""
    times, x = _ball_track(row)
    seed = int(row[0])
    chain = BallPositionChain(params, seed, x_m=float(x[0]))
    chain.reset(float(x[0]), 0.0, seed=seed)
    half = params.track.half_length_m
    out = []
    for b in range(_BALL_BLOCKS):
        k = slice(b * _BALL_STEPS, (b + 1) * _BALL_STEPS + 1)
        t = times[k]
        out.append(chain.advance_rig_block(t, x[k], np.abs(x[k]) <= half, equally_spaced(t)))
    return np.array([*out, chain.filtered_v])


def _ball_batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every run's chain at once (``BallChainBatch``)."""
    tracks = [_ball_track(row) for row in rows]
    times = tracks[0][0]
    x = np.array([track[1] for track in tracks])
    chains = BallChainBatch(list(params), rows[:, 0].astype(np.int64), x[:, 0], 0.0)
    runs = np.arange(len(rows))
    half = params[0].track.half_length_m
    out = []
    for b in range(_BALL_BLOCKS):
        k = slice(b * _BALL_STEPS, (b + 1) * _BALL_STEPS + 1)
        out.append(chains.advance(runs, times[k], x[:, k], np.abs(x[:, k]) <= half))
    return np.column_stack([*out, chains.filtered_v])


def _ball_chain(params: Parameters, seed: int) -> BallPositionChain:
    return BallPositionChain(params, seed)


BALL_SENSOR = register(
    BallSensorPart(
        name="resistive_wire",
        source="§6.3: the wiper on a resistance wire, Table 6.3's static curve, RC 147 Ω / 22 µF; contact noise "
        "assumed (fit from a log)",
        groups=_groups("ball_sensor"),
        equations=(wiper_static_v, wiper_v, rc_end_v, rc_filter_end_v, dropout_effects_v, BallPositionChain),
        mjcf=MjcfFragment(),
        batch=BatchForm(_ball_single, _ball_batch, _ball_inputs, "twin.sensors.BallChainBatch"),
        chain=_ball_chain,
        position_of=_wire_position_of,
        batch_chain=BallChainBatch,
    )
)


# --- the angle sensor: the motor's encoder, the counter and its DAC --------------------------------------
_ANGLE_KNOTS = 21  # a 20 ms block's physics steps at 1 ms
_ANGLE_T0_S = 0.1


def _angle_times() -> np.ndarray:
    return _ANGLE_T0_S + np.arange(_ANGLE_KNOTS) * Parameters().physics.timestep_s


def _angle_inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    zero = rng.uniform(-0.01, 0.01, n)
    params = [Parameters().with_overrides({"angle_sensor.zeroing_error_rad": z}) for z in zero.tolist()]
    rates = rng.uniform(-20.0, 20.0, n)  # up to 114 counts a block: past the count-crossing path's limit
    rates[: n // 4] = 0.0  # a still beam
    return params, np.column_stack([rng.uniform(-0.6, 0.6, n), rates])


def _angle_theta(row: np.ndarray) -> np.ndarray:
    times = _angle_times()
    return row[0] + row[1] * (times - times[0])


def _angle_single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One run's chain as the rig reads a block (``AngleChain.read_block_v``)."""
    times, theta = _angle_times(), _angle_theta(row)
    block = PhysicsBlock(times, np.zeros_like(times), theta, np.ones(times.shape, dtype=bool))
    return np.array([AngleChain(params).read_block_v(block)])


def _angle_batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every run's block mean at once (``angle_block_means_v``, each run's zeroing error)."""
    theta = np.array([_angle_theta(row) for row in rows])
    zero = np.array([p.angle_sensor.zeroing_error_rad for p in params])
    return angle_block_means_v(_angle_times(), theta, params[0], zero)[:, None]


class _EncoderBatch:
    """N runs' encoders, counters and block means (``AngleSensorBatch``): ``angle_block_means_v`` with each run's
    zeroing error (the batch shares the rest of the angle sensor's and the card's parameters:
    ``twin.rigs.batch.batch_key``)."""

    def __init__(self, params: Sequence[Parameters]) -> None:
        self.params = params[0]
        self.zeroing_error_rad = np.array([p.angle_sensor.zeroing_error_rad for p in params])

    def read(self, runs: np.ndarray, times_s: np.ndarray, theta_rad: np.ndarray) -> np.ndarray:
        return angle_block_means_v(times_s, theta_rad, self.params, self.zeroing_error_rad[runs])


ANGLE_SENSOR = register(
    AngleSensorPart(
        name="encoder_counter",
        source="§6.2: HEDS 5540 encoder on the motor, 10-bit up/down counter, AD561 DAC (eq 6.2.6), block mean",
        groups=_groups("angle_sensor"),
        equations=(counter_value, counter_dac_v, angle_block_mean_v, AngleChain),
        mjcf=MjcfFragment(),
        batch=BatchForm(_angle_single, _angle_batch, _angle_inputs, "twin.sensors.angle_block_means_v"),
        chain=AngleChain,
        angle_of=_encoder_angle_of,
        batch_read=_EncoderBatch,
    )
)


# --- the I/O board: the PCI-1712's converters and block timing -------------------------------------------
def _card_inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    return [Parameters()] * n, rng.uniform(-7.0, 7.0, (n, 1))  # past both converters' ends


def _card_single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One value through the per-tick converters (``adc_quantizer``, ``dac_quantizer``)."""
    v = float(row[0])
    return np.array([adc_quantizer(params.daq)(v), dac_quantizer(params.daq)(v)])


def _card_batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every value at once (``adc_quantize_v``, ``dac_quantize_v`` on arrays: the batch rig's)."""
    daq = params[0].daq
    return np.column_stack([adc_quantize_v(rows[:, 0], daq), dac_quantize_v(rows[:, 0], daq)])


def _card_dac(params: Parameters) -> Callable[[float], float]:
    return dac_quantizer(params.daq)


def _card_adc(params: Parameters) -> Callable[[float], float]:
    return adc_quantizer(params.daq)


def _same_daq(params: Sequence[Parameters]) -> Daq | None:
    """The card's parameters if every run has the same (a batch's group), else None."""
    daq = params[0].daq
    return daq if all(p.daq == daq for p in params) else None


def _card_batch_dac(params: Sequence[Parameters]) -> BatchWrite:
    """The DAC of N runs (``dac_quantize_v`` on the commands, finite as ``motor_volts`` asks), each run's card."""
    daq = _same_daq(params)
    each = [dac_quantizer(p.daq) for p in params]

    def write(runs: np.ndarray, command_v: np.ndarray) -> np.ndarray:
        c = finite_input(command_v, "command_v")
        if daq is not None:
            return np.asarray(dac_quantize_v(c, daq))
        return np.array([each[i](v) for i, v in zip(runs.tolist(), np.asarray(c).tolist(), strict=True)])

    return write


def _card_batch_adc(params: Sequence[Parameters]) -> BatchWrite:
    """The ADC of N runs (``adc_quantize_v`` on the volts), each run's card."""
    daq = _same_daq(params)
    each = [adc_quantizer(p.daq) for p in params]

    def read(runs: np.ndarray, volts: np.ndarray) -> np.ndarray:
        if daq is not None:
            return np.asarray(adc_quantize_v(volts, daq))
        return np.array([each[i](v) for i, v in zip(runs.tolist(), np.asarray(volts).tolist(), strict=True)])

    return read


IO_BOARD = register(
    IoBoardPart(
        name="pci1712",
        source="Table 6.4, §6.5, appendix A: Advantech PCI-1712, 12-bit ADC ±5 V and DAC 0…5 V, 800-sample blocks",
        groups=_groups("daq"),
        equations=(
            adc_quantize_v,
            dac_quantize_v,
            adc_quantizer,
            dac_quantizer,
            software_block_reading_v,
            block_time_s,
            TickSchedule,
        ),  # fmt: skip
        mjcf=MjcfFragment(),
        batch=BatchForm(_card_single, _card_batch, _card_inputs, "twin.daq.adc_quantize_v"),
        dac_writer=_card_dac,
        volts_of=_card_volts_of,
        adc=_card_adc,
        batch_dac=_card_batch_dac,
        batch_adc=_card_batch_adc,
    )
)

# The parameter groups no part owns, and why: each of the others belongs to exactly one part above.
NOT_PART_GROUPS: Mapping[str, str] = MappingProxyType(
    {
        "physics": "the MuJoCo model's numerical settings: the physics backend's, not the rig's",
        "software": "the rig software's conversion constants: what a controller receives, not hardware",
        "start": "how a run starts (the rig held, then released): the session's timing, not a part",
        "mcu_io": "an Arduino-class board's front end, for firmware in the loop: the controller host's board",
    }
)

THESIS = RigParts(
    ball=BALL,
    track=TRACK,
    beam_drive=BEAM_DRIVE,
    actuator=MOTOR,
    ball_sensor=BALL_SENSOR,
    angle_sensor=ANGLE_SENSOR,
    io_board=IO_BOARD,
)


def is_thesis_rig(parts: RigParts) -> bool:
    """Whether ``parts`` are the thesis's seven (whatever their parameters): what is written for the thesis's
    software and card alone (its view, its log checks, its smooth identification model) applies."""
    return all(ours is theirs for ours, theirs in zip(parts, THESIS, strict=True))
