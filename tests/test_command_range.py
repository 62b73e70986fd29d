"""A command far outside the DAC's range (2 500 V on a 0 … 5 V card) written to the simulated rig is clamped by
the card as before, bit for bit, but no longer silently: the first one of a run warns, naming the tick and the
value, and the rig counts every clamped command of the run. Commands through the engine (a controller's
update) and the wire (a client's COMMAND) are refused before they reach the card (tests/test_engine.py,
tests/test_wire.py); this is the rig's own ``write``, which a loop of the user's calls directly."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from twin.output_stage import CommandClampedWarning
from twin.parameters import Parameters
from twin.rigs.sim import SimRig


def _run(commands: list[float]) -> tuple[SimRig, list[np.ndarray], list[warnings.WarningMessage]]:
    """The rig's start block and block 0, then one write and one read per command; the true states."""
    rig = SimRig(Parameters(), seed=0)
    rig.reset(0.1, 0.05)
    rig.read()
    rig.read()
    states = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for command in commands:
            rig.write(command)
            rig.read()
            states.append(rig.true_state())
    return rig, states, list(caught)


@pytest.mark.quick
def test_a_2500_volt_command_warns_once_naming_the_tick_and_the_value() -> None:
    commands = [2.5, 2500.0, 2500.0, 3.0, -40.0, 2500.0]
    rig, _, caught = _run(commands)
    clamped = [w for w in caught if issubclass(w.category, CommandClampedWarning)]
    assert len(clamped) == 1, [str(w.message) for w in caught]
    text = str(clamped[0].message)
    assert "command_v = 2500.0 V written at tick k = 3" in text
    assert "outside the DAC's range daq.dac_min_v … daq.dac_max_v = 0.0 … 5.0 V" in text
    assert "the board outputs 5.0 V" in text
    assert clamped[0].filename == __file__  # the warning points at the caller's write
    assert rig.clamped_commands == 4
    rig.reset(0.1, 0.05)  # a new run: counted and warned afresh
    assert rig.clamped_commands == 0


@pytest.mark.quick
def test_the_clamped_commands_drive_the_twin_as_the_range_ends_do() -> None:
    """The twin's numbers are unchanged: 2 500 V and −40 V move the rig exactly as 5 V and 0 V do."""
    _, far, _ = _run([2500.0] * 5 + [-40.0] * 5)
    _, ends, caught = _run([5.0] * 5 + [0.0] * 5)
    assert not caught
    for a, b in zip(far, ends, strict=True):
        assert np.array_equal(a, b)


@pytest.mark.quick
def test_commands_inside_the_range_do_not_warn() -> None:
    rig, _, caught = _run([0.0, 1.25, 2.5, 3.75, 5.0])
    assert not [w for w in caught if issubclass(w.category, CommandClampedWarning)]
    assert rig.clamped_commands == 0
