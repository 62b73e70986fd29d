"""The Arduino Uno and Nano as I/O boards (twin.parts.arduino): analogRead against the ATmega328P data sheet's
ADC = ⌊V·1024/V_ref⌋, the Servo library's writeMicroseconds (its clamp, its 4 µs limits, its timer's ticks), the
I²C read's duration, the group's refusals, the batch form and the parts' contract."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.test_parts import _check_part
from twin.parameters import ParameterError, Parameters
from twin.parts import part_named, registered
from twin.parts.arduino import (
    ARDUINO_NANO,
    ARDUINO_UNO,
    Arduino,
    analog_read_counts,
    i2c_read_time_s,
    servo_limits_us,
    servo_pulse_us,
)
from twin.rigs.sim import SimRig

UNO = Parameters().with_overrides({"parts.io_board": "arduino_uno"})


@pytest.mark.quick
def test_analog_read_of_known_volts_on_the_5v_reference() -> None:
    adc = ARDUINO_UNO.adc(UNO)
    lsb = 5.0 / 1024  # 4.8828125 mV, exact in binary
    # the data sheet's ends: GND reads 0x000, V_ref minus one LSB reads 0x3FF; V_ref and above stay at 1023
    assert adc(0.0) == 0.0
    assert adc(5.0) == 1023.0
    assert adc(5.0 - lsb) == 1023.0
    assert adc(5.0 - 1.5 * lsb) == 1022.0
    assert adc(7.0) == 1023.0 and adc(-0.3) == 0.0  # beyond the rails: clipped, no wrap
    # mid-scale: 2.5 V is exactly code 512; a hair below is 511 (floor, not round)
    assert adc(2.5) == 512.0
    assert adc(2.5 - 1e-9) == 511.0
    assert adc(lsb) == 1.0 and adc(0.999 * lsb) == 0.0
    # 1.35 V: 1.35·1024/5 = 276.48 → 276; 3.65 V → 747.52 → 747
    assert adc(1.35) == 276.0 and adc(3.65) == 747.0


@pytest.mark.quick
def test_analog_read_on_another_reference_and_on_arrays() -> None:
    # a 3.3 V reference: 1.65 V is half of it, 512
    assert analog_read_counts(1.65, 3.3) == 512.0
    volts = np.array([-1.0, 0.0, 1.0, 2.5, 4.99, 5.0, 9.0])
    expected = [0, 0, 204, 512, 1021, 1023, 1023]  # ⌊V·204.8⌋: 204.8, 1021.952
    assert np.asarray(analog_read_counts(volts, 5.0)).tolist() == expected
    with pytest.raises(ValueError, match="must be finite"):
        analog_read_counts(math.nan, 5.0)


@pytest.mark.quick
def test_servo_pulse_quantization_and_the_librarys_default_clamp() -> None:
    write = ARDUINO_UNO.dac_writer(UNO)
    # writeMicroseconds(int): the command truncated to whole µs (timer ticks of 0.5 µs at 16 MHz carry them exactly)
    assert write(1500.0) == 1500.0
    assert write(1500.99) == 1500.0
    assert write(1234.5) == 1234.0
    # Servo.h's MIN_PULSE_WIDTH 544 and MAX_PULSE_WIDTH 2400 (attach(pin)'s limits)
    assert write(543.0) == 544.0 and write(0.0) == 544.0 and write(-100.0) == 544.0
    assert write(2400.0) == 2400.0 and write(2400.9) == 2400.0 and write(3000.0) == 2400.0
    assert write(math.inf) == 2400.0
    with pytest.raises(ValueError, match="nan"):
        write(math.nan)
    # one µs apart stays one µs apart: the resolution is 1 µs, not the 4 µs often quoted
    assert write(1501.0) - write(1500.0) == 1.0


@pytest.mark.quick
def test_the_attach_limits_are_held_in_4us_steps_and_a_slower_clock() -> None:
    # attach(pin, 1001, 1999): (544 − 1001)/4 = −114.25 → −114 (C truncates), 544 + 456 = 1000;
    # (2400 − 1999)/4 = 100.25 → 100, 2400 − 400 = 2000
    group = Arduino(servo_min_us=1001, servo_max_us=1999)
    assert servo_limits_us(group) == (1000, 2000)
    assert servo_pulse_us(900.0, group) == 1000.0 and servo_pulse_us(2100.0, group) == 2000.0
    # 8 MHz (a 3.3 V board): 1 tick = 1 µs, ticks = 8·(v − 2)/8 = v − 2, pulse = v − 2 + 2 = v
    slow = Arduino(clock_hz=8_000_000)
    assert servo_pulse_us(1501.7, slow) == 1501.0
    pulses = servo_pulse_us(np.array([100.0, 1500.5, 9999.0]), Arduino())
    assert np.asarray(pulses).tolist() == [544.0, 1500.0, 2400.0]


@pytest.mark.quick
def test_i2c_read_time_at_the_wire_librarys_clock() -> None:
    # two bytes (an AS5600 angle): address, register, address again and 2 data bytes = 5 bytes of 9 clocks,
    # plus START, repeated START and STOP: 48 clocks at 100 kHz = 0.48 ms
    assert i2c_read_time_s(2, Arduino().i2c_clock_hz) == pytest.approx(48 / 100_000, rel=1e-15)
    assert i2c_read_time_s(6, 400_000.0) == pytest.approx((9 * 9 + 3) / 400_000, rel=1e-15)
    with pytest.raises(ValueError):
        i2c_read_time_s(-1, 100_000.0)


@pytest.mark.quick
def test_the_group_refuses_impossible_boards_naming_the_field() -> None:
    with pytest.raises(ParameterError, match=r"arduino\.adc_reference_v = 6\.0 V is impossible"):
        Parameters().with_overrides({"arduino.adc_reference_v": 6.0})
    # attach() holds each limit as an int8 offset in 4 µs steps: 544 + 4·128 = 1056 µs at most
    with pytest.raises(
        ParameterError, match=r"arduino\.servo_min_us = 2000 µs is impossible: it must be <= 1056"
    ):
        Parameters().with_overrides({"arduino.servo_min_us": 2000})
    with pytest.raises(ParameterError, match=r"arduino\.servo_max_us = 3000 µs is impossible"):
        Parameters().with_overrides({"arduino.servo_max_us": 3000})
    assert Arduino().loop_period_s == 0.02 and Arduino().i2c_clock_hz == 100_000.0
    p = Parameters().with_overrides({"arduino.loop_period_s": 0.01})
    assert p.of(Arduino).loop_period_s == 0.01 and p.changed() == {"arduino.loop_period_s": 0.01}


@pytest.mark.quick
@pytest.mark.parametrize("part", [ARDUINO_UNO, ARDUINO_NANO], ids=lambda p: p.name)
def test_the_boards_keep_the_parts_contract_and_batch_equals_single(part) -> None:
    assert part in registered("io_board") and part_named("io_board", part.name) is part
    _check_part(part, seed=42, own_home=False)  # their equations' home is their module (see the report)
    assert all(eq.__module__ == "twin.parts.arduino" for eq in part.equations)
    assert part.batch.difference(np.random.default_rng(7), 200) == 0.0
    assert part.groups == {"arduino": Arduino}


@pytest.mark.quick
def test_a_board_named_by_the_parameters_reads_through_its_reference() -> None:
    nano = Parameters().with_overrides({"parts.io_board": "arduino_nano", "arduino.adc_reference_v": 4.096})
    adc = part_named("io_board", nano.parts.io_board).adc(nano)  # type: ignore[attr-defined]
    assert adc(2.048) == 512.0 and adc(1.0) == 250.0  # 1.0·1024/4.096 = 250 exactly


@pytest.mark.quick
def test_the_boards_output_range_is_the_servo_clamp_and_the_rig_takes_it() -> None:
    rng = ARDUINO_NANO.output_range(Parameters().with_overrides({"arduino.servo_min_us": 1001}))
    assert (rng.low, rng.high, rng.unit) == (1000.0, 2400.0, "µs")  # attach()'s 4 µs steps, as above
    assert "arduino.servo_min_us" in rng.text() and "1000.0 … 2400.0 µs" in rng.text()
    rig = SimRig(UNO.with_overrides({"parts.angle_sensor": "none"}), seed=0)
    assert rig.command_range() == ARDUINO_UNO.output_range(UNO)
