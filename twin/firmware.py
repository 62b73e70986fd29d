"""Firmware in the loop: the contract of a controller that is firmware on a microcontroller's board, and what
describes such a board (its pins and its DAC), below the rigs (docs/design.md, "Firmware in the loop").

``FirmwareBoard`` is what the simulated rig asks of the board every physics step (``twin.rigs.sim.SimRig.
read_with_firmware``); ``Firmware`` is the whole controller the engine runs (``twin.engine.ClosedLoop``): the
board plus its name, period, telemetry and the figures the target adds to a run's verdict. ``Board`` is where a
board wires the rig: the ADC channels of the two sensor signals, the DAC's chip select and the DAC chip that
turns a command word into volts (``twin.avr.boards`` holds the AVR boards). The analog front end's values
(divider, references, clock) are parameters: ``twin.parameters.McuIo``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from twin.interface import Telemetry

__all__ = ["MCP4921", "Board", "DacChip", "Firmware", "FirmwareBoard", "Pin"]


class FirmwareBoard(Protocol):
    """What the rig asks of a firmware's board (``Firmware`` is one)."""

    @property
    def command_v(self) -> float: ...

    def boot(self, time_s: float) -> None: ...

    def pins(
        self, time_s: float, ball_signal_v: float, angle_signal_v: float, until_s: float
    ) -> list[tuple[float, float]]: ...


@runtime_checkable
class Firmware(FirmwareBoard, Protocol):
    """A controller that is firmware on a microcontroller's board (``twin.avr.firmware.AvrFirmware``): its pins
    get the rig's sensor signals every physics step, its output drives the amplifier, on its own clock.
    Simulation only: the rig must offer ``read_with_firmware`` (``twin.rigs.sim.SimRig``). ``figures`` is
    what the target adds to a run's verdict (cycles per update, deadline margin, stack, missed periods)."""

    name: str
    period_s: float

    @property
    def telemetry(self) -> Telemetry: ...

    def figures(self) -> dict[str, Any]: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class Pin:
    """One digital pin: its port's letter and its bit (``Pin("B", 2)`` is PB2)."""

    port: str
    bit: int

    def __post_init__(self) -> None:
        if (
            len(self.port) != 1
            or not self.port.isalpha()
            or not self.port.isupper()
            or not 0 <= self.bit <= 7
        ):
            raise ValueError(f"pin P{self.port}{self.bit}: a port letter A…Z and a bit 0…7")

    def __str__(self) -> str:
        return f"P{self.port}{self.bit}"


@dataclass(frozen=True)
class DacChip:
    """An SPI DAC's command word (one frame of ``frame_bits`` while its chip select is low): bit ``ignore`` set
    means the chip ignores the frame, bit ``gain_one`` set is gain 1 (clear: 2), bit ``active`` clear shuts the
    output down, and the low ``code_bits`` are the code."""

    name: str
    frame_bits: int
    code_bits: int
    ignore: int
    gain_one: int
    active: int

    def volts(self, word: int, bits: int, reference_v: float) -> float | None:
        """The output for a command word at a resolution of ``bits`` (the code's top bits): code·V_ref/2^bits
        (twice that at gain 2, at most the supply, which is V_ref on these boards); ``None`` for a word the
        chip ignores. A word that shuts the output down is a ``ValueError``: the amplifier's input would float."""
        if word & self.ignore:
            return None
        if not word & self.active:
            raise ValueError(f"word 0x{word:04X} shuts the DAC's output down (SHDN = 0)")
        code = (word & ((1 << self.code_bits) - 1)) >> (self.code_bits - bits)
        gain = 1 if word & self.gain_one else 2
        return min(code * reference_v / (1 << bits) * gain, reference_v)


# MCP4921's command word (datasheet, register 5-1): bit 15 0 = write the DAC (1: the command is ignored),
# bit 13 GA (1: gain 1, 0: gain 2), bit 12 SHDN (0: output shut down), bits 11…0 the code.
MCP4921 = DacChip("MCP4921", frame_bits=16, code_bits=12, ignore=0x8000, gain_one=0x2000, active=0x1000)


@dataclass(frozen=True)
class Board:
    """Where a board wires the rig: the sensor signals' ADC channels (through the front end), the DAC's chip
    select (the frames latched when it rises are the amplifier's command) and the DAC chip, and the SPI pins
    the DAC's data and clock leave on (what a firmware for the board drives; the co-simulation reads the SPI
    unit itself)."""

    name: str
    mcus: tuple[str, ...]  # the microcontrollers (avr-gcc's -mmcu names) this board carries
    dac_select: Pin
    spi_mosi: Pin
    spi_sck: Pin
    ball_channel: int = 0
    angle_channel: int = 1
    dac: DacChip = MCP4921
