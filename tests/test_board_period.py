"""The loop's period belongs to the board (``Parameters.period_s``): the PCI-1712's ``daq.period_s`` on the
thesis's rig, an Arduino's ``arduino.loop_period_s``, a Quanser card's ``quanser_q8.loop_period_s``. The rig
ticks at it, a controller designed for the rig is discretized at it, and a period that is no whole number of
physics steps is refused naming the board's field."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.rig_lqg import rig_lqg
from twin.interface import RigError
from twin.parameters import Parameters
from twin.parts.description import preset
from twin.rigs.sim import SimRig, run_closed_loop


@pytest.mark.quick
def test_each_board_names_its_own_period_field() -> None:
    assert Parameters().period_field == "daq.period_s"
    assert Parameters().period_s == Parameters().daq.period_s
    obb = preset("open-ball-and-beam")
    assert obb.period_field == "arduino.loop_period_s"
    assert preset("quanser-bb01").period_field == "quanser_q8.loop_period_s"
    # the board's field is what counts: the PCI-1712's group does not move an Arduino's loop
    assert obb.with_overrides({"daq.period_s": 0.01}).period_s == 0.02
    assert obb.with_overrides({"arduino.loop_period_s": 0.01}).period_s == 0.01


@pytest.mark.quick
def test_a_period_of_no_whole_physics_steps_is_refused_naming_the_boards_field() -> None:
    rig = preset("open-ball-and-beam").with_overrides({"arduino.loop_period_s": 0.0105})
    with pytest.raises(RigError, match=r"arduino\.loop_period_s = 0\.0105 s is not a whole number"):
        SimRig(rig)


def test_an_arduino_loop_at_10_ms_ticks_every_10_ms_and_rig_lqg_designed_for_it_holds() -> None:
    rig = preset("open-ball-and-beam").with_overrides({"arduino.loop_period_s": 0.01})
    controller = rig_lqg(rig)
    assert controller.period_s == 0.01
    result = run_closed_loop(controller, x0_m=0.05, theta0_rad=0.0, duration_s=10.0, params=rig)
    spacing = np.diff(result.log.timem)
    assert np.allclose(spacing, 0.01, rtol=0, atol=1e-9)  # 1000 ticks of 10 ms
    assert result.verdict.held


@pytest.mark.quick
def test_setting_the_pci_cards_period_on_another_board_is_refused_naming_the_boards_field(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from twin.app.cli import main

    args = ["run", "--rig-file", "open-ball-and-beam", "--controller", "rig-lqg", "--x0", "0"]
    assert main([*args, "--theta0", "0", "--set", "daq.period_s=0.01"]) == 2
    assert "ticks at arduino.loop_period_s = 0.02 s" in capsys.readouterr().err
