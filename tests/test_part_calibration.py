"""The part-built rig's dynamic calibration (calib.part_identify) on logs of an independent simulator of the
open-ball-and-beam preset (tests/obb_simulator.py, numpy only)."""

from __future__ import annotations

from pathlib import Path

import pytest

from calib.part_identify import (
    CALIBRATION_ONLY,
    PART_FITTABLE,
    PartCalibration,
    calibrate_part_rig,
    describe_toml,
)
from calib.serial_log import SerialLogError, read_serial_log
from tests import obb_simulator as sim
from twin.parameters import declaration
from twin.parts.description import rig_from_text, rig_of

PRESET = "open-ball-and-beam"


@pytest.mark.quick
def test_fittable_names_are_fields_or_calibration_only() -> None:
    for name in PART_FITTABLE:
        unit = CALIBRATION_ONLY.get(name) or declaration(name)["unit"]
        assert unit == PART_FITTABLE[name].unit


@pytest.mark.quick
def test_simulator_linkage_level_and_ratio() -> None:
    # on paper: at the preset's neutral the horn is nearly horizontal and the rod nearly vertical, so the beam is
    # level within a milliradian and dθ/dφ is close to c/L = 0.0207587/0.23 = 0.0903 … times the rod's lean
    theta, ratio, _ = sim.beam_angle_rates(sim.TrueRig().horn_neutral_rad)
    assert abs(theta) < 1e-3
    assert 0.09 < ratio < 0.15


@pytest.mark.quick
def test_malformed_log_refused_naming_line_and_column(tmp_path: Path) -> None:
    lines = sim.simulate(sim.TrueRig(), 1.0, seed=3)
    t, d, p = lines[12].split(",")
    lines[12] = f"{t},{d},-40"  # a pulse no servo takes: a wrong column or unit
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(SerialLogError, match=r"line 13, column 3 \(command\)"):
        read_serial_log(path, PRESET, rig_of(PRESET))


@pytest.mark.quick
def test_fitted_description_loads_back() -> None:
    start = rig_of(PRESET).with_overrides({"servo.no_load_speed_rad_s": 5.0, "linkage.horn_neutral_rad": 0.8})
    cal = PartCalibration(start, {}, {}, {}, [], True, "", 0.0, 0, 0.0, 0.0)
    back = rig_from_text(describe_toml(cal), origin="fitted")
    assert back.group("servo").no_load_speed_rad_s == 5.0
    assert back.group("linkage").horn_neutral_rad == 0.8
    assert back.parts == start.parts


@pytest.mark.slow
def test_recovers_moved_parameters_within_intervals(tmp_path: Path) -> None:
    # the simulated rig away from the preset by known amounts: the horn splined 40 mrad lower, a faster servo
    # (7.0 rad/s against 6.545) with a 15 ms loop lag (13.3 ms)
    truth = sim.TrueRig().moved(horn_neutral_rad=0.84469 - 0.04, speed_limit_rad_s=7.0, time_constant_s=0.015)
    path = tmp_path / "obb.csv"
    sim.write_log(str(path), truth, 60.0, seed=5)  # seeds 1–4 derived MODEL_RESOLUTION: this one is held out
    params = rig_of(PRESET)
    log = read_serial_log(path, PRESET, params)
    fit = [
        "linkage.horn_neutral_rad",
        "servo.no_load_speed_rad_s",
        "servo.saturation_error_rad",
        "linkage.horn_travel_rad",
    ]
    cal = calibrate_part_rig(log, fit, params, max_nfev=100)
    # the beam never reaches the horn's stops in this log (its pulses stay within 1287…1735 µs, the stops at
    # 1040 and 1960 µs): the travel hardly touches the residuals
    assert set(cal.not_identifiable) == {"linkage.horn_travel_rad"}
    assert any("not identifiable by these logs: linkage.horn_travel_rad" in p for p in cal.problems)
    # on paper: the part's unsaturated loop lags by b/k_p = (τ_s/ω₀)/(τ_s/e_sat) = e_sat/ω₀ (supply = rated), so
    # the simulator's lag T and speed ω give e_sat = T·ω
    expected = {
        "linkage.horn_neutral_rad": truth.horn_neutral_rad,
        "servo.no_load_speed_rad_s": truth.speed_limit_rad_s,
        "servo.saturation_error_rad": truth.time_constant_s * truth.speed_limit_rad_s,
    }
    for name, value in expected.items():
        v = cal.values[name]
        assert v.ci_low <= value <= v.ci_high, (name, v, value)
    assert cal.converged
    # adequate: the ball channel's residual is the sensor's noise (white, near its floor)
    ball = cal.adequacy["ball"]
    assert ball.ratio < 1.5 and abs(ball.lag1) < 0.2
    # the fitted rig loads back as a rig description with the fitted values
    back = rig_from_text(describe_toml(cal), origin="fitted")
    assert back.group("linkage").horn_neutral_rad == cal.values["linkage.horn_neutral_rad"].value
    assert back.group("servo").no_load_speed_rad_s == cal.values["servo.no_load_speed_rad_s"].value


@pytest.mark.quick
def test_cli_refuses_malformed_serial_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from twin.app.cli import main

    lines = sim.simulate(sim.TrueRig(), 1.0, seed=4)
    t, _, p = lines[20].split(",")
    lines[20] = f"{t},-7,{p}"  # a negative distance: no VL53L0X reads one
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    argv = ["calibrate", "--rig-file", PRESET, "--log", str(path), "--columns", PRESET]
    assert main([*argv, "--fit", "linkage.horn_neutral_rad"]) == 2
    assert "line 21, column 2" in capsys.readouterr().err
    good = tmp_path / "good.csv"
    good.write_text("\n".join(sim.simulate(sim.TrueRig(), 1.0, seed=4)) + "\n", encoding="utf-8")
    argv[4] = str(good)
    assert (
        main([*argv, "--fit", "servo.stall_torque_nm"]) == 2
    )  # not fittable here: refused naming the choices
    assert "choose from servo.no_load_speed_rad_s" in capsys.readouterr().err


@pytest.mark.slow
def test_fit_model_is_the_reference_plant(tmp_path: Path) -> None:
    # the fit's compiled windows against ReferencePlant (twin.reference) driven tick by tick with the same targets
    # at the physics timestep: the same equations, so the same trajectory (numba compiles the kernel: slow)
    import numpy as np

    from calib.part_identify import _kernel, _Problem
    from twin.reference import ReferencePlant

    path = tmp_path / "obb.csv"
    sim.write_log(str(path), sim.TrueRig(), 4.0, seed=6)
    params = rig_of(PRESET)
    problem = _Problem(read_serial_log(path, PRESET, params), params, ["linkage.horn_neutral_rad"], 1.0)
    link = params.group("linkage")
    w, n = 1, int(round(problem.win.period_s / params.physics.timestep_s))
    theta0 = float(link.theta_rad(problem.win.target[w, 0] + link.horn_neutral_rad))
    plant = ReferencePlant(params)
    plant.reset(0.01, theta0)
    xs_ref = [0.01]
    for k in range(problem.K):
        plant.advance(np.full(n, problem.win.target[w, k]))
        xs_ref.append(float(plant.state()[0]))
    c = problem.columns(problem.starts[None, :])
    q = problem.q
    consts = np.array([*q.as_row()[:12], q.coulomb_nm, problem.offset_m, problem.weight_nm])
    rows = np.hstack([*c.drive, *c.servo, c.shaft_inertia, c.alpha, c.lo, c.hi, c.rolling])
    xs = np.empty((1, problem.nw, problem.K * n + 1))
    end = np.empty((1, problem.nw, 4))
    s0 = np.zeros((1, problem.nw, 4))
    s0[0, w] = [0.01, theta0, 0.0, 0.0]
    _kernel()(
        consts,
        rows,
        np.ascontiguousarray(problem.win.target),
        s0,
        n,
        problem.win.period_s / n,
        problem.W,
        xs,
        end,
    )
    assert np.max(np.abs(xs[0, w, ::n] - np.array(xs_ref))) < 1e-6
