"""Controller FMUs the FMI tests build: examples/fmu's unit with its Makefile, and small hostile ones written here
(the example's modelDescription.xml and its unsupported-function stubs, a doStep of the test's own)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FMU_DIR = ROOT / "examples" / "fmu"

_TEMPLATE = """#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include "fmi3Functions.h"
typedef struct { double ball_v, angle_v, dac_v; long steps; } unit;
const char *fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance i, fmi3Boolean on, size_t n, const fmi3String c[]) { return fmi3OK; }
fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean visible,
    fmi3Boolean logging, fmi3Boolean events, fmi3Boolean early, const fmi3ValueReference r[], size_t nr,
    fmi3InstanceEnvironment env, fmi3LogMessageCallback log, fmi3IntermediateUpdateCallback update) {
    unit *u = calloc(1, sizeof *u); u->dac_v = 2.5; return u; }
void fmi3FreeInstance(fmi3Instance i) { free(i); }
fmi3Status fmi3EnterInitializationMode(fmi3Instance i, fmi3Boolean td, fmi3Float64 t, fmi3Float64 s,
    fmi3Boolean sd, fmi3Float64 st) { return fmi3OK; }
fmi3Status fmi3ExitInitializationMode(fmi3Instance i) { return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance i) { return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance i) { return fmi3OK; }
fmi3Status fmi3GetFloat64(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv) {
    unit *u = i; for (size_t k = 0; k < n; k++) v[k] = vr[k] == 1 ? u->ball_v : vr[k] == 2 ? u->angle_v : u->dac_v;
    return fmi3OK; }
fmi3Status fmi3SetFloat64(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[],
    size_t nv) { unit *u = i; for (size_t k = 0; k < n; k++) { if (vr[k] == 1) u->ball_v = v[k];
    if (vr[k] == 2) u->angle_v = v[k]; } return fmi3OK; }
fmi3Status fmi3DoStep(fmi3Instance i, fmi3Float64 t, fmi3Float64 h, fmi3Boolean nsp, fmi3Boolean *event,
    fmi3Boolean *stop, fmi3Boolean *early, fmi3Float64 *last) {
    unit *u = i; *event = *stop = *early = fmi3False; *last = t + h; u->steps++;
    BODY
    return fmi3OK; }
"""


def _headers() -> Path:
    import fmpy

    return Path(fmpy.__file__).parent / "c-code"


def example_unit(tmp: Path) -> Path:
    """examples/fmu's BbStateFeedback.fmu built with its Makefile into a copy of the folders it reads."""
    if shutil.which("cc") is None or shutil.which("make") is None:
        pytest.skip("no C compiler or make to build examples/fmu")
    for name in ("fmu", "c", "avr"):
        shutil.copytree(
            ROOT / "examples" / name, tmp / "examples" / name, ignore=shutil.ignore_patterns("*.elf")
        )
    subprocess.run(
        ["make", "-s", "-C", str(tmp / "examples" / "fmu"), f"PYTHON={sys.executable}"], check=True
    )
    return tmp / "examples" / "fmu" / "BbStateFeedback.fmu"


def hostile_unit(tmp: Path, name: str, body: str, description: str | None = None) -> Path:
    """A controller unit whose doStep runs ``body`` (C; ``u->steps`` counts the steps, ``u->dac_v`` is the output)
    with the example's model description (or ``description``)."""
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler")
    source = tmp / f"{name}.c"
    source.write_text(_TEMPLATE.replace("BODY", body))
    lib = tmp / f"{name}_lib" / "binaries" / "x86_64-linux" / "BbStateFeedback.so"
    lib.parent.mkdir(parents=True)
    subprocess.run(
        [cc, "-std=c99", "-shared", "-fPIC", "-w", f"-I{_headers()}", "-o", str(lib), str(source),
         str(FMU_DIR / "fmi3_unsupported.c"), "-lm"],
        check=True,
    )  # fmt: skip
    out = tmp / f"{name}.fmu"
    with zipfile.ZipFile(out, "w") as z:
        z.writestr("modelDescription.xml", description or (FMU_DIR / "modelDescription.xml").read_text())
        z.write(lib, "binaries/x86_64-linux/BbStateFeedback.so")
    return out
