"""``--controller avr:FILE.elf`` at the command line: ``run`` prints the verdict with the firmware's figures, the
same twice; a path that is no firmware image, an MCU simavr does not know, a firmware where it cannot go (a rig
over the wire, a replayed log) are refused in one line naming the value."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from avr_images import example_image
from cli_checks import refused

from twin.app.cli import main


@pytest.fixture(scope="module")
def image(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from twin.avr.core import AvrCore, AvrUnavailable

    elf = example_image(tmp_path_factory.mktemp("avr_cli"))
    try:
        AvrCore(elf).close()
    except AvrUnavailable as exc:
        pytest.skip(str(exc))
    return elf


@pytest.mark.quick
def test_run_prints_the_verdict_and_the_firmwares_figures_the_same_twice(
    image: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "run",
        "--controller",
        f"avr:{image}",
        "--x0",
        "0.14",
        "--theta0",
        "-0.2",
        "--duration",
        "6",
        "--json",
    ]
    outs = []
    for _ in range(2):
        assert main(argv) == 0
        outs.append(capsys.readouterr().out)
    assert outs[0] == outs[1]
    summary = json.loads(outs[0])
    assert summary["held"] and summary["controller"] == f"avr:{image}"
    f = summary["firmware"]
    assert f["mcu"] == "atmega328p" and f["missed_periods"] == 0
    assert 0 < f["update_cycles_max"] < f["clock_hz"] * 0.02 and f["deadline_margin_s"] > 0
    assert 0 < f["stack_high_water_bytes"] < f["stack_room_bytes"]


@pytest.mark.quick
def test_what_is_no_firmware_image_is_refused_naming_it(
    image: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    start = ["--x0", "0", "--theta0", "0"]
    refused(
        capsys,
        ["run", "--controller", "avr:/no/such.elf", *start],
        "avr:/no/such.elf",
        "no such firmware image",
    )
    text = tmp_path / "notes.elf"
    text.write_text("not an image\n")
    refused(capsys, ["run", "--controller", f"avr:{text}", *start], "not an AVR ELF image")
    truncated = tmp_path / "truncated.elf"
    truncated.write_bytes(image.read_bytes()[:200])
    refused(capsys, ["run", "--controller", f"avr:{truncated}", *start], f"avr:{truncated}", "truncated")
    refused(
        capsys,
        ["run", "--controller", f"avr:atmega9999:{image}", *start],
        "built for atmega328p",
        "not for atmega9999",
    )
    refused(capsys, ["sweep", "--controller", "avr:/no/such.elf"], "no such firmware image")
    refused(capsys, ["view", "--controller", "avr:/no/such.elf"], "no such firmware image")


@pytest.mark.quick
def test_a_firmware_drives_the_simulated_rig_only(image: Path, capsys: pytest.CaptureFixture[str]) -> None:
    refused(
        capsys,
        ["run", "--rig", "udp://127.0.0.1:9", "--controller", f"avr:{image}"],
        "drives the simulated rig through its pins",
    )
    refused(
        capsys,
        [
            "compare",
            "--controller",
            f"avr:{image}",
            "tests/data/before_engine_appendix-sf.csv",
            "--out",
            "x/",
        ],
        "a log is replayed with a hardware controller",
    )
