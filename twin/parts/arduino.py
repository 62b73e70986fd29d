"""The Arduino Uno and Nano as the rig's I/O board (``arduino_uno``, ``arduino_nano``): the same ATmega328P at
16 MHz on a 5 V supply, one parameter group (``arduino``).

What the board reads and writes, in its own units (``twin.interface``: a controller gets the board's readings
and returns the board's output):

    analogRead      ``analog_read_counts``: the 10-bit ADC on its 5 V reference (AVcc, ``analogReference(DEFAULT)``):
                    counts = ⌊V·1024/V_ref⌋ clipped to 0 … 1023 (ATmega328P data sheet, "Analog-to-Digital
                    Converter", "ADC Conversion Result": ADC = V_IN·1024/V_REF, 0x000 is GND, 0x3FF is V_REF
                    minus one LSB)
    the servo       ``servo_pulse_us``: ``Servo.writeMicroseconds`` of the AVR Servo library (arduino-libraries/Servo,
                    src/avr/Servo.cpp): the command as a C ``int`` (truncated), clamped to the limits ``attach``
                    sets (544 … 2400 µs by default, each limit held in 4 µs steps), then timer 1 ticks at prescale
                    8 (0.5 µs at 16 MHz), less the library's 2 µs trim for its interrupt's latency. At 16 MHz the
                    pulse's resolution is therefore 1 µs (the ``int`` argument), not 4 µs: 4 µs is the resolution
                    of the ``attach(pin, min, max)`` limits (and of ``micros()``), not of the pulse
    I²C             ``i2c_read_time_s``: how long reading N bytes from a register takes at the bus clock (the
                    Wire library's 100 kHz: TWBR = 72, SCL = F_CPU/(16 + 2·TWBR), data sheet "2-wire Serial
                    Interface", "Bit Rate Generator Unit"): a latency the I²C sensors may use
    the loop        ``arduino.loop_period_s``: the sketch's control period (the board's and the controller's, not
                    the twin's): the simulated rig ticks at it (``Parameters.period_s``)

How the board's output reaches the actuator: ``dac_writer(params)`` turns the controller's command (µs) into
the pulse width the servo pin carries (µs, ``servo_pulse_us``); the rig passes it to the actuator's
``drive`` (``twin.parts.RigParts.motor_volts_of``), where a hobby servo part turns a pulse width into its target
angle (that part is not this module's). The servo sees a new width at most once per the library's 20 ms
refresh (``REFRESH_INTERVAL``), which the servo part may model.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from twin.interface import CommandRange
from twin.parameters import Parameters, check_group, param, register_group, register_loop_period
from twin.parts.contract import BatchForm, BatchWrite, IoBoardPart, MjcfFragment, register

__all__ = [
    "ADC_CODES",
    "ARDUINO_NANO",
    "ARDUINO_UNO",
    "Arduino",
    "analog_read_counts",
    "i2c_read_time_s",
    "servo_limits_us",
    "servo_pulse_us",
    "servo_range",
    "board_output_range",
    "register_step_dir_actuator",
    "step_target_steps",
]

# ATmega328P data sheet, "Analog-to-Digital Converter": a 10-bit converter, 1024 codes.
ADC_CODES = 1024
# The AVR Servo library (src/avr/Servo.cpp, Servo.h): timer 1 at prescale 8, a 2 µs trim subtracted before the
# conversion to ticks, the attach() limits stored as offsets from 544/2400 µs in 4 µs units.
SERVO_PRESCALE = 8
SERVO_TRIM_US = 2
SERVO_LIMIT_STEP_US = 4
SERVO_DEFAULT_MIN_US = 544  # MIN_PULSE_WIDTH
SERVO_DEFAULT_MAX_US = 2400  # MAX_PULSE_WIDTH
# An I²C register read: START, address+W, register, repeated START, address+R, N bytes, STOP. Each byte is 9 SCL
# periods (8 bits and the acknowledge); START, repeated START and STOP taken as one period each (assumed: the
# I²C specification's set-up and hold times for them are about half a period to one period at 100 kHz).
I2C_BITS_PER_BYTE = 9
I2C_HEADER_BYTES = 3
I2C_CONDITIONS = 3


@dataclass(frozen=True)
class Arduino:
    """An Arduino Uno or Nano (ATmega328P) as the rig's I/O board: its ADC's reference, its servo output's limits,
    its I²C clock and the sketch's loop period."""

    clock_hz: int = param(
        16_000_000,
        "Hz",
        "Arduino Uno R3 and Nano 3.x: a 16 MHz resonator/crystal on the ATmega328P (F_CPU; data sheet: 20 MHz "
        "at most at 4.5–5.5 V)",
        ge=1_000_000,
        le=20_000_000,
        integer=True,
        why="the ATmega328P runs at 1 to 20 MHz; the Servo library needs whole MHz (clockCyclesPerMicrosecond)",
    )
    adc_reference_v: float = param(
        5.0,
        "V",
        "analogReference(DEFAULT): AVcc, the board's 5 V supply (ATmega328P data sheet, ADMUX REFS = 01)",
        ge=1.0,
        le=5.5,
        why="the data sheet's external reference is 1.0 V at least and AVcc at most (5.5 V)",
    )
    servo_min_us: int = param(
        SERVO_DEFAULT_MIN_US,
        "µs",
        "Servo.h MIN_PULSE_WIDTH = 544 µs, the limit attach(pin) sets (arduino-libraries/Servo)",
        ge=SERVO_DEFAULT_MIN_US - 4 * 127,
        le=SERVO_DEFAULT_MIN_US + 4 * 128,
        integer=True,
        why="attach() holds the limit as an int8 offset from 544 µs in 4 µs steps",
    )
    servo_max_us: int = param(
        SERVO_DEFAULT_MAX_US,
        "µs",
        "Servo.h MAX_PULSE_WIDTH = 2400 µs, the limit attach(pin) sets (arduino-libraries/Servo)",
        ge=SERVO_DEFAULT_MAX_US - 4 * 127,
        le=SERVO_DEFAULT_MAX_US + 4 * 128,
        integer=True,
        why="attach() holds the limit as an int8 offset from 2400 µs in 4 µs steps",
    )
    i2c_clock_hz: float = param(
        100_000.0,
        "Hz",
        "the Wire library's default TWI_FREQ, 100 kHz (standard mode): TWBR = 72 at 16 MHz",
        ge=10_000.0,
        le=400_000.0,
        why="the ATmega328P's TWI runs up to 400 kHz (fast mode); below 10 kHz the I²C specification's devices "
        "may time out",
    )
    loop_period_s: float = param(
        0.02,
        "s",
        "assumed: a 50 Hz control loop, the thesis's period and the Servo library's 20 ms refresh",
        ge=0.001,
        le=1.0,
        why="an analogRead takes about 0.1 ms and a servo frame 20 ms: loops of 1 ms to 1 s",
    )

    def __post_init__(self) -> None:
        # the limits' bounds (36 … 1056 µs, 1892 … 2912 µs) keep the minimum below the maximum
        check_group(self, "arduino")


register_group("arduino", Arduino)
register_loop_period("arduino_uno", "arduino.loop_period_s")
register_loop_period("arduino_nano", "arduino.loop_period_s")


def analog_read_counts(volts: float | np.ndarray, reference_v: float | np.ndarray) -> float | np.ndarray:
    """``analogRead``: ⌊V·1024/V_ref⌋ clipped to 0 … 1023 (ATmega328P data sheet, "ADC Conversion Result"; a pin
    below GND reads 0, at or above V_ref reads 1023), as a float (one float in, one float out; arrays
    elementwise, the same bits)."""
    if np.ndim(volts) == 0 and np.ndim(reference_v) == 0:
        if not math.isfinite(float(volts)):
            raise ValueError(f"volts = {volts!r}: an analog pin's volts must be finite")
        code = math.floor(float(volts) * ADC_CODES / float(reference_v))
        return float(min(max(code, 0), ADC_CODES - 1))
    codes = np.floor(np.asarray(volts, dtype=float) * ADC_CODES / reference_v)
    return np.clip(codes, 0.0, ADC_CODES - 1.0)


def servo_limits_us(group: Arduino) -> tuple[int, int]:
    """The clamp ``writeMicroseconds`` applies (``SERVO_MIN()``, ``SERVO_MAX()``): 544 − 4·min8, 2400 − 4·max8 with
    ``attach``'s offsets min8 = (544 − min)/4, max8 = (2400 − max)/4 in C integer division (toward zero)."""
    min8 = int((SERVO_DEFAULT_MIN_US - group.servo_min_us) / SERVO_LIMIT_STEP_US)
    max8 = int((SERVO_DEFAULT_MAX_US - group.servo_max_us) / SERVO_LIMIT_STEP_US)
    return (
        SERVO_DEFAULT_MIN_US - SERVO_LIMIT_STEP_US * min8,
        SERVO_DEFAULT_MAX_US - SERVO_LIMIT_STEP_US * max8,
    )


def servo_pulse_us(command_us: float | np.ndarray, group: Arduino) -> float | np.ndarray:
    """The pulse width the servo pin carries for ``writeMicroseconds(command)`` (AVR Servo library): the command
    truncated to an ``int`` and clamped to ``servo_limits_us``; ticks = ⌊(F_CPU/1 MHz)·(value − 2)/8⌋ of timer 1;
    the pulse is ticks·8/(F_CPU/1 MHz) + 2 µs (the library's trim taken as the interrupt's exact latency).
    At 16 MHz that is the clamped whole microseconds."""
    lo, hi = servo_limits_us(group)
    cycles_per_us = group.clock_hz // 1_000_000  # clockCyclesPerMicrosecond(): integer division
    if np.ndim(command_us) == 0:
        if math.isnan(float(command_us)):
            raise ValueError("command_us = nan: writeMicroseconds takes a number of microseconds")
        value = math.trunc(min(max(float(command_us), lo), hi))  # clamping first: the same int for any float
        ticks = (cycles_per_us * (value - SERVO_TRIM_US)) // SERVO_PRESCALE
        return ticks * SERVO_PRESCALE / cycles_per_us + SERVO_TRIM_US
    return _pulses_us(
        np.asarray(command_us, dtype=float), np.array(lo), np.array(hi), np.array(cycles_per_us)
    )


def _pulses_us(
    command_us: np.ndarray, lo: np.ndarray, hi: np.ndarray, cycles_per_us: np.ndarray
) -> np.ndarray:
    """``servo_pulse_us`` on arrays (each element its own limits and clock): the batch form's."""
    values = np.trunc(np.clip(command_us, lo, hi)).astype(np.int64)
    ticks = (cycles_per_us * (values - SERVO_TRIM_US)) // SERVO_PRESCALE
    return np.asarray(ticks * SERVO_PRESCALE / cycles_per_us + SERVO_TRIM_US, dtype=float)


def i2c_read_time_s(n_bytes: int, clock_hz: float) -> float:
    """How long an I²C register read of ``n_bytes`` takes at ``clock_hz``: (9·(3 + N) + 3) SCL periods (address
    and register bytes, the repeated address, N data bytes, each 8 bits and an acknowledge; START, repeated
    START and STOP one period each). Two bytes (an AS5600's angle) at 100 kHz: 0.48 ms."""
    if n_bytes < 0:
        raise ValueError(f"n_bytes = {n_bytes!r}: a read has 0 or more bytes")
    periods = I2C_BITS_PER_BYTE * (I2C_HEADER_BYTES + n_bytes) + I2C_CONDITIONS
    return periods / clock_hz


def _adc(params: Parameters) -> Callable[[float], float]:
    reference_v = params.of(Arduino).adc_reference_v

    def read(volts: float) -> float:
        return float(analog_read_counts(volts, reference_v))

    return read


def _dac(params: Parameters) -> Callable[[float], float]:
    step_dir = _STEP_DIR_ACTUATORS.get(params.parts.actuator)
    if step_dir is not None:  # a STEP/DIR driver's actuator: the sketch's moveTo target (microsteps)
        limit = step_dir(params).high

        def move_to(command_steps: float) -> float:
            return float(step_target_steps(command_steps, limit))

        return move_to
    group = params.of(Arduino)

    def write(command_us: float) -> float:
        return float(servo_pulse_us(command_us, group))

    return write


def _batch_adc(params: Sequence[Parameters]) -> BatchWrite:
    """``analogRead`` of N boards (``analog_read_counts`` on arrays, each run's reference): ``_adc``'s bits."""
    references = np.array([p.of(Arduino).adc_reference_v for p in params])

    def read(runs: np.ndarray, volts: np.ndarray) -> np.ndarray:
        v = np.asarray(volts, dtype=float)
        if not np.isfinite(v).all():
            raise ValueError(f"volts = {v[~np.isfinite(v)][0]!r}: an analog pin's volts must be finite")
        return np.asarray(analog_read_counts(v, references[runs]))

    return read


def _batch_dac(params: Sequence[Parameters]) -> BatchWrite:
    """``writeMicroseconds`` of N boards (``servo_pulse_us`` on arrays, each run's limits and clock), or for a
    STEP/DIR actuator's rig the ``moveTo`` target (``step_target_steps`` on arrays): ``_dac``'s bits."""
    actuators = {p.parts.actuator for p in params}
    if len(actuators) > 1:  # runs of other rigs (a batch runs one rig's): each run its own board's write
        each = [_dac(p) for p in params]

        def write_each(runs: np.ndarray, command: np.ndarray) -> np.ndarray:
            return np.array(
                [each[i](c) for i, c in zip(runs.tolist(), np.asarray(command).tolist(), strict=True)]
            )

        return write_each
    step_dir = _STEP_DIR_ACTUATORS.get(params[0].parts.actuator)
    if step_dir is not None:
        travel = np.array([step_dir(p).high for p in params])

        def move_to(runs: np.ndarray, command_steps: np.ndarray) -> np.ndarray:
            c = np.asarray(command_steps, dtype=float)
            if np.isnan(c).any():
                raise ValueError("command_steps = nan: moveTo takes a number of microsteps")
            # + 0.0: a C long has no −0 (math.trunc's int), np.trunc(−0.5) is −0.0
            return np.trunc(np.minimum(np.maximum(c, -travel[runs]), travel[runs])) + 0.0

        return move_to
    groups = [p.of(Arduino) for p in params]
    limits = np.array([servo_limits_us(g) for g in groups], dtype=float)
    cycles = np.array([g.clock_hz // 1_000_000 for g in groups], dtype=np.int64)

    def write(runs: np.ndarray, command_us: np.ndarray) -> np.ndarray:
        c = np.asarray(command_us, dtype=float)
        if np.isnan(c).any():
            raise ValueError("command_us = nan: writeMicroseconds takes a number of microseconds")
        return _pulses_us(c, limits[runs, 0], limits[runs, 1], cycles[runs])

    return write


def servo_range(params: Parameters) -> CommandRange:
    """The board's output range (``IoBoardPart.output_range``): the pulse widths ``writeMicroseconds`` puts out,
    ``servo_limits_us`` (544 … 2400 µs by default); a command outside is clamped to them."""
    low, high = servo_limits_us(params.of(Arduino))
    return CommandRange(
        float(low),
        float(high),
        "µs",
        "arduino.servo_min_us … arduino.servo_max_us",
        "the servo pulse's range",
    )


# --- STEP/DIR output: the board drives a stepper's driver instead of a servo (``twin.parts.stepper``) ----------
# The actuators whose board output is a STEP/DIR driver's target, each with its output range (registered by the
# actuator's module): the sketch's moveTo(long) target in microsteps, not a servo pulse.
_STEP_DIR_ACTUATORS: dict[str, Callable[[Parameters], CommandRange]] = {}


def register_step_dir_actuator(name: str, output_range: Callable[[Parameters], CommandRange]) -> None:
    """The actuator ``name`` takes the board's output as a STEP/DIR target (microsteps, within
    ``output_range(params)``): a rig with it gets ``step_target_steps`` in place of the servo pulse."""
    _STEP_DIR_ACTUATORS[name] = output_range


def step_target_steps(command_steps: float, limit_steps: float) -> float:
    """The target the sketch hands AccelStepper's ``moveTo(long)``: the command clamped to ±``limit_steps`` (the
    sketch's travel) and converted to a C ``long`` (truncated toward zero), as a float."""
    if math.isnan(float(command_steps)):
        raise ValueError("command_steps = nan: moveTo takes a number of microsteps")
    return float(math.trunc(min(max(float(command_steps), -limit_steps), limit_steps)))


def board_output_range(params: Parameters) -> CommandRange:
    """The board's output range (``IoBoardPart.output_range``): the STEP/DIR target's for a stepper's rig
    (``register_step_dir_actuator``), else the servo pulse's (``servo_range``)."""
    step_dir = _STEP_DIR_ACTUATORS.get(params.parts.actuator)
    return servo_range(params) if step_dir is None else step_dir(params)


# --- the batch form: analogRead and the servo pulse over N boards at once ------------------------------------
def _inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    references = rng.uniform(3.0, 5.5, n)
    low = rng.integers(SERVO_DEFAULT_MIN_US - 200, SERVO_DEFAULT_MIN_US + 200, n)
    clocks = (rng.choice([8, 16], n) * 1_000_000).tolist()
    params = [
        Parameters().with_overrides(
            {
                "arduino.adc_reference_v": float(ref),
                "arduino.servo_min_us": int(lo),
                "arduino.clock_hz": clock,
            }
        )
        for ref, lo, clock in zip(references.tolist(), low.tolist(), clocks, strict=True)
    ]
    # volts past both ends of the ADC; commands past both clamps, fractional
    return params, np.column_stack([rng.uniform(-1.0, 6.0, n), rng.uniform(200.0, 2800.0, n)])


def _single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One board's per-tick reading and write (``adc``, ``dac_writer``)."""
    return np.array([_adc(params)(float(row[0])), _dac(params)(float(row[1]))])


def _batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every board at once: ``analog_read_counts`` and ``servo_pulse_us`` on arrays, each board's constants."""
    groups = [p.of(Arduino) for p in params]
    counts = analog_read_counts(rows[:, 0], np.array([g.adc_reference_v for g in groups]))
    limits = np.array([servo_limits_us(g) for g in groups], dtype=float)
    cycles = np.array([g.clock_hz // 1_000_000 for g in groups], dtype=np.int64)
    return np.column_stack([counts, _pulses_us(rows[:, 1], limits[:, 0], limits[:, 1], cycles)])


_BATCH = BatchForm(_single, _batch, _inputs, "twin.parts.arduino.analog_read_counts")
_EQUATIONS = (analog_read_counts, servo_limits_us, servo_pulse_us, servo_range, i2c_read_time_s)
_SOURCE = (
    "ATmega328P data sheet (ADC: 10 bits, ADC = V_IN·1024/V_REF; TWI bit rate); arduino-libraries/Servo "
    "src/avr/Servo.cpp (writeMicroseconds: 544…2400 µs clamp, timer 1 at prescale 8, 2 µs trim); Wire 100 kHz"
)


def _volts_of(params: Parameters) -> Callable[[float], float]:
    """The software's conversion of ``analogRead``'s counts to volts: (counts + ½)·V_ref/1024, the middle of the
    code's step."""
    reference = params.of(Arduino).adc_reference_v
    return lambda counts: (counts + 0.5) * reference / ADC_CODES


def _board(name: str, source: str) -> IoBoardPart:
    """An ATmega328P board at 16 MHz and 5 V: the Uno and the Nano are one front end under two names."""
    return register(
        IoBoardPart(
            name=name,
            source=f"{source} {_SOURCE}",
            groups={"arduino": Arduino},
            equations=_EQUATIONS,
            mjcf=MjcfFragment(),
            batch=_BATCH,
            dac_writer=_dac,
            adc=_adc,
            output_range=board_output_range,
            batch_dac=_batch_dac,
            batch_adc=_batch_adc,
            volts_of=_volts_of,
            adc_unit="counts",  # analogRead's 0 … 1023
        )
    )


ARDUINO_UNO = _board("arduino_uno", "Arduino Uno R3: ATmega328P at 16 MHz, 5 V.")
ARDUINO_NANO = _board(
    "arduino_nano", "Arduino Nano 3.x: the Uno's ATmega328P at 16 MHz, 5 V, on a smaller board."
)
