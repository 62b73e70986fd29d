"""The part-built rig's dynamic calibration (calib.part_identify) on the quanser-bb01 preset: logs of an independent
simulator of the BB01 (tests/bb01_simulator.py, numpy only), which is first checked against the twin's reference
model."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from calib.identify import CalibrationError
from calib.part_identify import RIG_SHAPES, calibrate_part_rig, describe_toml, shape_of
from calib.serial_log import read_serial_log
from tests import bb01_simulator as sim
from twin.parts.description import load_rig, rig_from_text, rig_of

PRESET = "quanser-bb01"
# efficiencies folded into the preset's resistance: R = R_m/(η_g·η_m) (the preset's note)
FOLD = 0.90 * 0.69


@pytest.mark.quick
def test_simulator_geometry_on_paper() -> None:
    # the ball on the rod and the strip's edge, by hand: D = |E − A| = √(12.7² + 3.175²) = 13.0909 mm,
    # l = ((r + ρ)² − r² + D²)/(2D) = 10.0110 mm, k = √((r + ρ)² − l²) = 12.3208 mm; the centre at
    # z = 20 + (l·3.175 + k·12.7)/D = 34.3809 mm; the rod's contact ρ/(r + ρ) of the way, the edge's at E:
    # s = 22.1563 mm... r* = √(r² − s²/4) = 11.3592 mm
    h_c, r_star = sim.ball_geometry()
    assert h_c == pytest.approx(0.0343809, abs=2e-7)
    assert r_star == pytest.approx(0.0113592, abs=2e-7)
    # at level the arm is horizontal and the link vertical: dθ_l/dθ = L/r_arm = 16.75 (Quanser's small-angle
    # θ_beam = (r_arm/L)·θ_l), and the arm sits at its zero
    theta_l, ratio, _ = sim.arm_rates(0.0)
    assert abs(theta_l) < 1e-12
    assert ratio == pytest.approx(0.42545 / 0.0254, rel=1e-6)


@pytest.mark.quick
def test_simulator_agrees_with_the_reference_model_over_1s() -> None:
    # the preset's reference model (twin.reference, eq 3.1.26/27 with the lever's DriveLaw and the geared motor)
    # and the simulator's own Lagrange equations, driven open-loop by the same volts from the same state
    from twin.reference import ReferencePlant

    params = rig_of(PRESET)
    plant = ReferencePlant(params)
    x0, th0 = 0.03, 0.01
    plant.reset(x0, th0)
    state = np.array([x0 + sim.L / 2, th0, 0.0, 0.0])
    n = int(round(sim.PERIOD_S / params.physics.timestep_s))
    worst_x = worst_th = 0.0
    for j in range(50):
        volts = 0.3 + 0.8 * math.sin(2 * math.pi * 1.5 * j * sim.PERIOD_S)
        plant.advance(np.full(n, volts))
        state = sim.advance(sim.TrueRig(), state, volts, sim.PERIOD_S)
        ref = plant.state()
        worst_x = max(worst_x, abs(ref[0] - (state[0] - sim.L / 2)))
        worst_th = max(worst_th, abs(ref[1] - state[1]))
    assert worst_x < 1e-6 and worst_th < 1e-6, (worst_x, worst_th)
    assert abs(state[0] - sim.L / 2 - 0.03) > 0.04  # the ball rolled 50 mm: the check is not of a still rig


@pytest.mark.quick
def test_log_reads_through_the_preset_map(tmp_path: Path) -> None:
    path = tmp_path / "bb01.csv"
    lines = sim.simulate(sim.TrueRig(), 0.4, seed=2)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    log = read_serial_log(path, PRESET, rig_of(PRESET))
    assert log.units == {"timem": "s", "datam1": "V", "datam2": "counts", "aout": "V"}
    t, v, n, c = lines[5].split(",")
    assert log.log.timem[4] == pytest.approx(int(t) / 1000.0)
    assert (log.log.datam1[4], log.log.datam2[4], log.log.aout[4]) == (float(v), float(n), float(c))


@pytest.mark.quick
def test_rig_shapes_and_refusals() -> None:
    params = rig_of(PRESET)
    shape = shape_of(params)
    assert (shape.law, shape.command, shape.angle_sensor, shape.ball_unit) == (
        "geared",
        "board",
        "shaft_encoder",
        "V",
    )
    assert shape_of(rig_of("open-ball-and-beam")).law == "servo"
    assert len({s.parts for s in RIG_SHAPES}) == len(RIG_SHAPES)
    with pytest.raises(CalibrationError, match="covers"):
        shape_of(rig_of("arduino-stepper-ultrasonic"))


@pytest.mark.slow
def test_recovers_moved_parameters_within_intervals(tmp_path: Path) -> None:
    # the simulated BB01 away from the preset by known amounts: R_m 15 % up, B_eq 0.020 (0.015), the beam's
    # inertia 25 % up, the strip's K_BS −0.0440 (−0.042545) with a 50 mV offset, the counter reset 7 counts off
    # level, a rolling resistance of 0.3 1/s (none)
    truth = sim.TrueRig().moved(
        resistance_ohm=2.6 * 1.15,
        load_damping_nm_s=0.020,
        beam_inertia_kgm2=0.0181 * 1.25,
        strip_gain_m_per_v=-0.0440,
        strip_offset_v=0.05,
        encoder_zero_counts=7,
        rolling_damping_1_s=0.3,
    )
    path = tmp_path / "bb01.csv"
    sim.write_log(str(path), truth, 60.0, seed=3)
    params = rig_of(PRESET)
    expected = {
        "motor.resistance_ohm": truth.resistance_ohm / FOLD,
        "motor.viscous_damping_nm_s_per_rad": truth.load_damping_nm_s / 70.0**2,  # B_eq/K_g² at the rotor
        "beam.inertia_pivot_kgm2": truth.beam_inertia_kgm2,
        "bb01_strip.gain_m_per_v": truth.strip_gain_m_per_v,
        "bb01_strip.offset_v": truth.strip_offset_v,
        "angle_reading.zero_counts": float(truth.encoder_zero_counts),
        "ball_rolling.damping_1_s": truth.rolling_damping_1_s,
    }
    fit = [*expected, "linkage.horn_travel_rad"]
    cal = calibrate_part_rig(read_serial_log(path, PRESET, params), fit, params)
    # the beam never reaches the arm's ±56° stops in this log: the travel does not touch the residuals
    assert set(cal.not_identifiable) == {"linkage.horn_travel_rad"}
    assert any("not identifiable by these logs: linkage.horn_travel_rad" in p for p in cal.problems)
    for name, value in expected.items():
        v = cal.values[name]
        assert v.ci_low <= value <= v.ci_high, (name, v, value)
    assert cal.converged
    # adequate: both channels' residuals are their noise (the strip's 5 mV and the ADC's step; a count's rounding)
    for channel in ("ball", "angle"):
        a = cal.adequacy[channel]
        assert a.ratio < 1.5 and abs(a.lag1) < 0.2, (channel, a)
    back = rig_from_text(describe_toml(cal), origin="fitted")
    assert back.motor.resistance_ohm == cal.values["motor.resistance_ohm"].value
    assert back.beam.inertia_pivot_kgm2 == cal.values["beam.inertia_pivot_kgm2"].value


@pytest.mark.slow
def test_cli_fits_a_bb01_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from twin.app.cli import main

    path = tmp_path / "bb01.csv"
    sim.write_log(str(path), sim.TrueRig().moved(strip_offset_v=0.03, encoder_zero_counts=-4), 8.0, seed=4)
    argv = [
        "calibrate",
        "--rig-file",
        PRESET,
        "--log",
        str(path),
        "--columns",
        PRESET,
        "--out",
        str(tmp_path / "o"),
    ]
    code = main([*argv, "--fit", "angle_reading.zero_counts,motor.resistance_ohm"])
    out = capsys.readouterr().out
    assert "angle channel: RMS" in out and "ball channel: RMS" in out
    assert code == 0, out
    result = json.loads((tmp_path / "o" / "calibration.json").read_text(encoding="utf-8"))
    zero = result["params"]["angle_reading.zero_counts"]
    assert zero["ci_low"] <= -4.0 <= zero["ci_high"]  # the counter reset 4 counts below level
    r = result["params"]["motor.resistance_ohm"]
    assert r["ci_low"] <= 2.6 / FOLD <= r["ci_high"]  # the simulated SRV02's R_m is the preset's
    assert set(result["adequacy"]) == {"ball", "angle"}
    fitted = load_rig(tmp_path / "o" / "rig.toml")
    assert fitted.motor.resistance_ohm == r["value"]
    assert fitted.parts == rig_of(PRESET).parts
    assert (
        main([*argv[:-2], "--fit", "servo.no_load_speed_rad_s"]) == 2
    )  # not the BB01's: refused naming choices
    assert "choose from motor.resistance_ohm" in capsys.readouterr().err
