"""Requirements in signal temporal logic (twin.requirements, ``run --spec``): the robustness rtamt's monitor
gives over a run's tick-sampled signals is the one computed here by hand from the same signals; a file that is
not a requirements file, a formula that does not parse or names no signal is refused naming the file and the
requirement."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_checks import refused

from controllers import registry
from twin.app.cli import main
from twin.parameters import ParameterError, Parameters
from twin.requirements import SIGNALS, load_requirements, parse_requirements, robustness, run_signals
from twin.rigs.sim import run_closed_loop

SPEC = {
    "kept": "always (abs(x_m) <= 0.3)",
    "settles": "eventually[0:5] always (abs(x_m - setpoint_m) <= 0.01)",
    "no_stops": "always (abs(theta_rad) <= 0.75)",
    "measured": "always[2:8] (abs(x_meas_m - x_m) <= 0.02)",
}


@pytest.fixture(scope="module")
def run() -> tuple:
    result = run_closed_loop(
        registry.make("appendix-sf"), x0_m=0.14, theta0_rad=-0.2, duration_s=10.0, seed=0
    )
    return result, run_signals(result.log, Parameters())


@pytest.mark.quick
def test_the_monitors_robustness_is_the_hand_computed_one(run: tuple) -> None:
    result, s = run
    got = robustness(parse_requirements({"requirements": SPEC}, "t"), s, 0.02)
    t, x, theta = s["time"], s["x_m"], s["theta_rad"]
    assert got["kept"] == 0.3 - np.max(np.abs(x))
    assert got["no_stops"] == 0.75 - np.max(np.abs(theta))
    margin = 0.01 - np.abs(x - s["setpoint_m"])
    tail_min = np.minimum.accumulate(margin[::-1])[::-1]  # always from each tick on
    assert got["settles"] == pytest.approx(np.max(tail_min[t <= 5.0 + 1e-9]), abs=1e-15)
    window = (t >= 2.0 - 1e-9) & (t <= 8.0 + 1e-9)
    assert got["measured"] == pytest.approx(np.min(0.02 - np.abs(s["x_meas_m"] - x)[window]), abs=1e-15)
    # the signals are the run's ticks from release: the true state as logged, the time from the first of them
    released = result.log.true_time_s >= 0
    assert np.array_equal(x, result.log.true_x_m[released]) and t[0] == 0.0
    assert set(s) == {"time", *SIGNALS}


@pytest.mark.quick
def test_lost_and_at_rail_are_zero_one_signals_of_the_run(run: tuple) -> None:
    result, s = run
    assert set(np.unique(s["lost"])) <= {0.0, 1.0} and not s["lost"].any()
    assert np.array_equal(s["at_rail"] == 1.0, np.abs(s["motor_v"]) >= Parameters().amplifier.rail_v - 1e-9)
    lost = run_closed_loop(registry.make("appendix-sf"), x0_m=0.3, theta0_rad=-0.7, duration_s=4.0, seed=0)
    signals = run_signals(lost.log, Parameters())
    assert lost.verdict.ball_lost and signals["lost"][-1] == 1.0
    r = robustness(parse_requirements({"requirements": {"kept": "always (lost <= 0)"}}, "t"), signals, 0.02)
    assert r["kept"] < 0


@pytest.mark.quick
def test_bad_requirements_are_refused_naming_the_file_and_the_requirement(tmp_path: Path) -> None:
    cases = {
        "no table": ("x = 1\n", "no [requirements] table"),
        "unknown signal": ('[requirements]\nr = "always (y <= 1)"\n', "requirement 'r': unknown signal 'y'"),
        "syntax": ('[requirements]\nr = "always (x_m <= "\n', "requirement 'r': 1:"),
        "not text": ("[requirements]\nr = 3\n", "requirement 'r' = 3"),
        "not toml": ("[requirements\n", "not a TOML requirements file"),
    }
    for name, (text, needle) in cases.items():
        path = tmp_path / f"{name.replace(' ', '_')}.toml"
        path.write_text(text)
        with pytest.raises(ParameterError, match=None) as caught:
            load_requirements(path)
        assert str(path) in str(caught.value) and needle in str(caught.value), (name, str(caught.value))


@pytest.mark.quick
def test_run_spec_prints_each_robustness_and_fails_a_violated_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = tmp_path / "spec.toml"
    spec.write_text('[requirements]\nkept = "always (abs(x_m) <= 0.3)"\ntight = "always (abs(x_m) <= 0.1)"\n')
    argv = ["run", "--controller", "appendix-sf", "--x0", "0.14", "--theta0", "-0.2", "--duration", "6"]
    assert main([*argv, "--spec", str(spec), "--json"]) == 1  # held, but "tight" is violated (x0 = 0.14)
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["held"] and summary["requirements"]["kept"] > 0 > summary["requirements"]["tight"]
    assert "requirements violated: tight" in captured.err
    refused(capsys, [*argv, "--spec", str(tmp_path / "missing.toml")], "missing.toml")


@pytest.mark.quick
def test_the_windowed_signals_at_the_last_tick_are_the_verdicts_final_window(run: tuple) -> None:
    result, s = run
    v = result.verdict
    assert s["x_mean_m"][-1] == v.steady_x_m and s["theta_mean_rad"][-1] == v.steady_theta_rad
    assert s["x_pp_m"][-1] == v.limit_cycle_x_pp_m and s["theta_pp_rad"][-1] == v.limit_cycle_theta_pp_rad
    assert s["rail_share"][-1] == v.saturated_fraction
    # at an earlier tick: the ticks within the window before it, by hand
    t = result.log.true_time_s[result.log.true_time_s >= 0]
    i = 300
    window = (t >= t[i] - 3.0) & (np.arange(t.size) <= i)
    assert s["x_mean_m"][i] == np.mean(s["x_m"][window]) and s["x_pp_m"][i] == np.ptp(s["x_m"][window])
    assert s["rail_share"][i] == np.mean(s["at_rail"][: i + 1])
