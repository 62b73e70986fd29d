"""Dynamic identification: recovery of known parameters from twin logs and from an independent simulator,
a held-out log, and the command line."""

import json
from pathlib import Path

import numpy as np
import pytest
from independent_rig import simulate

from calib.experiments import STUDY_FIT, STUDY_START, replay_rms, run_experiment
from calib.identify import FITTABLE, CalibrationError, calibrate
from calib.logs import RigLog, rig_log
from twin.app.cli import main
from twin.log import save_mat
from twin.parameters import Parameters

FIT = list(STUDY_FIT)
# A rig whose pivot bearing has noticeable viscous friction (the thesis neglects it: 0), the start of the fits.
NOMINAL = Parameters().with_overrides(STUDY_START)
# Acceptance: resistance and inertia within 3 %, pivot damping within 15 %, zeroing error within 0.5 mrad.
TOLERANCE = {FIT[0]: 0.03, FIT[1]: 0.03, FIT[2]: 0.15, FIT[3]: 0.5e-3}


def _truth(seed: int) -> dict[str, float]:
    """Up to ±20 % from nominal and a zeroing error up to ±0.015 rad."""
    rng = np.random.default_rng(100 + seed)
    f = rng.uniform(-0.2, 0.2, 3)
    return {
        FIT[0]: NOMINAL.motor.resistance_ohm * (1 + f[0]),
        FIT[1]: NOMINAL.beam.inertia_pivot_kgm2 * (1 + f[1]),
        FIT[2]: NOMINAL.beam.pivot_damping_nm_s_per_rad * (1 + f[2]),
        FIT[3]: float(rng.uniform(-0.015, 0.015)),
    }


def _error(name: str, fitted: float, true: float) -> float:
    return abs(fitted - true) if name == FIT[3] else abs(fitted / true - 1)


@pytest.mark.study  # five calibrations, ~2 min on one core: run with -m study
def test_recovery_from_twin_logs_five_seeds() -> None:
    """60 s of the recommended experiment on the twin (full sensor chain, noise on) for five perturbed rigs:
    every parameter within tolerance, and the 95 % intervals contain the truth in at least 4 of 5 seeds."""
    inside = {name: 0 for name in FIT}
    for seed in range(1, 6):
        truth = _truth(seed)
        run = run_experiment("square", NOMINAL.with_overrides(truth), duration_s=60.0, seed=seed)
        cal = calibrate([rig_log(run.log)], FIT, NOMINAL)
        assert cal.converged, (seed, cal.message)
        for name in FIT:
            v = cal.values[name]
            assert _error(name, v.value, truth[name]) <= TOLERANCE[name], (seed, name, v, truth[name])
            inside[name] += v.ci_low <= truth[name] <= v.ci_high
    assert all(count >= 4 for count in inside.values()), inside


@pytest.mark.slow
@pytest.mark.parametrize(
    "seed", [1, pytest.param(2, marks=pytest.mark.study), pytest.param(3, marks=pytest.mark.study)]
)  # one seed in the default run, the three in the study tier (the run's time)
def test_recovery_from_an_independent_simulator(seed: int) -> None:
    """Logs the twin did not make (tests/independent_rig.py: mass-matrix equations, adaptive DOP853, its own
    noise, spikes, encoder and controller): the same tolerances."""
    rng = np.random.default_rng(200 + seed)
    f = rng.uniform(-0.2, 0.2, 3)
    truth = {
        FIT[0]: 9.4 * (1 + f[0]),
        FIT[1]: 4e-3 * (1 + f[1]),
        FIT[2]: 1e-3 * (1 + f[2]),
        FIT[3]: float(rng.uniform(-0.015, 0.015)),
    }
    log = simulate(NOMINAL.with_overrides(truth), duration_s=60.0, seed=seed)
    rl = RigLog(
        path=Path("independent"),
        time_s=log["timem"][1:],
        ball_v=log["datam1"][1:],
        angle_v=log["datam2"][1:],
        command_v=log["aout"][1:],
    )
    cal = calibrate([rl], FIT, NOMINAL)
    for name in FIT:
        assert _error(name, cal.values[name].value, truth[name]) <= TOLERANCE[name], (name, cal.values[name])


@pytest.mark.study  # a calibration and a held-out log, ~30 s: run with -m study
def test_fitted_parameters_predict_a_held_out_log_better_than_nominal() -> None:
    """Fit on one log, replay a second log of the same rig (another seed of the experiment) in closed loop."""
    truth = NOMINAL.with_overrides(_truth(4))
    fit_log = run_experiment("square", truth, duration_s=60.0, seed=11)
    held_out = rig_log(run_experiment("square", truth, duration_s=30.0, seed=12).log)
    cal = calibrate([rig_log(fit_log.log)], FIT, NOMINAL)
    nominal = replay_rms(held_out, "square", 12, NOMINAL)
    fitted = replay_rms(held_out, "square", 12, cal.params)
    assert fitted["ball_m"] < 0.5 * nominal["ball_m"]
    assert fitted["angle_rad"] < 0.5 * nominal["angle_rad"]


@pytest.mark.slow
def test_a_short_log_recovers_resistance_and_zeroing_error() -> None:
    """20 s, two parameters: the quick check of the whole path (window cutting, model, fit, intervals)."""
    truth = {"motor.resistance_ohm": 10.8, "angle_sensor.zeroing_error_rad": -0.006}
    run = run_experiment("square", NOMINAL.with_overrides(truth), duration_s=20.0, seed=3)
    cal = calibrate([rig_log(run.log)], list(truth), NOMINAL)
    assert cal.values["motor.resistance_ohm"].value == pytest.approx(10.8, rel=0.01)
    assert cal.values["angle_sensor.zeroing_error_rad"].value == pytest.approx(-0.006, abs=0.3e-3)
    assert cal.rms_after["angle_rad"] < cal.rms_before["angle_rad"]
    assert cal.params.motor.resistance_ohm == cal.values["motor.resistance_ohm"].value


@pytest.mark.quick
def test_a_ball_reading_gain_is_folded_into_the_sensor_curve() -> None:
    out = Parameters().with_values({"ball_reading.gain": 1.1, "ball_reading.offset_m": 0.002})
    sw = out.software
    before = np.asarray(Parameters().ball_sensor.curve_volts_v) * sw.ball_gain_m_per_v + sw.ball_offset_m
    after = np.asarray(out.ball_sensor.curve_volts_v) * sw.ball_gain_m_per_v + sw.ball_offset_m
    np.testing.assert_allclose(after, 1.1 * before + 0.002, atol=1e-15)


def test_the_fittable_units_and_bounds_are_the_parameters_own() -> None:
    """FitSpec restates neither a unit nor a physical bound: both are the parameter's declaration, and the
    range the fit searches lies within the physical bounds."""
    from calib.identify import FitSpec
    from twin.parameters import ParameterError, declaration, within_bounds

    for name, spec in FITTABLE.items():
        assert spec.unit == declaration(name)["unit"]
        assert within_bounds(name, spec.lower) and within_bounds(name, spec.upper)
    units = {
        n: FITTABLE[n].unit for n in ("motor.resistance_ohm", "ball_reading.gain", "ball_reading.offset_m")
    }
    assert units == {"motor.resistance_ohm": "Ω", "ball_reading.gain": "-", "ball_reading.offset_m": "m"}
    with pytest.raises(ValueError, match="motor.resistance_ohm: the search range \\[0.0, 50.0\\]"):
        FitSpec("motor.resistance_ohm", 0.0, 50.0, 10.0, "beyond its physical bound (> 0)")
    with pytest.raises(ParameterError, match="unknown parameter 'motor.mass'"):
        FitSpec("motor.mass", 0.1, 1.0, 1.0, "no such parameter")


@pytest.mark.quick
def test_unknown_or_repeated_parameters_are_refused() -> None:
    run = run_experiment("dither", NOMINAL, duration_s=6.0, seed=1)
    with pytest.raises(CalibrationError, match="cannot fit \\['motor.mass'\\]"):
        calibrate([rig_log(run.log)], ["motor.mass"])
    with pytest.raises(CalibrationError, match="twice"):
        calibrate([rig_log(run.log)], ["motor.resistance_ohm", "motor.resistance_ohm"])
    assert set(FITTABLE) >= set(FIT)


@pytest.mark.slow
def test_cli_calibrate_writes_a_parameter_file_the_twin_loads(tmp_path: Path, capsys) -> None:
    log = tmp_path / "data_file.mat"
    save_mat(
        run_experiment("square", NOMINAL.with_overrides({"motor.resistance_ohm": 10.0}), duration_s=12.0).log,
        log,
    )
    out = tmp_path / "cal"
    fit = (
        "motor.resistance_ohm,ball_sensor.dropout_rate_hz"  # the rate is estimated apart from the smooth fit
    )
    args = ["calibrate", str(log), "--fit", fit, "--out", str(out), "--json"]
    assert main([*args, "--set", "beam.pivot_damping_nm_s_per_rad=0.001"]) == 0
    report = json.loads(capsys.readouterr().out)
    entry = report["params"]["motor.resistance_ohm"]
    assert set(entry) == {"value", "ci_low", "ci_high", "initial", "sd", "statistical_half", "unit"}
    # The interval is Student's t times the standard uncertainty: wider than the normal 1.96 σ, symmetric.
    half = (entry["ci_high"] - entry["ci_low"]) / 2
    assert half / entry["sd"] >= 1.959 and entry["value"] == pytest.approx(entry["ci_low"] + half)
    assert report["correlation"]["names"] == ["motor.resistance_ohm"]
    assert entry["value"] == pytest.approx(10.0, rel=0.01) and entry["initial"] == 9.4
    assert {p.name for p in out.iterdir()} >= {
        "params.toml",
        "calibration.json",
        "report.md",
        "fit.png",
        "correlation.png",
    }
    assert Parameters.from_file(out / "params.toml").motor.resistance_ohm == pytest.approx(entry["value"])
    # An existing output is not overwritten; nothing is computed for it.
    before = (out / "calibration.json").read_bytes()
    assert main(args) == 2
    assert "exists; not overwritten" in capsys.readouterr().err
    assert (out / "calibration.json").read_bytes() == before
    assert main(["calibrate", str(log), "--fit", "motor.colour"]) == 2
    assert "choose from" in capsys.readouterr().err


@pytest.mark.slow
def test_the_contact_dropout_rate_is_estimated_from_the_outliers() -> None:
    """20 contact losses per second (4× the default) in a 60 s twin log: the estimate's interval holds it."""
    truth = NOMINAL.with_overrides({"ball_sensor.dropout_rate_hz": 20.0})
    run = run_experiment("square", truth, duration_s=60.0, seed=3)
    cal = calibrate([rig_log(run.log)], ["ball_sensor.dropout_rate_hz"], NOMINAL)
    v = cal.values["ball_sensor.dropout_rate_hz"]
    assert v.value == pytest.approx(20.0, rel=0.2)
    assert v.ci_low <= 20.0 <= v.ci_high
    assert cal.params.ball_sensor.dropout_rate_hz == v.value
