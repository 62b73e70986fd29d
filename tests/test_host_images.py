"""The images a controller host loads, a controller FMU (``fmu:``) or a firmware image (``avr:``): each is checked
before anything in it is read whole, extracted or loaded, and what a run extracts is removed on every way out.

- An FMU whose ``modelIdentifier`` names a path (``../``, absolute) is refused naming the field and its value,
  before any library loads (a library outside the unit would run its constructor).
- An FMU is extracted once per command into one temporary folder, removed at exit, after an error and after
  Ctrl-C; a folder left by a killed process goes with the next extraction; an oversized entry is refused naming
  it and its size before anything is extracted; a sweep holds one unit process at a time per worker.
- A firmware image larger than its limit is refused before it is read; the MCU ``avr:MCU:FILE`` names must be the
  one the image was built for; a directory or a device given as an image says what it is.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest
from cli_checks import refused

from twin.app.cli import main

ROOT = Path(__file__).resolve().parents[1]
PASSIVE = "u->dac_v = 2.5;"  # a unit that holds the zero command
# A library whose constructor leaves a marker: loading it at all is what must not happen.
_MARKER_LIB = """#include <stdio.h>
__attribute__((constructor)) static void loaded(void) { FILE *f = fopen("MARKER", "w"); if (f) fclose(f); }
"""


def _unit(tmp: Path, name: str = "passive", description: str | None = None) -> Path:
    from fmu_units import hostile_unit

    return hostile_unit(tmp, name, PASSIVE, description)


def _description(identifier: str) -> str:
    from fmu_units import FMU_DIR

    text = (FMU_DIR / "modelDescription.xml").read_text()
    return text.replace('modelIdentifier="BbStateFeedback"', f'modelIdentifier="{identifier}"')


def _marker_library(tmp: Path) -> tuple[Path, Path]:
    """``tmp/outside.so``, whose constructor creates ``tmp/loaded`` (the marker returned)."""
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler")
    marker = tmp / "loaded"
    source = tmp / "outside.c"
    source.write_text(_MARKER_LIB.replace("MARKER", str(marker)))
    lib = tmp / "outside.so"
    subprocess.run([cc, "-shared", "-fPIC", "-o", str(lib), str(source)], check=True)
    return lib, marker


@pytest.fixture
def tmpdir_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A temporary folder of the test's own, for this process (tempfile) and its children (TMPDIR)."""
    import tempfile

    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setenv("TMPDIR", str(folder))
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


# --- item 2: a model identifier that names a path ------------------------------------------------------------
@pytest.mark.quick
@pytest.mark.parametrize("how", ["absolute", "dotdot"])
def test_a_model_identifier_naming_a_path_is_refused_before_any_library_loads(
    tmp_path: Path, tmpdir_env: Path, capsys: pytest.CaptureFixture[str], how: str
) -> None:
    lib, marker = _marker_library(tmp_path)
    stem = str(lib.with_suffix(""))
    identifier = stem if how == "absolute" else "../../../../../../../../../../.." + stem
    unit = _unit(tmp_path, f"escape_{how}", _description(identifier))
    line = refused(
        capsys,
        ["run", "--controller", f"fmu:{unit}", "--x0", "0.1", "--theta0", "0", "--duration", "0.1"],
        str(unit),
        "modelIdentifier",
        repr(identifier),
        "nothing loaded",
    )
    assert not marker.exists(), f"the library outside the unit was loaded: {line}"
    assert list(tmpdir_env.iterdir()) == []  # refused before anything was extracted


@pytest.mark.quick
def test_the_host_refuses_a_model_identifier_naming_a_path_on_its_own(tmp_path: Path) -> None:
    """The unit's process checks the description again before it loads a library."""
    lib, marker = _marker_library(tmp_path)
    folder = tmp_path / "unit"
    with zipfile.ZipFile(_unit(tmp_path, "plain")) as z:
        z.extractall(folder)
    (folder / "modelDescription.xml").write_text(_description(str(lib.with_suffix(""))))
    done = subprocess.run(
        [sys.executable, "-m", "twin.fmi.host", str(folder)], input=b"", capture_output=True, timeout=60
    )
    assert done.stdout.startswith(b"NO ") and b"modelIdentifier" in done.stdout, done.stdout
    assert not marker.exists()


# --- item 4: extracted once, removed on every exit, bounded -----------------------------------------------------
def test_a_sweep_extracts_its_unit_once_and_holds_one_unit_process_at_a_time(
    tmp_path: Path, tmpdir_env: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import twin.childproc
    from twin.fmi import archive

    unit = _unit(tmp_path)
    extracted: list[Path] = []
    real_extract = archive._extract

    def counting(path: Path, z: zipfile.ZipFile) -> Path:
        extracted.append(real_extract(path, z))
        return extracted[-1]

    hosts: list[subprocess.Popen[bytes]] = []
    most = [0]
    real_popen = subprocess.Popen

    def popen(argv: list[str], **kwargs: object) -> subprocess.Popen[bytes]:
        proc: subprocess.Popen[bytes] = real_popen(argv, **kwargs)  # type: ignore[call-overload]
        if "twin.fmi.host" in argv:
            hosts.append(proc)
            most[0] = max(most[0], sum(p.poll() is None for p in hosts))
        return proc

    monkeypatch.setattr(archive, "_extract", counting)
    monkeypatch.setattr(twin.childproc.subprocess, "Popen", popen)
    argv = [
        "sweep",
        "--controller",
        f"fmu:{unit}",
        "--engine",
        "mujoco",
        "--x0",
        "-0.1:0.1:4",
        "--theta0",
        "0:0:1",
    ]
    rc = main([*argv, "--duration", "0.3", "--workers", "1", "--json"])
    assert rc == 0, capsys.readouterr().err
    assert len(extracted) == 1, extracted
    assert len(hosts) >= 4  # the check and each run's own process
    assert most[0] == 1, f"{most[0]} unit processes at once"
    for proc in hosts:
        proc.wait(timeout=10)  # all ended


def _run(unit: Path, tmp: Path, *extra: str, duration: str = "0.3") -> subprocess.CompletedProcess[str]:
    argv = [
        "run",
        "--controller",
        f"fmu:{unit}",
        "--x0",
        "0.1",
        "--theta0",
        "0",
        "--duration",
        duration,
        *extra,
    ]
    env = {**os.environ, "TMPDIR": str(tmp)}
    return subprocess.run(
        [sys.executable, "-m", "twin.app.cli", *argv], capture_output=True, text=True, env=env, timeout=300
    )


def test_a_runs_extracted_unit_is_removed_at_exit_and_after_an_error(
    tmp_path: Path, tmpdir_env: Path
) -> None:
    from fmu_units import FMU_DIR

    done = _run(_unit(tmp_path), tmpdir_env)
    assert done.returncode in (0, 1) and "duration_s" in done.stdout, (
        done.stderr
    )  # 1: the passive unit drops it
    assert list(tmpdir_env.iterdir()) == []
    # a unit that loads but lacks the convention's output: refused (exit 2), nothing left
    text = (FMU_DIR / "modelDescription.xml").read_text().replace('name="dac_v"', 'name="dac_out"')
    done = _run(_unit(tmp_path, "renamed", text), tmpdir_env)
    assert done.returncode == 2 and "dac_v" in done.stderr, done.stderr
    assert list(tmpdir_env.iterdir()) == []


def test_ctrl_c_removes_the_extracted_unit(tmp_path: Path, tmpdir_env: Path) -> None:
    unit = _unit(tmp_path)
    argv = ["run", "--controller", f"fmu:{unit}", "--x0", "0.1", "--theta0", "0", "--duration", "600"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin.app.cli", *argv],
        env={**os.environ, "TMPDIR": str(tmpdir_env)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not any(tmpdir_env.glob("ballbeam-fmu-*")) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert any(tmpdir_env.glob("ballbeam-fmu-*")), "the unit was never extracted"
        time.sleep(1.0)  # into the run
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode != 0
    assert list(tmpdir_env.iterdir()) == []


@pytest.mark.quick
def test_a_folder_left_by_a_killed_process_goes_with_the_next_extraction(
    tmp_path: Path, tmpdir_env: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from twin.fmi import archive

    ended = subprocess.Popen(["true"])
    ended.wait()
    left = tmpdir_env / f"{archive.PREFIX}{ended.pid}-left"
    (left / "binaries").mkdir(parents=True)
    monkeypatch.setattr(archive, "_unpacked", {})
    folder = archive.unpack(_unit(tmp_path))
    try:
        assert not left.exists() and folder.is_dir()
    finally:
        shutil.rmtree(folder)


@pytest.mark.quick
def test_an_oversized_entry_is_refused_naming_it_before_anything_is_extracted(
    tmp_path: Path, tmpdir_env: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from twin.fmi import archive

    unit = _unit(tmp_path)
    size = zipfile.ZipFile(unit).getinfo("binaries/x86_64-linux/BbStateFeedback.so").file_size
    monkeypatch.setattr(archive, "MAX_ENTRY_BYTES", size - 1)
    refused(
        capsys,
        ["run", "--controller", f"fmu:{unit}", "--x0", "0.1", "--theta0", "0", "--duration", "0.1"],
        str(unit),
        "'binaries/x86_64-linux/BbStateFeedback.so'",
        f"{size} bytes",
        "not extracted",
    )
    assert list(tmpdir_env.iterdir()) == []


@pytest.mark.slow
def test_a_2_gib_entry_is_refused_with_its_size(tmp_path: Path, tmpdir_env: Path) -> None:
    """A real 2 GiB entry (zeros, deflated to about 2 MB): refused by its declared size, nothing extracted."""
    unit = _unit(tmp_path)
    big = 2 << 30
    with zipfile.ZipFile(unit, "a", compression=zipfile.ZIP_DEFLATED) as z:
        with z.open("resources/zeros.bin", "w", force_zip64=True) as out:
            block = bytes(16 << 20)
            for _ in range(big // len(block)):
                out.write(block)
    done = _run(unit, tmpdir_env)
    assert done.returncode == 2, done.stderr
    assert "'resources/zeros.bin'" in done.stderr and f"{big} bytes (2048.0 MiB)" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
    assert list(tmpdir_env.iterdir()) == []


# --- items 8 and 12: the images themselves -----------------------------------------------------------------------
@pytest.mark.quick
def test_a_1_gib_firmware_image_is_refused_before_it_is_read(tmp_path: Path) -> None:
    from twin.avr.core import MAX_IMAGE_BYTES

    image = tmp_path / "big.elf"
    with image.open("wb") as fh:  # sparse: an ELF header, then a 1 GiB hole
        fh.write(b"\x7fELF\x01\x01\x01" + bytes(11) + b"\x53\x00")
        fh.truncate(1 << 30)
    # A fresh parent process whose only child is the CLI: this worker's own
    # RUSAGE_CHILDREN also holds every earlier test's children.
    measure = (
        "import resource, subprocess, sys; r = subprocess.run(sys.argv[1:]); "
        "print('peak_kib', resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, file=sys.stderr); "
        "sys.exit(r.returncode)"
    )
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            measure,
            sys.executable,
            "-m",
            "twin.app.cli",
            "run",
            "--controller",
            f"avr:{image}",
            "--x0",
            "0",
            "--theta0",
            "0",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    peak_mib = int(done.stderr.rsplit("peak_kib ", 1)[1].split()[0]) / 1024
    assert done.returncode == 2, done.stderr
    assert str(image) in done.stderr and f"limit of {MAX_IMAGE_BYTES} bytes" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
    assert peak_mib < 256, f"{peak_mib:.0f} MiB at peak"


@pytest.mark.quick
def test_an_mcu_other_than_the_images_device_is_refused_naming_both(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from avr_images import board_image

    image = board_image("mcu", "", tmp_path)  # built with -mmcu=atmega328p
    refused(
        capsys,
        [
            "run",
            "--controller",
            f"avr:atmega2560:{image}",
            "--x0",
            "0.1",
            "--theta0",
            "0",
            "--duration",
            "0.1",
        ],
        str(image),
        "atmega328p",
        "atmega2560",
    )
    from twin.avr.firmware import AvrFirmware
    from twin.parameters import Parameters

    assert AvrFirmware(image, Parameters(), mcu="atmega328p").mcu == "atmega328p"  # the same MCU: taken


@pytest.mark.quick
@pytest.mark.parametrize("kind", ["avr", "fmu"])
def test_a_directory_or_a_device_given_as_an_image_is_named_for_what_it_is(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str
) -> None:
    for path, what in ((tmp_path, "a directory"), (Path("/dev/zero"), "a device, pipe or socket")):
        line = refused(
            capsys,
            ["run", "--controller", f"{kind}:{path}", "--x0", "0.1", "--theta0", "0", "--duration", "0.1"],
            str(path),
            what,
        )
        assert "no such" not in line


@pytest.mark.quick
def test_the_shared_image_check_reads_no_more_than_its_limit(tmp_path: Path) -> None:
    from twin.image import check_image, read_image

    image = tmp_path / "image.bin"
    image.write_bytes(bytes(100))
    assert check_image(image, "firmware image", 100, ValueError) == 100
    assert read_image(image, "firmware image", 100, ValueError) == bytes(100)
    with pytest.raises(ValueError, match=r"image.bin: 100 bytes, larger than the FMU limit of 99 bytes"):
        read_image(image, "FMU", 99, ValueError)
    with pytest.raises(ValueError, match=r"no such FMU"):
        check_image(tmp_path / "missing.fmu", "FMU", 99, ValueError)
