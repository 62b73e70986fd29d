"""The process a controller FMU runs in (``python -m twin.fmi.host FOLDER``, the unit as ``twin.fmi.archive``
checked and extracted it): a crash in its shared library ends this process, never ballbeam's.
``twin.fmi.controller.FmuController`` starts it and speaks to it over its stdin and stdout, little-endian:

    at start   "OK" and a newline, or "NO " and a line saying why (not an FMU, no co-simulation, a variable of
               the convention missing, an instantiation that failed)
    request    4 doubles: the communication point, the step, ball_v, angle_v
    answer     "K" and a double: dac_v after the step; or "E", a u16 length and a message (an error status, a
               value that is not a number) — the process goes on, the caller decides

The convention: inputs ``ball_v`` and ``angle_v`` (the card's readings, V), output ``dac_v`` (the DAC command, V),
FMI 2.0 or 3.0 co-simulation. Each request sets the inputs and takes one step.
"""

from __future__ import annotations

import os
import struct
import sys
from typing import Any

INPUTS = ("ball_v", "angle_v")
OUTPUT = "dac_v"
REQUEST = struct.Struct("<4d")


def _load(path: str) -> tuple[Any, Any, list[int], int, str]:
    import fmpy

    from twin.fmi.archive import check_description

    md = fmpy.read_model_description(path)
    check_description(path, md)  # checked when extracted; again here, since a library is loaded next
    if md.coSimulation is None:
        raise ValueError("not a co-simulation unit (no <CoSimulation>)")
    variables = {v.name: v for v in md.modelVariables}
    for name, causality in ((INPUTS[0], "input"), (INPUTS[1], "input"), (OUTPUT, "output")):
        v = variables.get(name)
        if v is None:
            raise ValueError(f"no variable {name!r} (the convention: inputs ball_v, angle_v; output dac_v)")
        if v.causality != causality:
            raise ValueError(f"variable {name!r} is an {v.causality}, not an {causality}")
    unit = fmpy.instantiate_fmu(path, md, fmi_type="CoSimulation")
    version = md.fmiVersion
    if not version.startswith("3"):
        unit.setupExperiment(startTime=0.0)  # FMI 2.0's step before initialization
    unit.enterInitializationMode()
    unit.exitInitializationMode()
    refs = [variables[name].valueReference for name in INPUTS]
    return unit, md, refs, variables[OUTPUT].valueReference, version


def main() -> int:
    out = os.fdopen(os.dup(1), "wb", buffering=0)
    os.dup2(2, 1)  # what the unit prints goes to stderr, not into the answers
    try:
        unit, _, refs, dac_ref, version = _load(sys.argv[1])
    except Exception as exc:  # noqa: BLE001 - any failure to load is told to the caller
        out.write(b"NO " + " ".join(str(exc).split())[:400].encode() + b"\n")
        return 1
    set_values = unit.setFloat64 if version.startswith("3") else unit.setReal
    get_values = unit.getFloat64 if version.startswith("3") else unit.getReal
    out.write(b"OK\n")
    stdin = sys.stdin.buffer
    while True:
        raw = stdin.read(REQUEST.size)
        if len(raw) < REQUEST.size:
            return 0
        t, h, ball_v, angle_v = REQUEST.unpack(raw)
        try:
            set_values(refs, [ball_v, angle_v])
            unit.doStep(t, h)
            (dac_v,) = get_values([dac_ref])
            out.write(b"K" + struct.pack("<d", float(dac_v)))
        except Exception as exc:  # noqa: BLE001 - an error status, told to the caller
            message = " ".join(str(exc).split())[:400].encode() or type(exc).__name__.encode()
            out.write(b"E" + struct.pack("<H", len(message)) + message)


if __name__ == "__main__":
    sys.exit(main())
