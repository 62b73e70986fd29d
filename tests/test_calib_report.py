"""What ``ballbeam calibrate`` and ``ballbeam compare`` write (calib.report, calib.report_render,
calib.compare_render): the files hold the numbers the analyses computed, on one short experiment log."""

from __future__ import annotations

from pathlib import Path

import pytest

from calib.compare import compare
from calib.compare_render import render_markdown as compare_markdown
from calib.experiments import run_experiment
from calib.identify import Calibration, calibrate
from calib.logs import rig_log
from calib.report import write_report
from calib.report_render import render_markdown as report_markdown
from twin.log import RunLog
from twin.parameters import Parameters


@pytest.fixture(scope="module")
def square_log() -> RunLog:
    return run_experiment("square", Parameters(), duration_s=6.0).log  # identification needs 5 s


@pytest.fixture(scope="module")
def calibration(square_log: RunLog) -> Calibration:
    return calibrate([rig_log(square_log)], fit=["motor.resistance_ohm"], diagnose=False, max_nfev=5)


@pytest.mark.quick
def test_the_report_holds_the_fitted_value_and_its_parameter_file_loads_it(
    calibration: Calibration, tmp_path: Path
) -> None:
    fitted = calibration.values["motor.resistance_ohm"]
    out = write_report(calibration, tmp_path / "cal")
    loaded = Parameters.from_file(out / "params.toml")
    assert loaded.motor.resistance_ohm == fitted.value == calibration.params.motor.resistance_ohm
    text = (out / "report.md").read_text(encoding="utf-8")
    assert text == report_markdown(calibration)
    row = next(line for line in text.splitlines() if line.startswith("| motor.resistance_ohm |"))
    assert f"{fitted.value:.6g}" in row and f"{fitted.ci_low:.6g}" in row and f"{fitted.ci_high:.6g}" in row
    assert f"{calibration.n_windows} windows, {calibration.n_ticks} ticks" in text
    with pytest.raises(FileExistsError):
        write_report(calibration, out)  # never overwritten unless asked


@pytest.mark.quick
def test_the_comparison_report_states_the_verdict_the_comparison_reached(square_log: RunLog) -> None:
    result = compare([("square.mat", square_log)], Parameters())
    text = compare_markdown(result)
    assert text.startswith("# The twin against the log")
    assert ("**Conforms**" in text) == result.passed and ("**Does not conform**" in text) != result.passed
    for failure in result.failures:
        assert failure in text
    assert f"{result.windowed.n_windows} windows of 1 s" in text
