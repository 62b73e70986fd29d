"""A firmware image on a simulated AVR: simavr (libsimavr) stepped cycle by cycle in a process of its own.

The C side (``cosim.c``) is a small program compiled on first use with the system's C compiler against Debian's
``libsimavr-dev`` and kept in a cache keyed by its source (``BALLBEAM_CACHE``, else ``$XDG_CACHE_HOME/ballbeam``,
else ``~/.cache/ballbeam``); what is missing is named (``AvrUnavailable``). It runs as a child process, spoken to
over its stdin and stdout, because a firmware can take simavr down with it (a crash path that exits, text
printed on stdout, a fault in the simulator): that ends the child, and the twin reports it. The core knows pins
and cycles, not the rig: millivolts go in on ADC channels, the 16-bit SPI frames the DAC's chip select (the
board's pin) latches come out with their cycles, and the stack pointer's low-water mark, the resets and a stack
that grew into the static data are kept.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import shutil
import struct
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from twin.avr.boards import UNO
from twin.childproc import Child
from twin.firmware import Pin
from twin.image import read_image

__all__ = [
    "STATE_CRASHED",
    "STATE_DONE",
    "STATE_ERROR",
    "STATE_SLEEPING",
    "STATE_STACK_OVERFLOW",
    "AvrCore",
    "AvrError",
    "AvrUnavailable",
    "Conversion",
    "MAX_IMAGE_BYTES",
    "Frame",
    "NO_ENTRY",
    "RunReport",
    "data_end",
    "elf_device",
    "elf_sections",
    "executable",
    "read_elf",
]

SOURCE = Path(__file__).with_name("cosim.c")
# simavr's cpu states (sim_avr.h): the firmware stopped (asleep with interrupts off), or crashed; and the
# harness's own: the stack pointer went below the static data.
STATE_SLEEPING = 3  # asleep until an interrupt: simavr runs the clock ahead to the next timer event
STATE_DONE = 6
STATE_CRASHED = 7
STATE_STACK_OVERFLOW = 100
STATE_ERROR = 101  # simavr logged an error: an invalid opcode, an access outside memory (RunReport.error)
# The largest image read: an AVR's flash is at most 256 KiB; the rest of an ELF is symbols and debug sections.
MAX_IMAGE_BYTES = 16 << 20
# How long one request may take before the child counts as hung (a run to the next physics step is
# microseconds of work; a whole period of a firmware busy-looping is tens of milliseconds).
ANSWER_TIMEOUT_S = 30.0


class AvrUnavailable(RuntimeError):
    """The co-simulation cannot be built here (no C compiler, no libsimavr-dev): the message says what to
    install."""


class AvrError(RuntimeError):
    """A firmware image simavr cannot load, or a co-simulation that ended or stopped answering."""


# ``Frame.since_entry`` when no interrupt had been entered before the frame.
NO_ENTRY = 0xFFFFFFFF


@dataclass(frozen=True)
class Frame:
    word: int  # the 16 bits shifted out while the chip select was low
    cycle: int  # the core's cycle when the chip select rose
    since_entry: int  # cycles from the latest interrupt's entry to the frame (NO_ENTRY: none entered yet)


@dataclass(frozen=True)
class Conversion:
    value: int  # the ADC's 16-bit result register as the firmware read it (ADCL, then ADCH)
    channel: int  # ADMUX's channel bits then
    cycle: int


@dataclass(frozen=True)
class RunReport:
    """Where a run to a target cycle left the core."""

    state: int  # simavr's cpu state, or STATE_STACK_OVERFLOW
    cycle: int
    pc: int  # byte address
    stack_low_water: int  # the lowest stack pointer so far (data-space address)
    resets: int  # returns to the reset vector since the start
    bad_frames: int  # chip-select pulses that did not carry exactly 16 bits
    dropped_frames: int  # frames beyond the 256 one run can hold (a firmware writing without pause)
    awake_cycles: int  # cycles the core ran (not asleep) since the start
    isr_cycles: int  # cycles spent in interrupts that have returned, since the start
    isr_entries: int  # interrupts entered from the main program since the start
    isr_max_cycles: int  # the longest of them
    in_isr: bool  # the core is in an interrupt now
    frames: tuple[Frame, ...]  # latched since the last run
    conversions: tuple[Conversion, ...] = ()  # ADC results the firmware read since the last run
    conversions_dropped: int = 0  # results beyond the 256 one run can hold
    error: str = ""  # simavr's first error message (STATE_ERROR)


def _cache_dir() -> Path:
    base = os.environ.get("BALLBEAM_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache"), "ballbeam"
    )
    return Path(base)


def executable() -> Path:
    """cosim.c built once per source (atomically: a parallel build cannot tear it)."""
    source = SOURCE.read_bytes()
    target = _cache_dir() / f"bbcosim-{hashlib.sha256(source).hexdigest()[:16]}"
    if target.exists():
        return target
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise AvrUnavailable("the firmware co-simulation needs a C compiler (Debian: apt-get install gcc)")
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        built = Path(tmp) / target.name
        done = subprocess.run(
            [cc, "-O2", "-o", str(built), str(SOURCE), "-lsimavr"], capture_output=True, text=True
        )
        if done.returncode != 0:
            if "simavr/" in done.stderr or "lsimavr" in done.stderr:
                raise AvrUnavailable(
                    "the firmware co-simulation needs simavr's library and headers "
                    "(Debian: apt-get install simavr libsimavr-dev)"
                )
            raise AvrUnavailable(f"building the firmware co-simulation failed: {done.stderr.strip()[-400:]}")
        os.replace(built, target)
    return target


# Symbols avr-libc's linker scripts put at the end of the static data (.data, .bss, .noinit).
DATA_END_SYMBOLS = (b"__bss_end", b"__noinit_end", b"__heap_start")


def read_elf(path: Path) -> bytes:
    """The firmware image's bytes: a regular file of at most ``MAX_IMAGE_BYTES`` (``AvrError`` naming it
    otherwise, before it is read)."""
    return read_image(path, "firmware image", MAX_IMAGE_BYTES, AvrError)


def data_end(path: Path | bytes) -> int:
    """The first data address above the firmware's static data: the highest of ``DATA_END_SYMBOLS`` in the
    ELF's symbol table (``path``: the image or its bytes); 0 when it has none (the stack is then not checked
    against the data)."""
    found = 0
    raw = path if isinstance(path, bytes) else read_elf(path)
    try:
        sections = elf_sections(raw)
        for _, kind, _, _, offset, size, link, _, _, entsize in sections:
            if kind != 2 or entsize != 16:  # SHT_SYMTAB
                continue
            names = sections[link][4]
            for i in range(size // 16):
                name_at, value = struct.unpack_from("<II", raw, offset + 16 * i)
                end = raw.index(b"\0", names + name_at)
                if raw[names + name_at : end] in DATA_END_SYMBOLS:
                    found = max(found, value & 0xFFFF)  # data addresses carry avr-gcc's 0x800000 offset
    except (struct.error, IndexError, ValueError):
        return 0
    return found


def elf_sections(raw: bytes) -> list[tuple[int, ...]]:
    """The section headers of a 32-bit little-endian ELF (an AVR image); ``ValueError`` for anything else."""
    if raw[:4] != b"\x7fELF" or raw[4] != 1 or raw[5] != 1:
        raise ValueError("not an ELF32 little-endian image")
    (shoff,) = struct.unpack_from("<I", raw, 0x20)
    shentsize, shnum = struct.unpack_from("<HH", raw, 0x2E)
    if shoff + shentsize * shnum > len(raw):
        raise ValueError("the section headers lie beyond the file's end")
    return [struct.unpack_from("<10I", raw, shoff + i * shentsize) for i in range(shnum)]


def elf_device(path: Path | bytes) -> str | None:
    """The MCU an image (``path``: the image or its bytes) was built for, as avr-gcc's ``-mmcu`` wrote it in the
    note ``.note.gnu.avr.deviceinfo`` (its last field: the device name); ``None`` when the image has no such
    note."""
    raw = path if isinstance(path, bytes) else read_elf(path)
    try:
        sections = elf_sections(raw)
        names = sections[struct.unpack_from("<H", raw, 0x32)[0]]
        for name_at, kind, _, _, offset, size, *_ in sections:
            start = names[4] + name_at
            if kind != 7 or raw[start : raw.index(b"\0", start)] != b".note.gnu.avr.deviceinfo":
                continue
            namesz, descsz, _ = struct.unpack_from("<III", raw, offset)
            desc = raw[offset + 12 + (namesz + 3) // 4 * 4 : offset + size][:descsz]
            # flash, SRAM and EEPROM (start, size each), the offset table's length in bytes (itself included)
            # and its offsets into the string table after it: the first is the device name's
            table_len, str_offset = struct.unpack_from("<II", desc, 24)
            table = desc[24 + table_len :]
            name = table[str_offset : table.index(b"\0", str_offset)].decode("ascii")
            return name if name.isalnum() else None
    except (struct.error, IndexError, ValueError, UnicodeDecodeError):
        return None
    return None


# simavr's ADC converts an integer input u against an integer reference R as ⌊u·1023 / R⌋ (sim/avr_adc.c; the
# datasheet: ⌊V·1024 / V_ref⌋). With R = 1023·M and u = ⌊V/V_ref · 1024·M⌋ that is ⌊⌊V/V_ref·1024·M⌋ / M⌋ =
# ⌊V·1024 / V_ref⌋ exactly for any whole M; simavr keeps an input in 16 bits, so 1024·M ≤ 65 535: M = 63
# (an input resolution of 1/63 count).
ADC_SCALE = 63


_REPORT = struct.Struct("<iQIHIiiQQIIBI")
_FRAME = struct.Struct("<HQI")
_CONVERSION = struct.Struct("<HBQ")


def _plain(message: str) -> str:
    """simavr's log line without its terminal colours and its "CORE: *** " prefix."""
    return re.sub(r"\x1b\[[0-9;]*m", "", message).replace("CORE: *** ", "").strip()


class AvrCore:
    """One firmware image on one simulated MCU, from reset, in its own process."""

    def __init__(
        self,
        elf: str | Path,
        *,
        mcu: str = "atmega328p",
        frequency_hz: int = 16_000_000,
        adc_reference_v: float = 5.0,
        dac_select: Pin = UNO.dac_select,
    ) -> None:
        """``dac_select``: the pin whose rising edge latches a DAC frame (the board's, ``twin.avr.boards``)."""
        self._child: Child | None = None
        path = Path(elf)
        raw = read_elf(path)
        self.path, self.mcu, self.frequency_hz = path, mcu, frequency_hz
        self.adc_reference_v = adc_reference_v
        argv = [
            str(executable()),
            str(path),
            mcu,
            str(frequency_hz),
            str(1023 * ADC_SCALE),
            str(data_end(raw)),
            dac_select.port,
            str(dac_select.bit),
        ]
        self._child = Child(
            argv, name=str(path), what="the co-simulation", error=AvrError, timeout_s=ANSWER_TIMEOUT_S
        )
        head = self._child.read(2)
        if head != b"OK":
            reason = self._child.line().decode(errors="replace").strip()
            self.close()
            raise AvrError(f"{path}: {reason or 'the co-simulation did not start'}")
        self.ramend, self.data_end = struct.unpack("<HH", self._child.read(4))

    @property
    def _proc(self) -> subprocess.Popen[bytes] | None:
        return self._child.proc if self._child is not None else None

    def close(self) -> None:
        child, self._child = self._child, None
        if child is not None:
            child.close(b"Q")

    def __enter__(self) -> AvrCore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()

    def set_adc_v(self, channel: int, volts: float) -> None:
        """The voltage at ADC ``channel``'s pin from now on: each conversion reads ⌊V·1024 / V_ref⌋ within
        0…1023, as the datasheet's ADC does (``ADC_SCALE``)."""
        self._send(self.adc_request(channel, volts))

    def adc_request(self, channel: int, volts: float) -> bytes:
        """``set_adc_v``'s request, to send with others in one write (``run_until``'s ``before``)."""
        units = math.floor(
            min(max(volts, 0.0), self.adc_reference_v) / self.adc_reference_v * 1024 * ADC_SCALE
        )
        return struct.pack("<cBI", b"A", channel, units)

    def run_until(self, cycle: int, before: bytes = b"") -> RunReport:
        """Run to ``cycle`` (after the requests ``before``, sent in the same write); the report's state says
        whether the firmware goes on."""
        child = self._alive()
        child.write(before + struct.pack("<cQ", b"R", cycle))
        read = child.read
        head = _REPORT.unpack(read(_REPORT.size))
        n = head[-1]
        raw = read(n * _FRAME.size)
        frames = tuple(Frame(*_FRAME.unpack_from(raw, i * _FRAME.size)) for i in range(n))
        (m,) = struct.unpack("<I", read(4))
        raw = read(m * _CONVERSION.size)
        conversions = tuple(Conversion(*_CONVERSION.unpack_from(raw, i * _CONVERSION.size)) for i in range(m))
        conv_dropped, length = struct.unpack("<IH", read(6))
        error = _plain(read(length).decode(errors="replace")) if length else ""
        state, now, pc, low, resets, bad, dropped, awake, isr, entries, isr_max, in_isr, _ = head
        return RunReport(
            state,
            now,
            pc,
            low,
            resets,
            bad,
            dropped,
            awake,
            isr,
            entries,
            isr_max,
            bool(in_isr),
            frames,
            conversions,
            conv_dropped,
            error,
        )

    def _send(self, data: bytes) -> None:
        self._alive().write(data)

    def _alive(self) -> Child:
        if self._child is None:
            raise AvrError(f"{self.path}: the co-simulation is closed")
        return self._child
