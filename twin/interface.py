"""The two contracts of the rig, free of MuJoCo so that hardware code can import them alone.

``Rig`` is what a controller talks to: the I/O card (raw volts in, a DAC command out, one block per tick).
``SimRig`` (twin.rigs.sim) implements it on the simulated rigs, ``RemoteRig`` (twin.rigs.remote) over protocol 1; a
hardware backend implements the same calls on the PCI-1712 (``getdata``/``putsample`` in the thesis's
MATLAB software, appendix A). The one closed loop (``twin.engine.ClosedLoop``) needs nothing else of a rig.

``Controller`` is what runs at each tick: ``start`` once with the first block (the software's Start and
Clear Buffer phase, which sets x1(1), x2(1)), then ``update`` with each block, returning the DAC command.
The controller that passes on the twin is the controller that drives the rig. Nothing here carries
simulation truth: laws that need all four states run on a separate, simulation-only path
(``twin.engine.StateLaw``).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:  # the parameters are a plain-Python module, imported lazily to keep this one bare
    from twin.parameters import Parameters

__all__ = ["CommandRange", "Controller", "DaqSample", "Rig", "RigEnded", "RigError", "Setpoint", "Telemetry"]


@dataclass(frozen=True)
class DaqSample:
    """One block of the I/O card as the thesis software reduces it (appendix A, Table 6.4)."""

    time_s: float  # time of the block's last sample: time(blocksize)
    ball_v: float  # ball channel, last sample of the block: data(blocksize,1), ADC volts
    angle_v: float  # angle channel, mean of the block: mean(data(:,2)), ADC volts


@dataclass(frozen=True)
class CommandRange:
    """What a rig's board can output, in its unit: the DAC's volts on the PCI-1712 (the default), a servo
    pulse's width in µs on an Arduino. ``names``: the parameters that set it (for a message); ``what``: the
    output, as a message names it."""

    low: float
    high: float
    unit: str = "V"
    names: str = "daq.dac_min_v … daq.dac_max_v"
    what: str = "the DAC's range"

    def text(self) -> str:
        """``the DAC's range daq.dac_min_v … daq.dac_max_v = 0.0 … 5.0 V``: the range as a message gives it."""
        return f"{self.what} {self.names} = {self.low!r} … {self.high!r} {self.unit}"


class RigError(ValueError):
    """A configuration the rig cannot run (period or latency not a whole number of physics steps, …)."""


class RigEnded(Exception):
    """Raised by a rig's ``read`` or ``write`` when the rig ends the session (it sent STOP, went silent): the
    closed loop ends the run there and reports the message; nothing of the run is lost."""


class Rig(ABC):
    """The I/O card as a controller sees it, on the twin or on the hardware.

    What a new rig implements: ``period_s``, ``read``, ``write``, ``parameters`` and the attribute
    ``command_v``; the flags ``held``, ``ball_lost`` and ``is_last`` when the rig reports them (they default
    to False). A simulated rig may offer the true state besides (``twin.engine.TrueState``): the loop records
    it when present, and judges from the measured volts when not."""

    command_v: float  # the DAC's value as last set: the zero command until the first ``write``

    @property
    @abstractmethod
    def period_s(self) -> float:
        """Control period: the card's timer period (0.02 s, Table 6.4)."""

    @abstractmethod
    def read(self) -> DaqSample:
        """Wait for the next block and return it."""

    @abstractmethod
    def write(self, command_v: float) -> None:
        """Set the analog output (0–5 V; the amplifier maps 1.25/2.5/3.75 V to −12/0/+12 V)."""

    @abstractmethod
    def parameters(self) -> Parameters:
        """The rig as far as it describes itself: its period, DAC range and zero command, software
        calibration (the guard's range check, the log and a verdict from the measured volts read them)."""

    def command_range(self) -> CommandRange:
        """What the board can output (the guard refuses a command outside it): the DAC's range of the rig's
        parameters (``daq.dac_min_v`` … ``daq.dac_max_v``) unless the rig's board says otherwise."""
        daq = self.parameters().daq
        return CommandRange(daq.dac_min_v, daq.dac_max_v)

    @property
    def held(self) -> bool:
        """Whether the block just read was taken while the rig was still held at its initial state."""
        return False

    @property
    def ball_lost(self) -> bool:
        """Whether the rig reports the ball lost (it left the track)."""
        return False

    @property
    def is_last(self) -> bool:
        """Whether the block just read is the session's last: the loop ends after answering it."""
        return False


def _nan4() -> np.ndarray:
    return np.full(4, math.nan)


@dataclass
class Telemetry:
    """What the thesis software logs each tick besides the raw data (appendix A)."""

    estimate: np.ndarray = field(default_factory=_nan4)  # x1…x4: x (m), θ (rad), ẋ (m/s), θ̇ (rad/s)
    u: float = math.nan  # u(k): torque (N·m) or motor volts, as the controller's software logs it
    u_computed: float = math.nan  # uhesap/Vhesap: the computed value before the command limits


class Controller(ABC):
    """A controller of the rig: raw volts in, DAC command volts out, every ``period_s``.

    This is the contract hardware code implements: it sees only what the I/O card gives (``DaqSample``)
    and returns only what the card accepts (a DAC voltage). ``telemetry`` is what it logs, as the rig
    software logs x1…x4, u and uhesap."""

    name: str = "controller"
    period_s: float = 0.02

    def __init__(self) -> None:
        self.telemetry = Telemetry()

    @abstractmethod
    def start(self, sample: DaqSample) -> None:
        """The first block, before the motor is driven: initialise the estimates from it."""

    @abstractmethod
    def update(self, sample: DaqSample) -> float:
        """One tick: the block just acquired → the DAC command (V). Updates ``self.telemetry``."""


@runtime_checkable
class Setpoint(Protocol):
    """A capability a controller (or a simulation-only law) declares when it regulates the ball to a settable
    position: ``setpoint_m`` (m along the beam, 0 = the centre) is read and assigned between ticks. The live
    view, the excitation experiments and the verdict's "about the setpoint" read it; a controller without it
    regulates to its own fixed point (the centre)."""

    setpoint_m: float
