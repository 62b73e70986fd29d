"""The manual's examples (README.md and the pages of docs/, tests/test_readme_commands.py's ``PAGES``) run as
printed."""

import contextlib
import io
import re
from pathlib import Path

import pytest
from test_readme_commands import manual_text

from twin.parameters import Parameters

README = manual_text()


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.S)


def test_the_controller_example_holds_the_ball() -> None:
    (code,) = [b for b in _blocks("python") if "class MyController" in b]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):  # run as a script (imported, it defines the class alone)
        exec(compile(code, "docs/validate.md", "exec"), {"__name__": "__main__"})
    assert out.getvalue().startswith("True held")


@pytest.mark.quick
def test_the_parameter_file_example_loads(tmp_path: Path) -> None:
    # the parameter file (the rig descriptions of docs/rigs.md name parts: tests/test_rig_description.py)
    (text,) = [b for b in _blocks("toml") if "[requirements]" not in b and "part = " not in b]
    path = tmp_path / "rig.toml"
    path.write_text(text)
    params = Parameters.from_file(path)
    assert params.beam.pivot_friction_nm == 1e-3 and params.ball_sensor.curve_volts_v == (-4.62, 0.0, 4.60)


def test_the_requirements_example_parses_and_holds_for_the_hardware_start(tmp_path: Path) -> None:
    """The "Requirements and counterexamples" file as written: each formula parses; appendix-sf from the README's
    start meets all three."""
    from twin.app.cli import main

    (text,) = [b for b in _blocks("toml") if "[requirements]" in b]
    path = tmp_path / "requirements.toml"
    path.write_text(text)
    argv = ["run", "--controller", "appendix-sf", "--x0", "0.14", "--theta0", "-0.2", "--duration", "10"]
    assert main([*argv, "--spec", str(path), "--json"]) == 0


def test_the_python_surface_example_runs_the_one_loop() -> None:
    """The "Using the twin from Python" example: appendix-sf holds the ball from (0.15 m, −0.2 rad), 500 ticks
    recorded after the start block, on the one loop."""
    (code,) = [b for b in _blocks("python") if "twin.ClosedLoop(" in b]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "docs/connect.md", "exec"), {"__name__": "readme"})
    held, steady, unit, ticks, ended = out.getvalue().split(maxsplit=4)
    assert (held, unit, ticks, ended.strip()) == ("True", "m", "501", "all ticks")
    assert abs(float(steady)) < 0.01  # the appendix controllers settle a few mm off centre (docs/design.md)
