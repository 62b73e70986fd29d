"""A fitted parameter the logs cannot identify (its interval not finite, or the residuals not depending on it)
is reported as such by name, calibrate exits 1, and it is left out of the fit's files: params.toml keeps its
start value and calibration.json (valid JSON) lists it under "not_identifiable", so the readers of those
files (--params, --calibration) take them as they are."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calib.experiments import run_experiment
from twin.app.cli import main
from twin.app.montecarlo import load_calibration_spread
from twin.log import save_mat
from twin.parameters import Parameters

RAIL = "amplifier.rail_v"


@pytest.fixture(scope="module")
def quiet_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """6 s of the dither experiment on the twin: its command stays far below the ±12 V rails."""
    run = run_experiment("dither", Parameters(), duration_s=6.0, seed=1)
    assert np.max(np.abs(run.log.aout)) < 0.5 * Parameters().amplifier.rail_v
    path = tmp_path_factory.mktemp("log") / "data_file.mat"
    save_mat(run.log, path)
    return path


def _strict(text: str) -> dict:
    def refuse(constant: str) -> None:
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.mark.slow
def test_a_rail_the_log_never_reaches_is_not_identifiable(
    quiet_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cal"
    argv = ["calibrate", str(quiet_log), "--fit", RAIL, "--out", str(out), "--json"]
    assert main([*argv, "--set", "amplifier.rail_v=11"]) == 1
    captured = capsys.readouterr()
    problem = [line for line in captured.err.splitlines() if "not identifiable" in line]
    assert problem and RAIL in problem[0] and "never reaches the rails" in problem[0], captured.err
    assert "kept at its start 11 V" in problem[0]
    report = _strict(captured.out)
    assert report["params"] == {} and set(report["not_identifiable"]) == {RAIL}
    assert report["not_identifiable"][RAIL]["kept"] == 11.0
    assert _strict((out / "calibration.json").read_text()) == report
    # the parameter file keeps the user's value, not the fit's start below the rail (9 V) or a NaN
    assert Parameters.from_file(out / "params.toml").amplifier.rail_v == 11.0
    assert "nan" not in (out / "params.toml").read_text().lower()


@pytest.mark.slow
def test_the_identified_values_are_kept_and_read_back(
    quiet_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cal"
    fit = f"motor.resistance_ohm,{RAIL}"
    assert main(["calibrate", str(quiet_log), "--fit", fit, "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert f"{RAIL}" in captured.out and "not identifiable by these logs" in captured.out
    assert "nan" not in captured.out and f"calibrate: not identifiable by these logs: {RAIL}" in captured.err
    report = _strict((out / "calibration.json").read_text())
    assert set(report["params"]) == {"motor.resistance_ohm"}
    assert report["correlation"]["names"] == ["motor.resistance_ohm"]
    assert np.shape(report["correlation"]["matrix"]) == (1, 1)
    params = Parameters.from_file(out / "params.toml")
    assert params.amplifier.rail_v == Parameters().amplifier.rail_v
    assert params.motor.resistance_ohm == pytest.approx(report["params"]["motor.resistance_ohm"]["value"])
    # --calibration's reader takes the folder: the spread is over what the logs identified
    _, spread = load_calibration_spread(out)
    assert spread.names == ("motor.resistance_ohm",)
