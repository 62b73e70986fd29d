"""The AVR boards a firmware image runs on (``twin.firmware.Board``): where each wires the rig.

Every board puts the DAC's chip select on its SPI unit's own SS pin (an output in master mode, so the unit
stays master) and the sensor signals on ADC0 (ball) and ADC1 (angle), as ``examples/avr/main.c`` does on the
Uno. An MCU no board here names runs with the Uno's wiring (the one every image had before boards were named).
"""

from __future__ import annotations

from twin.firmware import Board, Pin

__all__ = ["ATMEGA644", "BOARDS", "MEGA2560", "UNO", "board_for"]

# Arduino Uno / Nano: SS PB2, MOSI PB3, SCK PB5 (ATmega328P datasheet §1.1).
UNO = Board(
    "Arduino Uno/Nano",
    ("atmega328p", "atmega328", "atmega168", "atmega168p", "atmega88", "atmega88p", "atmega48", "atmega48p"),
    dac_select=Pin("B", 2),
    spi_mosi=Pin("B", 3),
    spi_sck=Pin("B", 5),
)
# Arduino Mega 2560: SS PB0, SCK PB1, MOSI PB2 (ATmega2560 datasheet §1.1): PB2 is the SPI's data out here.
MEGA2560 = Board(
    "Arduino Mega 2560",
    ("atmega2560", "atmega1280", "atmega640"),
    dac_select=Pin("B", 0),
    spi_mosi=Pin("B", 2),
    spi_sck=Pin("B", 1),
)
# An ATmega644 board (Sanguino-class): SS PB4, MOSI PB5, SCK PB7 (ATmega644 datasheet §1.1).
ATMEGA644 = Board(
    "ATmega644 board",
    ("atmega644", "atmega644p", "atmega1284", "atmega1284p", "atmega324p", "atmega164p"),
    dac_select=Pin("B", 4),
    spi_mosi=Pin("B", 5),
    spi_sck=Pin("B", 7),
)
BOARDS = (UNO, MEGA2560, ATMEGA644)


def board_for(mcu: str) -> Board:
    """The board that carries ``mcu`` (avr-gcc's name, any case); the Uno's wiring for one no board names."""
    name = mcu.lower()
    for board in BOARDS:
        if name in board.mcus:
            return board
    return UNO
