"""The manual's calibration recipe, run as printed: the commands of the first code block of docs/calibrate.md that
record a log on the twin and fit it (``experiment``, ``calibrate``), read with tests/test_readme_commands.py's
shell reading. A user pasting it gets exit 0 and the twin's own values back: tests/test_readme_in_order.py pastes
it as printed (exit 0 expected) in its one folder and checks the fit there with ``check_calibration`` (the recipe
is run once, not twice)."""

import json
from pathlib import Path

import pytest
from test_readme_commands import ROOT, _commands

from twin.parameters import Parameters


def _calibration_recipe() -> list[list[str]]:
    """The ``ballbeam`` commands of the first code block after the "## Record, fit, use" heading."""
    text = (ROOT / "docs" / "calibrate.md").read_text(encoding="utf-8")
    heading = text.index("\n## Record, fit, use\n")
    start = text.index("```", heading)
    end = text.index("```", start + 3) + 3
    first_line = text[:start].count("\n") + 1
    last_line = text[:end].count("\n") + 1
    return [words for number, words in _commands(text) if first_line <= number <= last_line]


def calibration_recipe() -> list[list[str]]:
    """The recipe's ``experiment`` and ``calibrate`` commands, in order."""
    recipe = [words for words in _calibration_recipe() if words[0] in ("experiment", "calibrate")]
    assert [words[0] for words in recipe] == ["experiment", "calibrate"]
    return recipe


def check_calibration(folder: Path) -> None:
    """The fit the recipe wrote in ``folder`` (where it ran, each command with exit 0): the parameters it was
    told to fit, no problem, and the twin's own values within their intervals."""
    calibrate = calibration_recipe()[1]
    out = folder / calibrate[calibrate.index("--out") + 1]
    result = json.loads((out / "calibration.json").read_text(encoding="utf-8"))
    fitted = calibrate[calibrate.index("--fit") + 1].split(",")
    assert sorted(result["params"]) == sorted(fitted) and not result["problems"]
    truth = Parameters()  # the twin the experiment ran on: the defaults (no --params, no --set)
    for name in fitted:
        group, field = name.split(".")
        true = float(getattr(getattr(truth, group), field))
        v = result["params"][name]
        assert v["ci_low"] <= true <= v["ci_high"], (name, v, true)


@pytest.mark.quick
def test_the_calibration_recipe_records_then_fits_four_parameters() -> None:
    """What tests/test_readme_in_order.py runs as printed (each command exit 0) and checks with
    ``check_calibration``: a log recorded on the twin, then the fit of the four parameters into ``--out``."""
    experiment, calibrate = calibration_recipe()
    assert "--out" in experiment and experiment[experiment.index("--out") + 1] in calibrate
    assert "--out" in calibrate and len(calibrate[calibrate.index("--fit") + 1].split(",")) == 4
