"""Firmware images the co-simulation tests build with avr-gcc (skipped, saying so, where it is not installed)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from twin.firmware import Board

F_CPU = 16_000_000
ROOT = Path(__file__).resolve().parents[1]
AVR_DIR = ROOT / "examples" / "avr"
C_DIR = ROOT / "examples" / "c"

# The board's DAC write (examples/avr/main.c's dac_write) and a 20 ms Timer1 interrupt, for small firmware.
BOARD = (
    "#include <avr/interrupt.h>\n#include <avr/io.h>\n#include <avr/sleep.h>\n#include <avr/wdt.h>\n"
    "#include <stdint.h>\n"
    "static void dac(uint16_t w) { PORTB &= ~(1 << PB2); SPDR = w >> 8; while (!(SPSR & (1 << SPIF))) { }\n"
    "  SPDR = w & 0xFF; while (!(SPSR & (1 << SPIF))) { } PORTB |= (1 << PB2); }\n"
    "static void board(void) { DDRB |= (1 << PB2) | (1 << PB3) | (1 << PB5); PORTB |= (1 << PB2);\n"
    "  SPCR = (1 << SPE) | (1 << MSTR); TCCR1B = (1 << WGM12) | (1 << CS11) | (1 << CS10); OCR1A = 4999;\n"
    "  TIMSK1 = (1 << OCIE1A); }\n"
    "static volatile uint16_t period;\n"
)


def build_image(name: str, text: str, tmp: Path, mcu: str = "atmega328p") -> Path:
    """A one-file firmware ``text`` built with avr-gcc for ``mcu`` (the ATmega328P) at 16 MHz."""
    avr_gcc = shutil.which("avr-gcc")
    if avr_gcc is None:
        pytest.skip("avr-gcc is not installed (Debian: apt-get install gcc-avr avr-libc)")
    source = tmp / f"{name}.c"
    source.write_text(text)
    out = tmp / f"{name}.elf"
    subprocess.run([avr_gcc, "-std=c99", "-Os", f"-mmcu={mcu}", f"-DF_CPU={F_CPU}UL", "-o", str(out), str(source)],
                   check=True)  # fmt: skip
    return out


def board_image(name: str, isr: str, tmp: Path, main: str = "", *, prefix: str = "") -> Path:
    """A firmware on the board: ``isr`` is the body of the 20 ms interrupt (``period`` counts them), ``main``
    what main does before it sleeps with interrupts on, ``prefix`` C before the interrupt."""
    text = (
        BOARD
        + prefix
        + "ISR(TIMER1_COMPA_vect) { period++; "
        + isr
        + " }\nint main(void) { board(); "
        + main
        + " set_sleep_mode(SLEEP_MODE_IDLE); sei(); for (;;) sleep_mode(); }\n"
    )
    return build_image(name, text, tmp)


def _makefile_cflags() -> list[str]:
    text = (AVR_DIR / "Makefile").read_text()
    flags = re.search(r"^CFLAGS = (.*)$", text, re.M)
    assert flags is not None
    return (
        flags[1]
        .replace("$(MCU)", "atmega328p")
        .replace("$(F_CPU)", str(F_CPU))
        .replace("-I../c", f"-I{C_DIR}")
        .split()
    )


def example_image(tmp: Path) -> Path:
    """examples/avr's image built with the Makefile's flags into ``tmp``."""
    avr_gcc = shutil.which("avr-gcc")
    if avr_gcc is None:
        pytest.skip("avr-gcc is not installed (Debian: apt-get install gcc-avr avr-libc)")
    out = tmp / "bb_sf.elf"
    subprocess.run(
        [avr_gcc, *_makefile_cflags(), "-Werror", "-o", str(out), str(AVR_DIR / "main.c"),
         str(C_DIR / "appendix_sf.c"), "-lm"],
        check=True,
    )  # fmt: skip
    return out


def example_image_for(board: Board, mcu: str, tmp: Path) -> Path:
    """examples/avr's image built for ``mcu`` on ``board`` (twin.avr.boards): main.c's Uno pins (chip select PB2,
    MOSI PB3, SCK PB5) replaced by the board's, with the Makefile's flags otherwise."""
    avr_gcc = shutil.which("avr-gcc")
    if avr_gcc is None:
        pytest.skip("avr-gcc is not installed (Debian: apt-get install gcc-avr avr-libc)")
    text = (AVR_DIR / "main.c").read_text()
    spi = "(1 << PB2) | (1 << PB3) | (1 << PB5)"
    assert spi in text and text.count("PB2") == 5, "examples/avr/main.c's pins changed: update this builder"
    text = text.replace(spi, "(1 << DAC_SELECT) | (1 << SPI_MOSI) | (1 << SPI_SCK)").replace(
        "PB2", "DAC_SELECT"
    )
    source = tmp / "main_board.c"
    source.write_text(text)
    out = tmp / f"bb_sf_{mcu}.elf"
    pins = {"DAC_SELECT": board.dac_select, "SPI_MOSI": board.spi_mosi, "SPI_SCK": board.spi_sck}
    flags = [f for f in _makefile_cflags() if not f.startswith("-mmcu=")]
    subprocess.run(
        [avr_gcc, *flags, f"-mmcu={mcu}", "-Werror", f"-I{AVR_DIR}",
         *(f"-D{name}=P{pin.port}{pin.bit}" for name, pin in pins.items()),
         "-o", str(out), str(source), str(C_DIR / "appendix_sf.c"), "-lm"],
        check=True,
    )  # fmt: skip
    return out


def host_law(tmp: Path) -> Path:
    """The law and I/O arithmetic compiled for the host in single precision (twin.app.firmware_forms.host_law)."""
    from twin.app.firmware_forms import host_law as build

    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler")
    return build(tmp, single=True)
