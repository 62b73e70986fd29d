"""The presets (twin/parts/presets/*.toml): each loads, its numbers reproduce the hardware data they were taken
from, and a controller designed by the project's own tools from the preset's linearization (``rig-lqg``) holds
the ball from a documented start."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.rig_lqg import rig_lqg
from twin.engine import ClosedLoop
from twin.parameters import Parameters
from twin.parts import rig_parts
from twin.parts.description import PRESETS, preset
from twin.parts.linkage import Linkage
from twin.parts.servo import Servo
from twin.rigs.sim import SimRig

# Open Ball & Beam's measured beam angle against servo pulse (TSummersLab/open-ball-beam,
# ballbeam/calibration/servo_calibration_data.txt: the mean of 20 accelerometer samples per pulse).
OBB_PULSE_US = (1000, 1100, 1200, 1300, 1400, 1500, 1600, 1700, 1800, 1900, 2000)
OBB_BEAM_DEG = (-7.60, -6.43, -4.97, -3.28, -1.56, 0.0, 1.46, 2.54, 3.25, 3.66, 3.86)


@pytest.mark.quick
@pytest.mark.parametrize("name", PRESETS)
def test_every_preset_loads_and_names_registered_parts(name: str) -> None:
    rig = preset(name)
    assert [part.name for part in rig_parts(rig)] == [getattr(rig.parts, role) for role in vars(rig.parts)]
    if name == "thesis":
        assert rig == Parameters()


@pytest.mark.quick
def test_open_ball_and_beams_linkage_reproduces_its_measured_angle_against_pulse() -> None:
    """The preset's horn and shaft were fitted to these 11 points through the exact closure: the twin's lever
    (a four-bar solved here by circle intersection, independently of twin.parts.linkage) gives them within
    0.1°, including the flattening near 2000 µs where the linkage nears its dead point."""
    rig = preset("open-ball-and-beam")
    link, servo = rig.of(Linkage), rig.of(Servo)
    worst = 0.0
    for pulse, measured in zip(OBB_PULSE_US, OBB_BEAM_DEG, strict=True):
        rate = (servo.angle_at_max_rad - servo.angle_at_min_rad) / (servo.pulse_max_us - servo.pulse_min_us)
        phi = link.horn_neutral_rad + servo.angle_at_min_rad + (pulse - servo.pulse_min_us) * rate
        pin_x, pin_z = (
            link.shaft_x_m + link.crank_m * math.cos(phi),
            link.shaft_z_m + link.crank_m * math.sin(phi),
        )
        d = math.hypot(pin_x, pin_z)
        # the attachment, L out along the beam at θ, lies r from the pin: the triangle pivot–pin–attachment
        theta = math.atan2(pin_z, pin_x) + math.acos(
            (link.beam_arm_m**2 + d * d - link.rod_m**2) / (2 * link.beam_arm_m * d)
        )
        worst = max(worst, abs(math.degrees(theta) - measured))
    assert worst < 0.1  # the fit's worst point: 0.065°


@pytest.mark.parametrize(
    ("name", "start", "held_mm"),
    [
        ("open-ball-and-beam", (0.05, 0.0), 5.0),  # measured: 1.2 mm at 10 s, 1.47 mm RMS over the last 2 s
        ("open-ball-and-beam", (-0.08, 0.0), 5.0),  # measured: 1.0 mm, 1.34 mm RMS
        ("thesis", (0.15, -0.1), 5.0),  # measured: −1.4 mm, 0.86 mm RMS
        ("arduino-stepper-ultrasonic", (0.05, 0.0), 8.0),  # measured: 3.9 mm RMS
        ("arduino-stepper-ultrasonic", (-0.1, 0.0), 8.0),  # measured: 2.0 mm RMS
        (
            "quanser-bb01",
            (-0.15, 0.0),
            5.0,
        ),  # measured: 1.2 mm, 1.12 mm RMS (the arm's weight: test_preset_bb01)
    ],
)
def test_rig_lqg_designed_from_the_presets_linearization_holds_the_ball(
    name: str, start: tuple[float, float], held_mm: float
) -> None:
    rig = SimRig(preset(name), seed=0)
    rig.reset(*start)
    controller = rig_lqg(preset(name))
    loop = ClosedLoop(rig, controller)
    xs = []
    for _ in range(500):  # 10 s at 50 Hz
        loop.tick()
        xs.append(rig.true_state()[0])
    assert not rig.ball_lost
    assert np.sqrt(np.mean(np.square(xs[-100:]))) * 1e3 < held_mm


@pytest.mark.quick
def test_rig_lqg_is_refused_on_a_part_that_gives_no_conversion(monkeypatch: pytest.MonkeyPatch) -> None:
    import dataclasses

    from twin.parts import contract

    wire = contract.part_named("ball_sensor", "resistive_wire")
    monkeypatch.setitem(
        contract._REGISTRY["ball_sensor"], "resistive_wire", dataclasses.replace(wire, position_of=None)
    )
    contract._rig_parts.cache_clear()
    try:
        with pytest.raises(ValueError, match=r"parts.ball_sensor = 'resistive_wire' \(position_of\)"):
            rig_lqg(Parameters())
    finally:
        monkeypatch.undo()
        contract._rig_parts.cache_clear()


@pytest.mark.quick
def test_rig_lqg_designs_once_per_rig_and_its_controllers_cannot_change_the_design() -> None:
    first, second = rig_lqg(preset("open-ball-and-beam")), rig_lqg(preset("open-ball-and-beam"))
    assert first.design is second.design  # a batch of runs on one rig designs once
    assert rig_lqg(preset("quanser-bb01")).design is not first.design
    with pytest.raises(ValueError, match="read-only"):
        first.design.gain[0, 0] = 0.0
