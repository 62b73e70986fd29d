"""README.md's calibration recipe, run as printed: the commands of the code block under "## Calibration" that
record a log on the twin and fit it (``experiment``, ``calibrate``), read with tests/test_readme_commands.py's
shell reading, in a fresh directory. A user pasting it gets exit 0 and the twin's own values back."""

import json
from pathlib import Path

import pytest
from test_readme_commands import README, _commands

from twin.app.cli import main
from twin.parameters import Parameters


def _calibration_recipe() -> list[list[str]]:
    """The ``ballbeam`` commands of the first code block after the "## Calibration" heading."""
    text = README.read_text(encoding="utf-8")
    heading = text.index("\n## Calibration\n")
    start = text.index("```", heading)
    end = text.index("```", start + 3) + 3
    first_line = text[:start].count("\n") + 1
    last_line = text[:end].count("\n") + 1
    return [words for number, words in _commands(text) if first_line <= number <= last_line]


@pytest.mark.slow
def test_the_readme_calibration_recipe_runs_as_printed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    recipe = [words for words in _calibration_recipe() if words[0] in ("experiment", "calibrate")]
    assert [words[0] for words in recipe] == ["experiment", "calibrate"]
    monkeypatch.chdir(tmp_path)
    for words in recipe:
        code = main(words)
        assert code == 0, (words, capsys.readouterr().err[-2000:])
    calibrate = recipe[1]
    out = Path(calibrate[calibrate.index("--out") + 1])
    result = json.loads((out / "calibration.json").read_text(encoding="utf-8"))
    fitted = calibrate[calibrate.index("--fit") + 1].split(",")
    assert sorted(result["params"]) == sorted(fitted) and not result["problems"]
    truth = Parameters()  # the twin the experiment ran on: the defaults (no --params, no --set)
    for name in fitted:
        group, field = name.split(".")
        true = float(getattr(getattr(truth, group), field))
        v = result["params"][name]
        assert v["ci_low"] <= true <= v["ci_high"], (name, v, true)
