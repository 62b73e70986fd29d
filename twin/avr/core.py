"""A firmware image on a simulated AVR: simavr (libsimavr) stepped cycle by cycle through ``cosim.c``.

The C side is compiled on first use with the system's C compiler against Debian's ``libsimavr-dev`` and kept in
a cache keyed by its source (``BALLBEAM_CACHE``, else ``$XDG_CACHE_HOME/ballbeam``, else ``~/.cache/ballbeam``);
what is missing is named (``AvrUnavailable``). The core knows pins and cycles, not the rig: millivolts go in on
ADC channels, the 16-bit SPI frames the DAC's chip select latches come out with their cycles, and the stack
pointer's low-water mark is kept.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

__all__ = ["AvrCore", "AvrError", "AvrUnavailable", "Frame", "STATE_CRASHED", "STATE_DONE"]

SOURCE = Path(__file__).with_name("cosim.c")
# simavr's cpu states (sim_avr.h): the firmware stopped (asleep with interrupts off), or crashed.
STATE_DONE = 6
STATE_CRASHED = 7
MAX_FRAMES = 256


class AvrUnavailable(RuntimeError):
    """The co-simulation cannot be built here (no C compiler, no libsimavr-dev): the message says what to
    install."""


class AvrError(ValueError):
    """A firmware image simavr cannot load, named with the reason."""


@dataclass(frozen=True)
class Frame:
    word: int  # the 16 bits shifted out while the chip select was low
    cycle: int  # the core's cycle when the chip select rose


def _cache_dir() -> Path:
    base = os.environ.get("BALLBEAM_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache"), "ballbeam"
    )
    return Path(base)


def _library() -> ctypes.CDLL:
    """cosim.c as a shared library, built once per source (atomically: a parallel build cannot tear it)."""
    source = SOURCE.read_bytes()
    target = _cache_dir() / f"bbcosim-{hashlib.sha256(source).hexdigest()[:16]}.so"
    if not target.exists():
        cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
        if cc is None:
            raise AvrUnavailable(
                "the firmware co-simulation needs a C compiler (Debian: apt-get install gcc)"
            )
        if not Path("/usr/include/simavr/sim_avr.h").exists() and not _has_simavr_headers(cc):
            raise AvrUnavailable(
                "the firmware co-simulation needs simavr's library and headers "
                "(Debian: apt-get install simavr libsimavr-dev)"
            )
        target.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
            built = Path(tmp) / target.name
            done = subprocess.run(
                [cc, "-O2", "-shared", "-fPIC", "-o", str(built), str(SOURCE), "-lsimavr"],
                capture_output=True,
                text=True,
            )
            if done.returncode != 0:
                raise AvrUnavailable(
                    f"building the firmware co-simulation failed: {done.stderr.strip()[-400:]}"
                )
            os.replace(built, target)
    return _declare(ctypes.CDLL(str(target)))


def _has_simavr_headers(cc: str) -> bool:
    probe = subprocess.run(
        [cc, "-E", "-x", "c", "-", "-o", os.devnull],
        input="#include <simavr/sim_avr.h>\n",
        capture_output=True,
        text=True,
    )
    return probe.returncode == 0


def _declare(lib: ctypes.CDLL) -> ctypes.CDLL:
    handle, u16, u32, u64 = ctypes.c_void_p, ctypes.c_uint16, ctypes.c_uint32, ctypes.c_uint64
    lib.bb_new.restype = handle
    lib.bb_new.argtypes = [ctypes.c_char_p, ctypes.c_char_p, u32, u32, ctypes.c_char_p, ctypes.c_int]
    lib.bb_free.argtypes = [handle]
    lib.bb_set_adc_mv.argtypes = [handle, ctypes.c_int, u32]
    lib.bb_run_until.argtypes = [handle, u64]
    lib.bb_run_until.restype = ctypes.c_int
    for name, restype in (("bb_cycle", u64), ("bb_pc", u32), ("bb_min_sp", u16), ("bb_ramend", u16)):
        getattr(lib, name).argtypes = [handle]
        getattr(lib, name).restype = restype
    lib.bb_bad_frames.argtypes = [handle]
    lib.bb_bad_frames.restype = ctypes.c_int
    lib.bb_take_frames.argtypes = [handle, ctypes.POINTER(u16), ctypes.POINTER(u64), ctypes.c_int]
    lib.bb_take_frames.restype = ctypes.c_int
    return lib


_LIB: ctypes.CDLL | None = None


def library() -> ctypes.CDLL:
    global _LIB
    if _LIB is None:
        _LIB = _library()
    return _LIB


class AvrCore:
    """One firmware image on one simulated MCU, from reset."""

    def __init__(
        self, elf: str | Path, *, mcu: str = "atmega328p", frequency_hz: int = 16_000_000, vcc_mv: int = 5000
    ):
        path = Path(elf)
        if not path.is_file():
            raise AvrError(f"{path}: no such firmware image")
        self._lib = library()
        err = ctypes.create_string_buffer(256)
        handle = self._lib.bb_new(str(path).encode(), mcu.encode(), frequency_hz, vcc_mv, err, len(err))
        if not handle:
            raise AvrError(f"{path}: {err.value.decode(errors='replace')}")
        self._handle: int | None = handle
        self.mcu, self.frequency_hz = mcu, frequency_hz
        self._words = (ctypes.c_uint16 * MAX_FRAMES)()
        self._cycles = (ctypes.c_uint64 * MAX_FRAMES)()

    def close(self) -> None:
        if self._handle is not None:
            self._lib.bb_free(self._handle)
            self._handle = None

    def __enter__(self) -> AvrCore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()

    def set_adc_mv(self, channel: int, millivolts: float) -> None:
        """The voltage at ADC ``channel``'s pin from now on (simavr takes whole millivolts)."""
        self._lib.bb_set_adc_mv(self._handle, channel, max(0, round(millivolts)))

    def run_until(self, cycle: int) -> int:
        """Run to ``cycle``; simavr's state after (``STATE_DONE``, ``STATE_CRASHED`` end the firmware)."""
        return int(self._lib.bb_run_until(self._handle, cycle))

    def frames(self) -> list[Frame]:
        out: list[Frame] = []
        while True:
            n = self._lib.bb_take_frames(self._handle, self._words, self._cycles, MAX_FRAMES)
            out += [Frame(int(self._words[i]), int(self._cycles[i])) for i in range(n)]
            if n < MAX_FRAMES:
                return out

    @property
    def cycle(self) -> int:
        return int(self._lib.bb_cycle(self._handle))

    @property
    def pc(self) -> int:
        return int(self._lib.bb_pc(self._handle))

    @property
    def stack_low_water(self) -> int:
        """The lowest stack pointer so far (data-space address)."""
        return int(self._lib.bb_min_sp(self._handle))

    @property
    def ramend(self) -> int:
        return int(self._lib.bb_ramend(self._handle))

    @property
    def bad_frames(self) -> int:
        """Chip-select pulses that did not carry exactly 16 bits."""
        return int(self._lib.bb_bad_frames(self._handle))
