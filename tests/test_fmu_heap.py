"""The exported twin FMU leaves its importer's heap whole: a Python process that simulates the FMI 3.0 and the FMI
2.0 unit twice each with FMPy exits 0, with no "corrupted double-linked list" abort at its exit; under valgrind,
no error lies in the unit's library.

The abort came from pythonfmu's library (both versions): it keeps its interpreter state in a static
``std::shared_ptr`` the C++ runtime destroys at exit, after which its unload hook assigns to it again (a use
after free, then a double free). ``twin.fmi.unit.release_state_at_exit`` has the unit release that state first,
from the importer's exit handlers.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from twin.app.cli import main

pytestmark = pytest.mark.slow

# Each unit simulated twice in one process, as an importer that runs a study does (0.2 s of the rig each).
_IMPORTER = """
import sys, fmpy
for unit in sys.argv[1:]:
    for _ in range(2):
        rows = fmpy.simulate_fmu(unit, stop_time=0.2, step_size=0.02, output_interval=0.02,
                                 start_values={"x0_m": 0.1})
        print(unit, len(rows), rows[-1]["x_m"], flush=True)
print("done", flush=True)
"""


@pytest.fixture(scope="module")
def units(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    folder = tmp_path_factory.mktemp("heap")
    out = []
    for version in ("3", "2"):
        unit = folder / f"BallBeam{version}.fmu"
        assert main(["export-fmu", "--fmi", version, "--out", str(unit)]) == 0
        out.append(str(unit))
    return out


def _importer(
    tmp: Path, prefix: list[str], units: list[str], env_extra: dict[str, str]
) -> subprocess.CompletedProcess[str]:
    script = tmp / "importer.py"
    script.write_text(_IMPORTER)
    # every allocation through malloc: the checker sees them all
    env = {**os.environ, "PYTHONMALLOC": "malloc", **env_extra}
    return subprocess.run(
        [*prefix, sys.executable, str(script), *units], capture_output=True, text=True, env=env, timeout=1800
    )


# glibc's checking allocator (glibc >= 2.34): a corrupted heap is found at the next call, not by chance.
_MALLOC_DEBUG = Path("/lib/x86_64-linux-gnu/libc_malloc_debug.so.0")


def test_simulating_the_units_twice_each_exits_cleanly(tmp_path: Path, units: list[str]) -> None:
    checking = {"LD_PRELOAD": str(_MALLOC_DEBUG), "GLIBC_TUNABLES": "glibc.malloc.check=3"}
    for _ in range(3):  # the abort depends on the heap's layout: it did not come every time
        done = _importer(tmp_path, [], units, checking if _MALLOC_DEBUG.exists() else {})
        assert done.returncode == 0, f"exit code {done.returncode}: {done.stderr[-2000:]}"
        assert done.stdout.rstrip().endswith("done") and done.stdout.count(" 11 ") == 4, done.stdout
        assert "corrupted" not in done.stderr and "double free" not in done.stderr, done.stderr[-2000:]


def test_valgrind_finds_no_error_in_the_units_library(tmp_path: Path, units: list[str]) -> None:
    """Python's own start and glibc's loader make reports of their own under valgrind (uninitialised reads
    Python tolerates by design): what counts is an error with a frame in the unit's library (the extracted
    ``binaries/``), where the use after free and the double free were."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        pytest.skip("valgrind is not installed (Debian: apt-get install valgrind)")
    checker = [valgrind, "--error-exitcode=97", "--num-callers=40", "--error-limit=no"]
    done = _importer(tmp_path, checker, units, {})
    assert done.returncode in (0, 97), f"exit code {done.returncode}: {done.stderr[-3000:]}"
    assert done.stdout.rstrip().endswith("done"), done.stdout
    records = re.split(r"==\d+== \n", done.stderr)
    in_unit = [r for r in records if "/binaries/" in r and ("Invalid" in r or "free" in r)]
    assert not in_unit, in_unit[0][:3000]
