"""Controller hosts, registered (twin.app.hosts): a host written from the contract alone runs ``run``, ``sweep``
and ``validate`` after one row; no ``avr:``/``fmu:`` test is left outside the table; the boards' pins are the
boards' (a Mega 2560 selects its DAC on PB0, its SPI's SS, not on PB2, its data out)."""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

import twin.app.hosts as hosts
from twin.app.cli import main
from twin.app.hosts import AVR, FMU, MODULE, NAME, controller_host, host_of, register
from twin.app.replay import controller_identity
from twin.interface import Controller
from twin.parameters import ParameterError, Parameters

ROOT = Path(__file__).resolve().parents[1]

# A controller file the test host loads: the motor held off (the ball rolls off, so the runs end early).
LAW = """
from twin.interface import Controller, DaqSample


class Law(Controller):
    name = "motor off"

    def start(self, sample: DaqSample) -> None:
        pass

    def update(self, sample: DaqSample) -> float:
        return 2.5
"""

LOADED: list[str] = []


def _load(spec: str, params: Parameters) -> Controller:
    """``pyfile:FILE.py``: the class ``Law`` of a Python file, executed from its path (no import)."""
    path = Path(spec.partition(":")[2])
    try:
        source = path.read_text()
    except OSError as exc:
        raise ParameterError(f"--controller {spec}: {path}: {exc.strerror}") from None
    namespace: dict[str, object] = {}
    exec(compile(source, str(path), "exec"), namespace)
    law = namespace.get("Law")
    if not isinstance(law, type) or not issubclass(law, Controller):
        raise ParameterError(f"--controller {spec}: {path} defines no Controller class Law")
    LOADED.append(spec)
    return law()


PYFILE = controller_host(
    "pyfile",
    "pyfile:FILE.py",
    _load,
    lambda spec: f"your Python file {spec}",
    lambda spec: Path(spec.partition(":")[2]),
    help="; or pyfile:FILE.py, a file's class Law",
)


@pytest.fixture
def pyfile(tmp_path: Path) -> Iterator[str]:
    """The row registered, and a controller file for it: the value naming it."""
    register(PYFILE)
    LOADED.clear()
    law = tmp_path / "law.py"
    law.write_text(LAW)
    try:
        yield f"pyfile:{law}"
    finally:
        del hosts.HOSTS["pyfile"]


@pytest.mark.quick
def test_the_parser_reads_every_row() -> None:
    assert host_of("avr:fw.elf") is AVR and host_of("avr:atmega2560:fw.elf") is AVR
    assert host_of("fmu:ctl.fmu") is FMU
    assert host_of("mypkg.mod:MyController") is MODULE and host_of("appendix-sf") is NAME
    assert host_of("pyfile:law.py") is MODULE  # not registered: a module named pyfile
    assert [row.kind for row in (AVR, FMU, MODULE, NAME)] == [
        "firmware",
        "controller",
        "controller",
        "controller",
    ]
    assert AVR.image("avr:atmega2560:dir/fw.elf") == Path("dir/fw.elf")
    assert FMU.image("fmu:a/b.fmu") == Path("a/b.fmu")
    with pytest.raises(ValueError, match="'avr'"):
        register(replace(PYFILE, scheme="avr"))  # a scheme is one row's


def test_a_host_from_the_contract_alone_runs_run_sweep_and_validate(
    pyfile: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert host_of(pyfile) is PYFILE
    law = Path(pyfile.partition(":")[2])
    # what a replay hashes is the row's file
    assert controller_identity(pyfile) == hashlib.sha256(law.read_bytes()).hexdigest()

    code = main(["run", "--controller", pyfile, "--x0", "0.1", "--theta0", "0", "--duration", "1", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1 and out["controller"] == pyfile and out["ball_lost"] is True
    assert LOADED == [pyfile]

    sweep_out = tmp_path / "sweep"
    code = main(
        ["sweep", "--controller", pyfile, "--x0=-0.1:0.1:2", "--theta0=0:0:1", "--duration", "1",
         "--out", str(sweep_out), "--json"]
    )  # fmt: skip
    data = json.loads(capsys.readouterr().out)
    assert code == 0 and data["complete"] and data["settings"]["controller"] == pyfile
    assert [p["held"] for p in data["points"]] == [False, False] and sweep_out.is_dir()
    assert len(LOADED) >= 3  # checked once, then built for each of the 2 runs

    criteria = tmp_path / "criteria.toml"
    criteria.write_text(
        "nominal_seeds = 1\nduration_s = 1.0\nregion_x0 = [-0.2, 0.2, 2]\nregion_theta0 = [-0.3, 0.3, 2]\n"
        "region_duration_s = 1.0\nzeroing_counts = 0\nlatencies_s = [0.0]\nfree_runs_s = [0.04]\n"
    )
    report = tmp_path / "report"
    code = main(
        ["validate", "--controller", pyfile, "--criteria", str(criteria), "--out", str(report), "--json"]
    )
    data = json.loads(capsys.readouterr().out)
    assert code == 1 and data["passed"] is False  # the motor off holds nothing
    assert (report / "report.md").read_text().startswith(f"# Validation of `{pyfile}`")

    # its help is the row's, and its refusals are its loader's (one line, exit code 2)
    assert "pyfile:FILE.py" in hosts.HOSTS["pyfile"].help
    missing = tmp_path / "none.py"
    code = main(["run", "--controller", f"pyfile:{missing}", "--x0", "0", "--theta0", "0", "--duration", "1"])
    err = capsys.readouterr().err
    assert code == 2 and f"--controller pyfile:{missing}" in err and "Traceback" not in err


# A prefix test: a literal "avr:"/"fmu:", or startswith/removeprefix/== on a host's scheme.
_PREFIX_TEST = re.compile(
    r"""["'](avr|fmu):["']|(startswith|removeprefix)\(\s*\(?\s*["'](avr|fmu)|[=!]=\s*["'](avr|fmu):?["']"""
)


@pytest.mark.quick
def test_no_host_is_recognised_outside_the_registry() -> None:
    found = [
        f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
        for folder in ("twin", "scripts", "controllers", "calib")
        for path in sorted((ROOT / folder).rglob("*.py"))
        if path != ROOT / "twin" / "app" / "hosts.py"
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if _PREFIX_TEST.search(line)
    ]
    assert found == []
    # the scan sees one when there is one
    assert _PREFIX_TEST.search('if spec.startswith("avr:"):') and _PREFIX_TEST.search('if scheme == "fmu":')


@pytest.mark.quick
def test_each_board_names_its_pins() -> None:
    from twin.avr.boards import ATMEGA644, MEGA2560, UNO, board_for
    from twin.firmware import Board

    assert all(isinstance(board, Board) for board in (UNO, MEGA2560, ATMEGA644))

    assert board_for("atmega328p") is UNO and str(UNO.dac_select) == "PB2"
    assert board_for("ATmega2560") is MEGA2560 and str(MEGA2560.dac_select) == "PB0"
    assert str(MEGA2560.spi_mosi) == "PB2"  # the data out: never the select
    assert board_for("atmega644p") is ATMEGA644 and str(ATMEGA644.dac_select) == "PB4"
    assert board_for("attiny85") is UNO  # an MCU no board names: the Uno's wiring, as before boards
    for board in (UNO, MEGA2560, ATMEGA644):
        assert (board.ball_channel, board.angle_channel, board.dac.name) == (0, 1, "MCP4921")


def test_a_mega_2560_image_selecting_its_dac_on_pb0_holds_the_ball(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from avr_images import example_image_for

    from twin.avr.boards import MEGA2560

    image = example_image_for(MEGA2560, "atmega2560", tmp_path)
    code = main(
        ["run", "--controller", f"avr:atmega2560:{image}", "--x0", "0.14", "--theta0", "-0.2", "--duration", "10",
         "--json"]
    )  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["held"] is True
    f = out["firmware"]
    assert f["mcu"] == "atmega2560" and f["missed_periods"] == 0 and f["updates"] >= 490
