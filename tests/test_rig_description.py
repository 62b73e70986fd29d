"""A rig description (twin.parts.description): the TOML file naming a rig's parts and their values, the
``--rig-file`` option every command has, ``params --rig-file``, and the refusals of a hostile description."""

from __future__ import annotations

import argparse
import dataclasses
import os
from pathlib import Path

import pytest

from twin.app.cli import build_parser, main
from twin.model import build_model
from twin.parameters import (
    GROUPS,
    ParameterError,
    Parameters,
    PartNames,
    all_groups,
    check_group,
    param,
    register_group,
)
from twin.parts import ROLES, THESIS, rig_parts
from twin.parts.description import PRESETS, describe_rig, load_rig, preset, rig_from_text, rig_of

# The commands a rig description applies to (the environment has its own test below).
COMMANDS = (
    "run",
    "view",
    "sweep",
    "montecarlo",
    "validate",
    "falsify",
    "certify",
    "calibrate",
    "compare",
    "shadow",
    "serve",
    "export-fmu",
    "params",
)


def _write(tmp_path: Path, text: str, name: str = "rig.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.quick
def test_the_thesis_preset_is_the_default_rig_and_its_model() -> None:
    assert "thesis" in PRESETS
    assert preset("thesis") == Parameters()
    described = load_rig(Path(__file__).parents[1] / "twin" / "parts" / "presets" / "thesis.toml")
    assert described == Parameters()
    assert rig_parts(described) == THESIS
    # the same compiled model, element for element and number for number
    a, b = build_model(described), build_model(Parameters())
    for name in ("body_mass", "body_inertia", "geom_size", "geom_pos", "actuator_gear", "jnt_range"):
        assert (getattr(a, name) == getattr(b, name)).all(), name


@pytest.mark.quick
def test_a_description_sets_a_parts_fields_by_name_and_by_group(tmp_path: Path) -> None:
    rig = load_rig(
        _write(
            tmp_path,
            'name = "heavier ball"\n[ball]\nmass_kg = 0.03\n[actuator.amplifier]\nrail_v = 10.0\n'
            "[actuator]\nresistance_ohm = 8.0\n[physics]\ngravity_m_s2 = 9.80665\n",
        )
    )
    assert rig.changed() == {
        "ball.mass_kg": 0.03,
        "amplifier.rail_v": 10.0,
        "motor.resistance_ohm": 8.0,
        "physics.gravity_m_s2": 9.80665,
    }


@pytest.mark.quick
@pytest.mark.parametrize(
    ("text", "named"),
    [
        ('[track]\npart = "no_such_track"\n', "[track] parts.track = 'no_such_track'"),
        ("[track]\npart = 3\n", "[track] part = '3' is not a part's name"),
        ('[track]\npart = "../../etc"\n', "[track] parts.track = '../../etc': no track of that name"),
        ("[actuator]\nrail_v = -1.0\n", "[actuator] part 'escap_dc_motor': amplifier.rail_v = -1.0 V"),
        ("[actuator]\nvolts = 1.0\n", "[actuator] part 'escap_dc_motor': no field 'volts'"),
        ("[actuator.amplifier]\nresistance_ohm = 1.0\n", "no field amplifier.resistance_ohm"),
        ('[ball]\nmass_kg = "heavy"\n', "ball.mass_kg = 'heavy' is not a number"),
        ("[ball]\nmass_kg = 18.8\n", "ball.mass_kg = 18.8 kg is impossible"),
        (
            "[motor]\nresistance_ohm = 1.0\n",
            "[motor] belongs to a part: set it in its role's table ([actuator])",
        ),
        ("[servoo]\nx = 1\n", "[servoo] is neither a role"),
        ("mass_kg = 1\n", "mass_kg = 1 is not a table"),
        ('preset = "nope"\n', "preset = 'nope': no such preset"),
        ("preset = 3\n", "preset = 3 is not a string"),
        ("[ball\nmass_kg = 1\n", "not a valid TOML file"),
        ("[ball]\nmass_kg = 1\nmass_kg = 2\n", "not a valid TOML file"),
        ("[a.b.c.d.e]\nx = 1\n", "nested deeper than a rig description"),
        ("[ball]\nradius_m = 0.006\n[track]\ncontact_spacing_m = 0.013785\n", "falls between"),
    ],
)
def test_a_hostile_description_is_refused_naming_the_file_part_and_field(
    tmp_path: Path, text: str, named: str
) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ParameterError) as caught:
        load_rig(path)
    message = str(caught.value)
    assert named in message, message
    if "preset" not in text or "nope" not in text:
        assert str(path) in message or "falls between" in message, message


@pytest.mark.quick
def test_files_that_are_no_description_are_refused_before_parsing(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match="larger than"):
        load_rig(_write(tmp_path, "# " + "x" * (1 << 20) + "\n"))
    with pytest.raises(ParameterError, match="not a UTF-8"):
        (tmp_path / "bin.toml").write_bytes(b"\xff\xfe\x00[ball]")
        load_rig(tmp_path / "bin.toml")
    with pytest.raises(ParameterError, match="absent.toml"):
        load_rig(tmp_path / "absent.toml")
    with pytest.raises(ParameterError, match="rig"):
        load_rig(tmp_path)  # a folder
    if os.path.exists("/dev/zero"):
        with pytest.raises(ParameterError, match="/dev/zero"):
            load_rig("/dev/zero")
    # a value that names neither a file nor a preset
    with pytest.raises(ParameterError, match="neither a rig description"):
        rig_of("my_rig")


@pytest.mark.quick
def test_a_preset_names_no_preset_of_its_own() -> None:
    with pytest.raises(ParameterError, match="names no preset of its own"):
        rig_from_text('preset = "thesis"\n', origin="preset 'x'", allow_preset=False)


@pytest.mark.quick
@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_takes_a_rig_file(command: str) -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    options = {opt for action in sub.choices[command]._actions for opt in action.option_strings}
    assert "--rig-file" in options, command


@pytest.mark.quick
def test_a_commands_rig_is_the_description_with_params_and_set_on_top(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = _write(tmp_path, "[ball]\nmass_kg = 0.03\nradius_m = 0.009\n")
    extra = _write(tmp_path, "[ball]\nmass_kg = 0.04\n", "params.toml")
    assert (
        main(
            [
                "params",
                "--rig-file",
                str(rig),
                "--params",
                str(extra),
                "--set",
                "start.free_run_s=0",
                "--json",
            ]
        )
        == 0
    )
    import json

    values = json.loads(capsys.readouterr().out)
    assert values["ball"] == {"mass_kg": 0.04, "radius_m": 0.009}  # --params over the description
    assert values["start"]["free_run_s"] == 0.0  # --set over both
    assert values["parts"] == dataclasses.asdict(PartNames())


@pytest.mark.quick
def test_params_lists_a_rigs_parameters_part_by_part_with_bounds(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["params", "--rig-file", "thesis"]) == 0
    out = capsys.readouterr().out
    for role in ROLES:
        assert f"[{role}] part = {getattr(PartNames(), role)!r}" in out
    assert "ball.mass_kg" in out and "(> 0.0 <= 1.0)" in out and "Table 3.1 (m)" in out
    rows = describe_rig(Parameters())
    assert {row["name"].split(".")[0] for row in rows} | {"physics", "software", "start", "mcu_io"} == set(
        GROUPS
    )


@pytest.mark.quick
def test_a_bad_rig_file_on_a_command_exits_2_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(tmp_path, '[ball_sensor]\npart = "laser"\n')
    code = main(
        ["run", "--controller", "appendix-sf", "--x0", "0.1", "--theta0", "0", "--rig-file", str(path)]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert str(path) in err and "parts.ball_sensor = 'laser'" in err and "Traceback" not in err


@pytest.mark.quick
def test_the_environment_takes_a_rig() -> None:
    from twin.app.envs import make_config

    assert make_config(rig="thesis").params == Parameters()
    with pytest.raises(ParameterError, match="neither a rig description"):
        make_config(rig="nope")
    with pytest.raises(ValueError, match="not both"):
        make_config(rig="thesis", params=Parameters())


@dataclasses.dataclass(frozen=True)
class _Gadget:
    """A part's group written in the test from the contract alone."""

    reach_m: float = param(0.1, "m", "test", gt=0.0, le=1.0, why="a bench-top gadget")

    def __post_init__(self) -> None:
        check_group(self, "gadget_test")


@pytest.mark.quick
def test_a_parts_group_is_registered_held_saved_and_read_back(tmp_path: Path) -> None:
    import twin.parameters

    register_group("gadget_test", _Gadget)
    try:
        _check_the_registered_group(tmp_path)
    finally:  # the table is the process's: a group made up here must not reach another test (the manual's pages)
        del twin.parameters._PART_GROUPS["gadget_test"]
    assert "gadget_test" not in all_groups()


def _check_the_registered_group(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match="in the table already"):
        register_group("gadget_test", _Gadget)
    with pytest.raises(ParameterError, match="in the table already"):
        register_group("ball", _Gadget)
    p = Parameters()
    assert p.of(_Gadget) == _Gadget() and p.part_groups == ()  # defaults are not held
    q = p.with_overrides({"gadget_test.reach_m": 0.2})
    assert q.of(_Gadget).reach_m == 0.2 and q.changed() == {"gadget_test.reach_m": 0.2}
    assert q.with_overrides({"gadget_test.reach_m": 0.1}) == p  # back at its defaults: the same rig
    with pytest.raises(ParameterError, match=r"gadget_test.reach_m = 2.0 m is impossible"):
        p.with_overrides({"gadget_test.reach_m": 2.0})
    hash(q)  # a cache key (the compiled model's)
    q.save(tmp_path / "q.toml")
    assert Parameters.from_file(tmp_path / "q.toml") == q


@pytest.mark.quick
def test_every_description_in_the_manual_loads_or_names_a_part_still_being_built() -> None:
    import re

    page = (Path(__file__).parents[1] / "docs" / "rigs.md").read_text()
    blocks = re.findall(r"```toml\n(.*?)```", page, flags=re.S)
    assert blocks
    loaded = 0
    for text in blocks:
        try:
            rig_from_text(text, origin="docs/rigs.md")
            loaded += 1
        except ParameterError as exc:  # only a part the page marks as being built may be missing
            (name,) = re.findall(r"parts\.\w+ = '([\w-]+)': no \w+ of that name", str(exc))
            assert re.search(rf"{name}.*being built|being built.*{name}", page), str(exc)
    assert loaded >= 1
