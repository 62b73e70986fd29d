"""The example spread file the README points to: every key is a parameter, every entry says its source, and
``ballbeam montecarlo --spread`` takes it."""

import dataclasses
import json
import re
import tomllib
from pathlib import Path

import pytest

from twin.app.cli import main
from twin.app.montecarlo import load_spread
from twin.parameters import Parameters

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "docs" / "examples" / "spread.toml"
SOURCES = ("printed:", "measured:", "assumed:")


def _entries() -> list[str]:
    data = tomllib.loads(EXAMPLE.read_text(encoding="utf-8"))
    return [f"{group}.{name}" for group, table in data.items() for name in table]


def test_the_readme_points_to_the_example() -> None:
    readme = (ROOT / "docs" / "validate.md").read_text(encoding="utf-8")  # the manual's page on montecarlo
    assert "--spread docs/examples/spread.toml" in readme


@pytest.mark.parametrize("name", _entries())
def test_every_key_is_a_parameter(name: str) -> None:
    group, field = name.split(".")
    section = getattr(Parameters(), group, None)
    assert dataclasses.is_dataclass(section), f"[{group}] is not a parameter group"
    assert field in {f.name for f in dataclasses.fields(section)}, f"{name} is not a parameter"


def test_every_entry_says_where_its_spread_comes_from() -> None:
    """The comment block above each entry names its source (printed digits, a measurement or an assumption)."""
    lines = EXAMPLE.read_text(encoding="utf-8").splitlines()
    entries = [i for i, line in enumerate(lines) if re.match(r"^\w+\s*=\s*\{", line)]
    assert len(entries) == len(_entries()) >= 8
    for i in entries:
        above = []
        for line in reversed(lines[:i]):
            if not line.startswith("#"):
                break
            above.append(line)
        assert any(s in c for c in above for s in SOURCES), f"line {i + 1}: {lines[i]} has no source comment"


@pytest.mark.quick
def test_it_loads_as_a_spread_about_the_nominal_rig() -> None:
    spread = load_spread(EXAMPLE, Parameters())
    assert list(spread.names) == _entries()
    low, high = (
        dict(zip(spread.names, spread.low, strict=True)),
        dict(zip(spread.names, spread.high, strict=True)),
    )
    # The printed resistance's rounding interval holds the nominal value; the warm winding lies above it.
    assert low["motor.resistance_ohm"] < Parameters().motor.resistance_ohm < high["motor.resistance_ohm"]


def test_montecarlo_accepts_it(capsys: pytest.CaptureFixture[str]) -> None:
    """A tiny run: two perturbed rigs, one second each."""
    code = main(
        [
            "montecarlo",
            "--controller",
            "appendix-sf",
            "--n",
            "2",
            "--duration",
            "1",
            "--spread",
            str(EXAMPLE),
            "--json",
        ]
    )
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["summary"]["runs"] == 2
    assert set(result["runs"][0]["parameters"]) == set(_entries())
