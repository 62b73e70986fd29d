"""Requirement formulas are checked when their file is loaded, before any run, against the run's duration and
period (twin.requirements.parse_requirements, check_timing): time bounds below 0, reversed, not whole DAQ
periods or past the run's end, a division by zero or by a signal, functions that can fail on a run, numbers
that are not finite and nesting too deep are refused (exit 2, naming the file, the requirement and the value).
A robustness of ±inf or NaN is stated finite, so the JSON a command prints is JSON."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_checks import refused

from twin.app.cli import main
from twin.requirements import ROBUSTNESS_LIMIT, Requirement, robustness, stated

ROOT = Path(__file__).resolve().parents[1]
SPREAD = ROOT / "docs" / "examples" / "spread.toml"
RUN = ["run", "--controller", "appendix-sf", "--x0", "0.1", "--theta0", "0", "--duration", "2"]

# formula: what the refusal must name (beyond the file and the requirement)
BAD = {
    "eventually[0:1e12] (abs(x_m) <= 0.3)": ("eventually[0:1e+12]", "past the run's 2 s"),
    "eventually[0:0.013] (abs(x_m) <= 0.3)": ("0.013 s is not a whole number of DAQ periods", "0 and 0.02"),
    "eventually[0:510ms] (abs(x_m) <= 0.3)": ("0.51 s is not a whole number", "0.5 and 0.52"),
    "eventually[-1:1] (abs(x_m) <= 0.3)": ("eventually[-1:1]", "below 0"),
    "always[1.5:0.5] (abs(x_m) <= 0.3)": ("always[1.5:0.5]", "lower bound 1.5 s is above the upper 0.5 s"),
    "always[0:1.5] (eventually[0:1] (x_m <= 1))": ("eventually[0:1]", "looks 2.5 s ahead"),
    "always (x_m / 0 <= 0.3)": ("divides by 0", "division by zero"),
    "always (x_m / setpoint_m <= 0.3)": ("divides by setpoint_m",),
    "always (sqrt(x_m) <= 1)": ("sqrt(",),
    "always (exp(x_m) <= 1)": ("exp(",),
    "always (x_m <= 1e400)": ("not finite",),
    "(" * 41 + "x_m" + ")" * 41 + " <= 1": ("nested 41 deep", "at most 40"),
    "always " * 45 + "(x_m <= 1)": ("nested deeper than 40",),
}


@pytest.fixture(autouse=True)
def _no_search(monkeypatch: pytest.MonkeyPatch) -> None:
    """A falsification or certification that starts fails the test (``no_work`` covers the other jobs)."""

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("the work started although an argument was bad")

    monkeypatch.setattr("twin.app.falsify.falsify", fail)
    monkeypatch.setattr("twin.app.certify.certify", fail)


def _spec(tmp_path: Path, formula: str) -> Path:
    path = tmp_path / "req.toml"
    path.write_text(f'[requirements]\nok = "always (lost < 0.5)"\nbad = {json.dumps(formula)}\n')
    return path


@pytest.mark.quick
@pytest.mark.parametrize("formula", list(BAD))
def test_a_formula_unfit_for_the_run_is_refused_before_it(
    formula: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], no_work: None
) -> None:
    spec = _spec(tmp_path, formula)
    refused(capsys, [*RUN, "--spec", str(spec)], str(spec), "requirement 'bad'", *BAD[formula])


@pytest.mark.quick
def test_every_command_with_a_spec_checks_it_against_its_own_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_work: None
) -> None:
    spec = _spec(tmp_path, "eventually[0:12] (abs(x_m) <= 0.3)")
    box = ["--x0", "0.1:0.2", "--theta0", "-0.1:0"]
    falsify = ["falsify", "--controller", "appendix-sf", "--spec", str(spec), *box]
    refused(capsys, [*falsify, "--duration", "10"], str(spec), "requirement 'bad'", "past the run's 10 s")
    certify = ["certify", "--controller", "appendix-sf", "--spec", str(spec), "--spread", str(SPREAD), *box]
    refused(capsys, [*certify, "--duration", "5"], str(spec), "requirement 'bad'", "past the run's 5 s")
    # validate's runs are 15 s (nominal) and 10 s (region): a formula the region check asks is held to 10 s
    vspec = tmp_path / "v.toml"
    vspec.write_text(
        '[requirements]\nlong = "eventually[0:12] (abs(x_m) <= 0.3)"\n[validate]\nregion = ["long"]\n'
    )
    refused(capsys, ["validate", "--controller", "appendix-sf", "--spec", str(vspec)], "'long'", "run's 10 s")
    # the period is the run's: 0.03 s is whole periods of 0.01 s but not of the default 0.02 s
    spec = _spec(tmp_path, "eventually[0:0.03] (abs(x_m) <= 0.3)")
    refused(capsys, [*RUN, "--spec", str(spec)], "0.03 s is not a whole number of DAQ periods (0.02 s)")


@pytest.mark.quick
def test_a_deeply_nested_file_is_refused_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    deep = tmp_path / "deep.toml"
    deep.write_text("[requirements]\na = " + "{ b = " * 3000 + "1" + " }" * 3000 + "\n")
    refused(capsys, [*RUN, "--spec", str(deep)], str(deep), "nested too deep")
    table = tmp_path / "table.toml"
    table.write_text("[requirements]\na = " + "{ b = " * 200 + "1" + " }" * 200 + "\n")
    line = refused(capsys, [*RUN, "--spec", str(table)], str(table), "requirement 'a' = a dict", "in quotes")
    assert len(line) < 300


@pytest.mark.quick
def test_an_infinite_or_undefined_robustness_is_stated_finite() -> None:
    assert stated(float("inf")) == ROBUSTNESS_LIMIT and stated(float("-inf")) == -ROBUSTNESS_LIMIT
    assert stated(float("nan")) == -ROBUSTNESS_LIMIT and stated(-0.25) == -0.25
    empty = {"time": []}
    assert robustness((Requirement("r", "always (x_m <= 1)"),), empty, 0.02) == {"r": -ROBUSTNESS_LIMIT}


def _strict(text: str) -> dict:
    def refuse(constant: str) -> None:
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.mark.quick
def test_run_json_with_an_infinite_robustness_is_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Nested in `always`, the window [0.5, 1] s lies past the run at its last ticks: rtamt's −inf.
    spec = _spec(tmp_path, "always (eventually[0.5:1] (x_m <= 1))")
    assert main([*RUN, "--spec", str(spec), "--json"]) == 1
    summary = _strict(capsys.readouterr().out)
    assert summary["requirements"]["bad"] == -ROBUSTNESS_LIMIT
    assert summary["requirements"]["ok"] == 0.5
    # a formula that fits the run exactly (its bound is the run's duration) is judged
    spec = _spec(tmp_path, "eventually[0:2] (abs(x_m) <= 0.3)")
    assert main([*RUN, "--spec", str(spec), "--json"]) == 1  # the run is shorter than the verdict's window
    assert _strict(capsys.readouterr().out)["requirements"]["bad"] > 0
