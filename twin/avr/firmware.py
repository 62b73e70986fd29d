"""A firmware image as a controller of the twin: the board between the rig's analog signals and the amplifier.

``AvrFirmware`` implements ``twin.firmware.Firmware``: every physics step the rig hands it the two sensor
signals (the ball chain's RC output and the angle counter's DAC level, in the rig's volts); the board's front
end maps each onto its ADC pin (``mcu_io``; the channels are the board's, ``twin.avr.boards``), the core runs to
the step's end (``AvrCore``), and the SPI frames the firmware latched into its DAC (the board's chip select and
chip: an MCP4921) are the amplifier's command input. The core's clock is the twin's: cycle
c is ``boot_s + c / clock_hz``.

What the target adds to a run's verdict is kept as it runs (``figures``): the cycles from each update's
interrupt to its DAC write, the deadline margin against the rig's period, the stack's high-water mark, the
periods without an output, the core's load. A firmware that crashes, resets, stops, overflows its stack into
its data, writes something other than a DAC frame or nothing at all fails the run (``ControllerError``)
naming the cycle, the time and what happened.
"""

from __future__ import annotations

import hashlib
import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.avr.boards import board_for
from twin.avr.core import (
    NO_ENTRY,
    STATE_CRASHED,
    STATE_DONE,
    STATE_ERROR,
    STATE_SLEEPING,
    STATE_STACK_OVERFLOW,
    AvrCore,
    AvrError,
    Conversion,
    Frame,
    RunReport,
    elf_device,
    elf_sections,
    read_elf,
)
from twin.engine import ControllerError
from twin.firmware import MCP4921
from twin.interface import Telemetry
from twin.parameters import McuIo, Parameters

__all__ = [
    "DEFAULT_MCU",
    "NO_OUTPUT_PERIODS",
    "STUCK_PERIODS",
    "AvrFirmware",
    "dac_output_v",
    "stuck_output",
]

DEFAULT_MCU = "atmega328p"
# A firmware that latches no DAC frame for this many of the rig's periods has stopped driving the rig: the run
# fails there (a hung interrupt, a firmware asleep for good, one that never writes).
NO_OUTPUT_PERIODS = 5
# A failed run whose firmware wrote one word for at least this many periods at its end is said to be stuck.
STUCK_PERIODS = 10


def stuck_output(figures: dict[str, Any], period_s: float) -> str | None:
    """A failed run's diagnosis when the firmware's output had stopped changing: the same word for the run's last
    ``STUCK_PERIODS`` periods or more (a law whose output never moves while the rig falls is stuck); else
    ``None``."""
    unchanged = figures.get("output_unchanged_s", math.nan)
    if not unchanged >= STUCK_PERIODS * period_s:
        return None
    return (
        f"the firmware's output stayed at {figures['output_v']:.3f} V (DAC word 0x{figures['output_word']:04X}) "
        f"for the run's last {unchanged:.2f} s"
    )


def image_spec(rest: str) -> tuple[str, Path]:
    """What follows ``avr:`` in a ``--controller`` value (``FILE.elf`` or ``MCU:FILE.elf``) → (MCU or "", the
    image's path)."""
    mcu, colon, path = rest.partition(":")
    if colon and mcu.isalnum() and mcu.lower().startswith("at"):
        return mcu.lower(), Path(path)
    return "", Path(rest)


def dac_output_v(word: int, io: McuIo) -> float | None:
    """The MCP4921's output for a command word at the front end's resolution and reference
    (``twin.firmware.DacChip.volts``)."""
    return MCP4921.volts(word, int(io.dac_bits), io.dac_reference_v)


@dataclass
class _Updates:
    """The DAC frames of a run, as the figures need them."""

    count: int = 0
    cycles_max: int = 0
    cycles_sum: int = 0
    timed: int = 0  # frames written within an interrupt's reach (since_entry known)
    missed_periods: int = 0
    last_time_s: float = math.nan
    constant_since_s: float = math.nan  # when the output last changed
    constant_longest_s: float = 0.0


class AvrFirmware:
    """One firmware image driving the twin's rig through an Arduino-class board (``mcu_io``; its pins:
    ``board``, the MCU's, ``twin.avr.boards.board_for``)."""

    def __init__(
        self,
        elf: str | Path,
        params: Parameters,
        *,
        mcu: str = "",
        name: str | None = None,
        record: bool = False,
    ) -> None:
        """``record``: keep every DAC frame and ADC result of the run (``frames``, ``conversions``): what the
        firmware saw and wrote, to replay through another build of its law."""
        self._core: AvrCore | None = None
        path = Path(elf)
        raw = read_elf(path)
        # ELF, 32-bit, little-endian, e_machine 83 (EM_AVR)
        if raw[:6] != b"\x7fELF\x01\x01" or raw[18:20] != b"\x53\x00":
            raise AvrError(f"{path}: not an AVR ELF image (build it with avr-gcc)")
        try:
            elf_sections(raw)
        except (struct.error, ValueError):
            raise AvrError(f"{path}: a truncated ELF image ({len(raw)} bytes)") from None
        self.path = path
        device = elf_device(raw)
        if mcu and device and mcu.lower() != device.lower():
            # simavr would run the image on the named core, and its faults would be blamed on the firmware
            raise AvrError(
                f"{path}: built for {device} (its device note, avr-gcc -mmcu={device}), not for {mcu} as "
                f"avr:{mcu}:… names; name {device} or build the image for {mcu}"
            )
        self.mcu = mcu or device or DEFAULT_MCU
        self.board = board_for(self.mcu)
        self.io = params.mcu_io
        self.clock_hz = int(params.mcu_io.clock_hz)
        self.period_s = params.period_s
        self.name = name or f"avr:{path.name}"
        self.sha256 = hashlib.sha256(raw).hexdigest()
        self.telemetry = Telemetry()  # the firmware reports nothing of its estimates
        self._zero_v = params.amplifier.zero_command_v
        self._command_v = self._zero_v
        self.record = record
        self.frames: list[Frame] = []
        self.conversions: list[Conversion] = []
        self._boot_s = 0.0
        self._ramend = self._data_end = 0
        self._report: RunReport | None = None

    # --- the Firmware protocol -------------------------------------------------------------------------
    def boot(self, time_s: float) -> None:
        """Power on: the core leaves reset at ``time_s`` (s from the rig's release)."""
        self.close()
        try:
            self._core = self.core()
        except AvrError as exc:
            raise ControllerError(f"{self.name}: {exc}") from None
        self._boot_s = time_s
        self._ramend, self._data_end = self._core.ramend, self._core.data_end  # the figures outlive the core
        self._report = None
        self._units: dict[
            int, bytes
        ] = {}  # each ADC channel's last request (sent again only when it changes)
        self._command_v = self._zero_v  # assumed: the motor off until the firmware's first frame (held then)
        self._last_word = -1
        self._words: set[int] = set()
        self._updates = _Updates()
        self._now_cycle = 0
        self._asleep_until = -1  # the core's cycle when a run ended with it asleep beyond its target
        self.frames, self.conversions = [], []

    def pins(
        self, time_s: float, ball_signal_v: float, angle_signal_v: float, until_s: float
    ) -> list[tuple[float, float]]:
        """The sensor signals from ``time_s`` to ``until_s``; the board's output over that span as (fraction of
        the span, command volts) pieces, in order (the frames latched in it switch it)."""
        core = self._core
        if core is None:
            raise ControllerError(f"{self.name}: pins before boot")
        io = self.io
        start = self._now_cycle
        end = self._now_cycle = round((until_s - self._boot_s) * self.clock_hz)
        if self._asleep_until >= end:
            # The core sleeps through this step (simavr ran it ahead to the event that wakes it): nothing in it
            # reads a pin or writes the DAC, so the step needs no request; the pins go with the run that wakes it.
            self._check_output(until_s)
            return [(1.0, self._command_v)]
        before = b""
        board = self.board
        for channel, signal_v in ((board.ball_channel, ball_signal_v), (board.angle_channel, angle_signal_v)):
            request = core.adc_request(channel, io.input_offset_v + io.input_gain_v_per_v * signal_v)
            if request != self._units.get(channel):
                before += request
                self._units[channel] = request
        try:
            report = core.run_until(end, before)
        except AvrError as exc:
            raise ControllerError(f"{self.name}: {exc} at t = {time_s:.4f} s") from None
        self._report = report
        self._check(report)
        self._asleep_until = report.cycle if report.state == STATE_SLEEPING else -1
        if self.record:
            self.frames += report.frames
            self.conversions += report.conversions
        pieces: list[tuple[float, float]] = []
        at = start
        span = max(end - start, 1)
        for frame in report.frames:
            try:
                volts = board.dac.volts(frame.word, int(io.dac_bits), io.dac_reference_v)
            except ValueError as exc:
                raise ControllerError(self._where(f"{exc}", frame.cycle)) from None
            self._count(frame.word, frame.since_entry, self._time_s(frame.cycle))
            if volts is None:
                continue
            if frame.cycle > at:
                pieces.append(((min(frame.cycle, end) - at) / span, self._command_v))
                at = min(frame.cycle, end)
            self._command_v = volts
        pieces.append(((end - at) / span, self._command_v))
        self._check_output(until_s)
        return pieces

    def core(self) -> AvrCore:
        """A core with this image, out of reset (``AvrError`` when simavr cannot load it)."""
        return AvrCore(
            self.path,
            mcu=self.mcu,
            frequency_hz=self.clock_hz,
            adc_reference_v=self.io.adc_reference_v,
            dac_select=self.board.dac_select,
        )

    @property
    def command_v(self) -> float:
        """The DAC's output now (the amplifier's zero before the firmware's first frame)."""
        return self._command_v

    def figures(self) -> dict[str, Any]:
        """What the target adds to the run's verdict (see the module's doc)."""
        u, r = self._updates, self._report
        period_cycles = self.period_s * self.clock_hz
        worst = u.cycles_max if u.timed else math.nan
        high = self._ramend - r.stack_low_water if r is not None and r.stack_low_water <= self._ramend else 0
        total = r.cycle if r is not None else 0
        return {
            "image": str(self.path),
            "sha256": self.sha256,
            "mcu": self.mcu,
            "clock_hz": self.clock_hz,
            "updates": u.count,
            "update_cycles_max": worst,
            "update_cycles_mean": u.cycles_sum / u.timed if u.timed else math.nan,
            "update_max_s": worst / self.clock_hz,
            "deadline_margin_s": (period_cycles - worst) / self.clock_hz,
            "deadline_margin": 1.0 - worst / period_cycles,
            "missed_periods": u.missed_periods,
            "stack_high_water_bytes": high,
            # the room above the static data (unknown when the image names no end of it)
            "stack_room_bytes": self._ramend - self._data_end if self._data_end else math.nan,
            "load": r.awake_cycles / total if r is not None and total else math.nan,
            "interrupts": r.isr_entries if r is not None else 0,
            "interrupt_max_cycles": r.isr_max_cycles if r is not None else 0,
            "distinct_outputs": len(self._words),
            "output_constant_longest_s": u.constant_longest_s,
            "output_v": self._command_v,
            "output_word": self._last_word if self._last_word >= 0 else None,
            "output_unchanged_s": self._time_s(total) - u.constant_since_s if u.count else math.nan,
        }

    def close(self) -> None:
        core, self._core = self._core, None
        if core is not None:
            core.close()

    def __del__(self) -> None:
        self.close()

    # --- internals ----------------------------------------------------------------------------------------
    def _time_s(self, cycle: int) -> float:
        return self._boot_s + cycle / self.clock_hz

    def _where(self, what: str, cycle: int) -> str:
        return f"{self.name}: {what} at cycle {cycle} (t = {self._time_s(cycle):.4f} s)"

    def _check(self, r: RunReport) -> None:
        if r.state == STATE_STACK_OVERFLOW:
            raise ControllerError(
                self._where(
                    f"stack overflow into the static data (the stack pointer reached 0x{r.stack_low_water:04X}, "
                    f"the data end at 0x{self._data_end:04X}; pc 0x{r.pc:04X})",
                    r.cycle,
                )
            )
        if r.state == STATE_ERROR:
            raise ControllerError(self._where(f"the core faulted: {r.error} (pc 0x{r.pc:04X})", r.cycle))
        if r.state == STATE_CRASHED:
            raise ControllerError(self._where(f"the core crashed (pc 0x{r.pc:04X})", r.cycle))
        if r.state == STATE_DONE:
            raise ControllerError(
                self._where(f"the firmware stopped: asleep with interrupts off (pc 0x{r.pc:04X})", r.cycle)
            )
        if r.resets:
            raise ControllerError(
                self._where("the core reset (the watchdog's, or a jump to address 0)", r.cycle)
            )
        if r.bad_frames:
            raise ControllerError(
                self._where(
                    f"{r.bad_frames} chip-select pulse(s) carried other than the DAC's 16 bits: garbage on SPI",
                    r.cycle,
                )
            )
        if r.dropped_frames:
            raise ControllerError(
                self._where(f"{r.dropped_frames} DAC frames beyond 256 within one physics step", r.cycle)
            )

    def _count(self, word: int, since_entry: int, time_s: float) -> None:
        u = self._updates
        if not math.isnan(u.last_time_s):
            gap = round((time_s - u.last_time_s) / self.period_s)
            u.missed_periods += max(0, gap - 1)
        u.last_time_s = time_s
        u.count += 1
        if since_entry != NO_ENTRY:
            u.timed += 1
            u.cycles_sum += since_entry
            u.cycles_max = max(u.cycles_max, since_entry)
        self._words.add(word)
        if word != self._last_word:
            u.constant_since_s = time_s
            self._last_word = word
        u.constant_longest_s = max(u.constant_longest_s, time_s - u.constant_since_s)

    def _check_output(self, time_s: float) -> None:
        u = self._updates
        since = self._boot_s if math.isnan(u.last_time_s) else u.last_time_s
        if time_s - since > NO_OUTPUT_PERIODS * self.period_s:
            r = self._report
            assert r is not None
            doing = "in an interrupt" if r.in_isr else ("asleep" if r.state == STATE_SLEEPING else "running")
            what = "never wrote its DAC" if math.isnan(u.last_time_s) else "stopped writing its DAC"
            raise ControllerError(
                self._where(
                    f"the firmware {what}: no frame for {NO_OUTPUT_PERIODS} periods since t = {since:.4f} s "
                    f"(the core is {doing}, pc 0x{r.pc:04X})",
                    r.cycle,
                )
            )
