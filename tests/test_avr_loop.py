"""The firmware in the loop (twin.avr.firmware, SimRig.read_with_firmware): examples/avr's image on a simulated
ATmega328P drives the twin, its pins fed the sensor chain's signals every physics step. It holds the ball from
the hardware start, repeats bit for bit, computes what the host's single-precision build of the same law
computes from the ADC results it read in the run, and reports its timing and stack; every hostile firmware fails
its run with a message naming the cycle, the time and the tick.

Needs Debian's gcc-avr, avr-libc and libsimavr-dev (``.ci/run`` installs them); skipped, saying so, without."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from avr_images import F_CPU, board_image, example_image, host_law

from twin.app.firmware_forms import host_words, period_inputs
from twin.avr.firmware import AvrFirmware
from twin.engine import ControllerError, RunResult
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop

PERIOD_CYCLES = F_CPU // 50


@pytest.fixture(scope="module")
def image(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return example_image(tmp_path_factory.mktemp("avr_loop"))


def _firmware(elf: Path, params: Parameters | None = None, record: bool = False) -> AvrFirmware:
    from twin.avr.core import AvrUnavailable

    fw = AvrFirmware(elf, params or Parameters(), record=record)
    try:
        fw.boot(0.0)
    except AvrUnavailable as exc:
        pytest.skip(str(exc))
    fw.close()
    return fw


def _run(elf: Path, duration_s: float = 6.0, seed: int = 0, record: bool = False, **start: float) -> tuple:
    fw = _firmware(elf, record=record)
    result = run_closed_loop(
        fw,
        x0_m=start.get("x0_m", 0.14),
        theta0_rad=start.get("theta0_rad", -0.2),
        duration_s=duration_s,
        seed=seed,
    )
    return result, fw


@pytest.mark.quick
def test_the_firmware_holds_the_ball_from_the_hardware_start_and_repeats_bit_for_bit(image: Path) -> None:
    """From x0 = 0.14 m, θ0 = −0.2 rad (the thesis's hardware start), noise on: held; the same run twice gives
    the same log, bit for bit. The figures: one DAC frame per period (the zero command at boot, then one per
    interrupt), each written within its interrupt (an update's cycles ≤ the longest interrupt's), so the deadline
    margin is the period less the longest; the stack's high-water mark is below the room above the static data."""
    a, fw = _run(image)
    b, _ = _run(image)
    assert a.verdict.held and a.ended == "all ticks"
    for name in ("true_x_m", "true_theta_rad", "motor_volts_v", "datam1", "datam2", "aout"):
        assert np.array_equal(getattr(a.log, name), getattr(b.log, name)), name
    f = a.firmware
    assert f == b.firmware and f["mcu"] == "atmega328p" and f["clock_hz"] == F_CPU
    ticks = len(a.log.datam1)
    assert f["updates"] in (ticks, ticks + 1)  # boot's zero command + one per interrupt within the run
    assert 0 < f["update_cycles_mean"] <= f["update_cycles_max"] <= f["interrupt_max_cycles"] < PERIOD_CYCLES
    assert f["deadline_margin_s"] == pytest.approx((PERIOD_CYCLES - f["update_cycles_max"]) / F_CPU)
    assert f["missed_periods"] == 0
    assert 0 < f["stack_high_water_bytes"] < f["stack_room_bytes"]
    # the core is awake for its interrupts: load ≈ their cycles over the run's
    assert f["load"] == pytest.approx(f["update_cycles_mean"] * f["interrupts"] / (F_CPU * 6.04), rel=0.1)


def test_the_firmwares_words_are_the_host_builds_from_the_adc_results_it_read(
    image: Path, tmp_path: Path
) -> None:
    """Equality where it must hold: every ADC result the firmware read in a closed-loop run (eight per channel
    per interrupt), summed as main.c sums them and fed to the same law compiled for the host in single
    precision, gives the firmware's DAC words, every one."""
    result, fw = _run(image, record=True)
    assert result.verdict.held
    frames = fw.frames[1:]  # the first is main's zero command, before any interrupt
    sums = []
    for inside in period_inputs(frames, fw.conversions):
        assert [c.channel for c in inside] == [0] * 8 + [1] * 8
        sums.append((sum(c.value for c in inside[:8]), sum(c.value for c in inside[8:])))
    got = [f.word for f in frames]
    assert len(set(got)) > 50
    assert got == host_words(host_law(tmp_path), sums)


# --- hostile firmware: each fails its run, saying what happened where -----------------------------------
ZERO = "dac(0x3000 | 2048);"
HOSTILE = {
    # the interrupt hangs at its 10th period
    "isr_loop": ("if (period == 10) for (;;) { } " + ZERO, "", r"stopped writing its DAC.*in an interrupt"),
    # a recursion from the 10th period takes the stack into the static data
    "stack": (
        "if (period == 10) { volatile uint8_t pad[64]; pad[0] = period; period = pad[0] + deep(); } " + ZERO,
        "",
        r"stack overflow into the static data",
    ),
    # a watchdog never fed
    "reset": (ZERO, "wdt_enable(WDTO_60MS);", r"the core reset"),
    # the timer runs, nothing is written
    "silent": ("", "", r"never wrote its DAC"),
    # 8 bits per chip select
    "garbage": ("PORTB &= ~(1 << PB2); SPDR = 0x55; while (!(SPSR & (1 << SPIF))) { } PORTB |= (1 << PB2);", "",
                r"garbage on SPI"),
    # an undefined opcode at the 10th period
    "illegal": ('if (period == 10) __asm__ volatile (".word 0x0001"); ' + ZERO, "", r"Invalid Opcode"),
    # the DAC shut down (SHDN = 0)
    "shutdown": ("dac(0x2000 | 2048);", "", r"shuts the DAC's output down"),
}  # fmt: skip
DEEP = "static uint8_t deep(void);\n"


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_firmware_fails_its_run_naming_the_cycle_time_and_tick(name: str, tmp_path: Path) -> None:
    isr, main, message = HOSTILE[name]
    prefix = (
        DEEP + "static uint8_t deep(void) { volatile uint8_t pad[16]; pad[0] = 1; return deep() + pad[0]; }\n"
        if name == "stack"
        else ""
    )
    elf = board_image(name, isr, tmp_path, main, prefix=prefix)
    fw = _firmware(elf)
    with pytest.raises(ControllerError, match=message) as caught:
        run_closed_loop(fw, x0_m=0.1, theta0_rad=0.0, duration_s=5.0)
    text = str(caught.value)
    assert text.startswith(f"avr:{name}.elf: ") and " at cycle " in text and "tick k = " in text
    found = re.search(r"at cycle (\d+) \(t = ([-0-9.]+) s\)", text)
    assert found is not None  # within the run's time: at most NO_OUTPUT_PERIODS after the 10th period
    assert float(found[2]) == pytest.approx(int(found[1]) / F_CPU - 0.03, abs=1e-4) and float(found[2]) < 0.4
    assert fw._core is None  # the co-simulation's process is closed


@pytest.mark.parametrize("word, volts", [(0x3000, 0.0), (0x3FFF, 4095 * 5 / 4096)])
def test_a_stuck_output_fails_the_run_and_is_named(word: int, volts: float, tmp_path: Path) -> None:
    """A firmware writing one word every period (0 V or full scale at the amplifier's input: its rails) loses
    the ball; the run's diagnosis names the output and how long it stayed."""
    from twin.avr.firmware import stuck_output

    elf = board_image(f"stuck_{word:x}", f"dac(0x{word:04X});", tmp_path)
    result, _ = _run(elf, duration_s=5.0, x0_m=0.1, theta0_rad=0.0)
    assert not result.verdict.held and (result.verdict.ball_lost or result.verdict.hit_stops)
    f = result.firmware
    assert f["distinct_outputs"] == 1 and f["output_v"] == volts
    text = stuck_output(f, 0.02)
    assert text is not None and f"word 0x{word:04X}" in text and f"{volts:.3f} V" in text


@pytest.mark.quick
def test_the_mcp4921_word_is_decoded_as_its_datasheet_says() -> None:
    """Register 5-1: bits 11…0 the code, V = code·V_ref/4096 (gain 1, GA = 1) or twice that (GA = 0) up to the
    supply; bit 15 set: the command is ignored; SHDN = 0: the output is shut down."""
    from twin.avr.firmware import dac_output_v

    io = Parameters().mcu_io
    assert dac_output_v(0x3000 | 2048, io) == 2.5
    assert dac_output_v(0x3000 | 4095, io) == 4095 * 5 / 4096
    assert dac_output_v(0x1000 | 1000, io) == 2 * 1000 * 5 / 4096
    assert dac_output_v(0x1000 | 3000, io) == 5.0
    assert dac_output_v(0xB000 | 100, io) is None
    with pytest.raises(ValueError, match="SHDN"):
        dac_output_v(0x2000 | 100, io)


@pytest.mark.quick
def test_the_pins_see_the_sensor_signals_through_the_boards_front_end(image: Path) -> None:
    """What the firmware converted in the run's first (held) period is the front end's count of the held rig's
    signals: the ball chain at rest (the wiper's static volts at x0) and the angle counter's level at θ0."""
    from twin.sensors import angle_sensor_v, wiper_static_v

    p = Parameters()
    x0, th0 = 0.1, -0.1
    fw = _firmware(image, record=True)
    run_closed_loop(fw, x0_m=x0, theta0_rad=th0, duration_s=0.1, noise=False)
    first = [c for c in fw.conversions if c.cycle < fw.frames[1].cycle]
    io = p.mcu_io
    for channel, signal in (
        (0, float(wiper_static_v(x0, p.ball_sensor))),
        (1, float(angle_sensor_v(th0, p))),
    ):
        count = math.floor((io.input_offset_v + io.input_gain_v_per_v * signal) * 1024 / io.adc_reference_v)
        assert {c.value for c in first if c.channel == channel} == {count}


def test_run_result_carries_no_firmware_figures_for_a_python_controller() -> None:
    from controllers import registry

    r: RunResult = run_closed_loop(registry.make("appendix-sf"), x0_m=0.1, theta0_rad=0.0, duration_s=0.2)
    assert r.firmware is None


@pytest.mark.quick
def test_the_live_view_runs_the_firmware_shows_its_load_and_closes_it(image: Path) -> None:
    """The view (a tick per frame) runs what ``ballbeam run`` runs, bit for bit; its status line gives the
    firmware's load, longest update and stack; Reset replaces the co-simulation (the old process ends)."""
    from twin.app.hosts import catalogue_for
    from twin.engine import update_ticks
    from twin.viewer import LiveTwin

    _firmware(image)  # skips without simavr
    spec = f"avr:{image}"
    p = Parameters()
    live = LiveTwin(p, catalogue_for(spec, p), spec, seed=0, speed=1.0)
    for _ in range(update_ticks(2.0, p)):
        live.tick()
    fw = _firmware(image)
    reference = run_closed_loop(fw, x0_m=live.x0_m, theta0_rad=live.theta0_rad, duration_s=2.0, seed=0)
    np.testing.assert_array_equal(live.loop.log().true_x_m, reference.log.true_x_m)
    status = live.status_markdown()
    f = live.loop.firmware_figures()
    assert (
        f is not None
        and f"load {100 * f['load']:.1f} %" in status
        and f"stack {f['stack_high_water_bytes']} of" in status
    )
    first = live.loop.controller
    assert isinstance(first, AvrFirmware)
    live.apply("reset")
    second = live.loop.controller
    assert first._core is None and isinstance(second, AvrFirmware) and second is not first
    live.close()
    assert second._core is None
