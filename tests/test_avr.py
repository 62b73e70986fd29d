"""The firmware on a simulated ATmega328P (examples/avr, twin/avr): it is built from the PC client's law source
with avr-gcc, knows the rig's calibration the twin holds, boots and writes the DAC every period at the timer's
exact cycles, and computes what the same law compiled for the host in single precision computes, bit for bit.

Needs Debian's gcc-avr, avr-libc and libsimavr-dev (``.ci/run`` installs them); skipped, saying so, without."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from avr_images import build_image, example_image, host_law

from twin.app.firmware_forms import host_words
from twin.parameters import Parameters

ROOT = Path(__file__).resolve().parents[1]
AVR_DIR = ROOT / "examples" / "avr"
C_DIR = ROOT / "examples" / "c"
F_CPU = 16_000_000
PERIOD_CYCLES = F_CPU // 50  # Timer1 in CTC mode at F_CPU / 64, 5000 counts: 20 ms


def _defines() -> dict[str, float]:
    text = (AVR_DIR / "rig.h").read_text()
    return {m[1]: float(m[2]) for m in re.finditer(r"^#define (\w+) ([-+0-9.eE]+)\s*$", text, re.M)}


@pytest.mark.quick
def test_the_firmware_knows_the_rigs_software_calibration_and_its_board() -> None:
    """Every number of the rig software's calibration in examples/avr/rig.h is the twin's
    (twin.parameters.SoftwareCalibration), and so are the period and the board's front end, ADC and DAC
    (twin.parameters.McuIo)."""
    d, p = _defines(), Parameters()
    s, io = p.software, p.mcu_io
    for name, value in {
        "RIG_BALL_GAIN_M_PER_V": s.ball_gain_m_per_v,
        "RIG_BALL_OFFSET_M": s.ball_offset_m,
        "RIG_ANGLE_GAIN_DEG_PER_V": s.angle_gain_deg_per_v,
        "RIG_ANGLE_REFERENCE_V": s.angle_reference_v,
        "RIG_ANGLE_REFERENCE_MOTOR_DEG": s.angle_reference_motor_deg,
        "RIG_ANGLE_GEAR_RATIO": s.angle_gear_ratio,
        "RIG_SOFTWARE_PI": s.software_pi,
        "RIG_COMMAND_GAIN_V_PER_V": s.command_gain_v_per_v,
        "RIG_COMMAND_ZERO_V": s.command_zero_v,
        "RIG_COMMAND_LOW_V": s.command_low_v,
        "RIG_COMMAND_HIGH_V": s.command_high_v,
        "RIG_PERIOD_S": p.daq.period_s,
        "IO_INPUT_GAIN_V_PER_V": io.input_gain_v_per_v,
        "IO_INPUT_OFFSET_V": io.input_offset_v,
        "IO_ADC_REFERENCE_V": io.adc_reference_v,
        "IO_ADC_BITS": io.adc_bits,
        "IO_DAC_BITS": io.dac_bits,
        "IO_DAC_REFERENCE_V": io.dac_reference_v,
    }.items():
        assert d[name] == value, name
    make = (AVR_DIR / "Makefile").read_text()
    assert re.search(r"^F_CPU \?= (\d+)$", make, re.M)[1] == str(io.clock_hz)  # type: ignore[index]


@pytest.fixture(scope="module")
def firmware(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return example_image(tmp_path_factory.mktemp("avr"))


def _core(firmware: Path):  # type: ignore[no-untyped-def]
    from twin.avr.core import AvrCore, AvrUnavailable

    try:
        return AvrCore(firmware)
    except AvrUnavailable as exc:
        pytest.skip(str(exc))


def _drive(firmware: Path, inputs_mv: np.ndarray) -> list[tuple[int, int]]:
    """Hold each period's (ball, angle) pin millivolts from 1000 cycles before its interrupt; the frames."""
    frames = []
    with _core(firmware) as core:
        for k, (ball, angle) in enumerate(inputs_mv, start=1):
            frames += core.run_until(k * PERIOD_CYCLES - 1000).frames
            core.set_adc_v(0, float(ball) / 1000)
            core.set_adc_v(1, float(angle) / 1000)
        frames += core.run_until((len(inputs_mv) + 1) * PERIOD_CYCLES).frames
    return [(f.word, f.cycle) for f in frames]


@pytest.mark.quick
def test_the_firmware_boots_and_writes_the_dac_every_period(firmware: Path) -> None:
    """The zero command (2.5 V: code 2048) at reset, then one frame per timer interrupt, each within the period
    of its interrupt; the stack stays far from the data; the same run twice is the same bits."""
    inputs = np.tile([[3497.0, 2212.0]], (10, 1))
    frames = _drive(firmware, inputs)
    assert frames[0][0] == 0x3000 | 2048 and frames[0][1] < PERIOD_CYCLES
    ticks = frames[1:]
    assert len(ticks) == len(inputs)
    for k, (_, cycle) in enumerate(ticks, start=1):
        assert k * PERIOD_CYCLES < cycle < (k + 1) * PERIOD_CYCLES
    assert all(word >> 12 == 0x3 for word, _ in frames)  # DAC A, unbuffered, gain 1, active
    assert frames == _drive(firmware, inputs)
    with _core(firmware) as core:
        report = core.run_until(3 * PERIOD_CYCLES)
        assert (
            report.state in (2, 3)
            and report.resets == 0
            and report.bad_frames == 0
            and report.dropped_frames == 0
        )
        assert core.ramend == 0x8FF and core.data_end < report.stack_low_water < core.ramend


def test_the_firmware_computes_the_host_single_precision_law_bit_for_bit(
    firmware: Path, tmp_path: Path
) -> None:
    """200 periods of changing pin voltages: the counts the firmware converts are the datasheet's,
    ⌊V·1024 / 5 V⌋ (twin.avr.core scales simavr's ·1023 to it), eight per channel; the same sums through the
    host build give the firmware's DAC frames, every one."""
    rng = np.random.default_rng(7)
    ball = 2500 + np.round(1200 * np.sin(np.arange(200) / 9.0)) + rng.integers(-40, 40, 200)
    angle = 2500 + np.round(600 * np.cos(np.arange(200) / 13.0)) + rng.integers(-40, 40, 200)
    frames = _drive(firmware, np.stack([ball, angle], axis=1))
    counts = np.floor(np.stack([ball, angle], axis=1) * 1024 / 5000).astype(int) * 8
    expected = host_words(host_law(tmp_path), [(int(b), int(a)) for b, a in counts])
    got = [word for word, _ in frames[1:]]
    assert len(set(got)) > 50  # the commands move: the law is exercised, not pinned at a rail
    assert got == expected


# --- hostile firmware: the core reports what it did, and never takes the twin with it ---------------------
HOSTILE = {
    "isr_loop": "#include <avr/io.h>\n#include <avr/interrupt.h>\nISR(TIMER1_COMPA_vect) { for (;;) { } }\n"
    "int main(void) { TCCR1B = (1 << WGM12) | (1 << CS11) | (1 << CS10); OCR1A = 4999;"
    " TIMSK1 = (1 << OCIE1A); sei(); for (;;) { } }\n",
    "stack": "#include <stdint.h>\nvolatile uint8_t sink;\n"
    "static uint8_t deep(uint8_t n) { volatile uint8_t pad[16]; pad[0] = n; return deep(n + 1) + pad[0]; }\n"
    "int main(void) { sink = deep(0); for (;;) { } }\n",
    "reset": "#include <avr/wdt.h>\nint main(void) { wdt_enable(WDTO_15MS); for (;;) { } }\n",
    "stop": "#include <avr/interrupt.h>\n#include <avr/sleep.h>\n"
    "int main(void) { cli(); set_sleep_mode(SLEEP_MODE_PWR_DOWN); sleep_enable(); sleep_cpu(); for (;;) { } }\n",
}


def _hostile(name: str, tmp: Path) -> Path:
    return build_image(name, HOSTILE[name], tmp)


def _ten_periods(elf: Path):  # type: ignore[no-untyped-def]
    from twin.avr.core import STATE_CRASHED, STATE_DONE, STATE_STACK_OVERFLOW

    frames = []
    with _core(elf) as core:
        for k in range(1, 11):
            report = core.run_until(k * PERIOD_CYCLES)
            frames += report.frames
            if report.state in (STATE_DONE, STATE_CRASHED, STATE_STACK_OVERFLOW):
                break
    return report, frames


@pytest.mark.quick
def test_hostile_firmware_is_reported_by_the_core(tmp_path: Path) -> None:
    """An interrupt that never returns writes nothing (the core runs on, the host sees no frame); a recursion
    takes the stack into the static data (stopped at once, the static data's end from the ELF's symbols); a
    watchdog that is never fed resets the core every 15 ms; a sleep with interrupts off stops it."""
    from twin.avr.core import STATE_DONE, STATE_STACK_OVERFLOW, data_end

    report, frames = _ten_periods(_hostile("isr_loop", tmp_path))
    assert frames == [] and report.cycle >= 10 * PERIOD_CYCLES and report.state in (2, 3)
    elf = _hostile("stack", tmp_path)
    report, _ = _ten_periods(elf)
    assert report.state == STATE_STACK_OVERFLOW and report.stack_low_water < data_end(elf)
    report, _ = _ten_periods(_hostile("reset", tmp_path))
    assert 10 <= report.resets <= 14  # 200 ms of a 15 ms watchdog (its oscillator's nominal period)
    report, _ = _ten_periods(_hostile("stop", tmp_path))
    assert report.state == STATE_DONE and report.cycle < PERIOD_CYCLES


@pytest.mark.quick
def test_a_co_simulation_that_dies_is_an_error_not_a_crash_of_the_twin(firmware: Path) -> None:
    from twin.avr.core import AvrError

    core = _core(firmware)
    assert core._proc is not None
    core._proc.kill()
    with pytest.raises(AvrError, match="the co-simulation ended"):
        core.run_until(PERIOD_CYCLES)
    core.close()
    with pytest.raises(AvrError, match="no such firmware image"):
        _core(Path("/nonexistent.elf"))


ADC_PROBE = (
    "#include <avr/io.h>\n#include <stdint.h>\n"
    "int main(void) { DDRB |= (1 << PB2) | (1 << PB3) | (1 << PB5); PORTB |= (1 << PB2);"
    " SPCR = (1 << SPE) | (1 << MSTR); ADCSRA = (1 << ADEN) | 7;\n"
    " for (;;) { ADMUX = (1 << REFS0); ADCSRA |= (1 << ADSC); while (ADCSRA & (1 << ADSC)) { } uint16_t v = ADC;\n"
    "  PORTB &= ~(1 << PB2); SPDR = v >> 8; while (!(SPSR & (1 << SPIF))) { }"
    " SPDR = v & 0xFF; while (!(SPSR & (1 << SPIF))) { } PORTB |= (1 << PB2); } }\n"
)


@pytest.mark.quick
def test_the_simulated_adc_reads_the_datasheets_counts(tmp_path: Path) -> None:
    """A probe firmware sends each conversion of ADC0 over SPI. At and just below every count's edge
    (n·V_ref/1024) and at the ends, the count is ⌊V·1024 / V_ref⌋ within 0…1023 — the datasheet's, not simavr's
    own ⌊mV·1023 / V_ref⌋ (twin.avr.core.ADC_SCALE)."""
    elf = build_image("adc_probe", ADC_PROBE, tmp_path)
    volts = [0.0, 5.0, 5.2, 4.99999]
    for n in (1, 2, 511, 512, 716, 1022, 1023):
        volts += [n * 5.0 / 1024, n * 5.0 / 1024 - 1e-6]
    with _core(elf) as core:
        for i, v in enumerate(volts):
            core.set_adc_v(0, v)
            frames = core.run_until((i + 1) * 20_000).frames
            assert frames[-1].word == min(math.floor(min(v, 5.0) * 1024 / 5.0), 1023), v
