"""``export_fmu``: the rig, with a set of parameters, as an FMI 3.0 or 2.0 co-simulation unit (``BallBeam.fmu``).

The unit is ``ballbeam_fmu.py`` packed by pythonfmu3 (FMI 3.0; ``ballbeam_fmu2.py`` by pythonfmu for FMI 2.0)
with ``resources/rig.json``: every parameter's value (the
curves included), each one's unit and source, where the values come from, the exporting version and, for a
calibration, each fitted value's standard uncertainty. Written atomically; an existing file is kept unless
``overwrite``.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

from twin.parameters import Parameters

__all__ = ["MODEL", "SCRIPT", "SCRIPTS", "check_rig", "export_fmu", "rig_description"]

SCRIPT = Path(__file__).with_name("ballbeam_fmu.py")
SCRIPTS = {3: SCRIPT, 2: Path(__file__).with_name("ballbeam_fmu2.py")}
MODEL = "BallBeam"  # the unit's model identifier: the slave's class


def check_rig(params: Parameters, source: str) -> None:
    """Refuse, before a unit is written, parameters its rig cannot be built from: the unit builds the very
    ``TwinRig`` a run does (``RigUnit.start``), so this is the check ``ballbeam run`` makes (a period, latency or
    free-run time that is no whole number of physics steps, …), not a copy of it."""
    from twin.parameters import ParameterError
    from twin.rigs.sim import TwinRig

    try:
        TwinRig(params)
    except ValueError as exc:
        raise ParameterError(f"the parameters of {source} make no rig a run accepts: {exc}") from None


def rig_description(
    params: Parameters, *, version: str, source: str, uncertainty: dict[str, float] | None = None
) -> dict[str, Any]:
    """What ``resources/rig.json`` holds (see the module's doc)."""
    declared = {
        f"{group}.{f.name}": {"unit": str(f.metadata["unit"]), "source": str(f.metadata["source"])}
        for group in params.held_groups()
        for f in dataclasses.fields(params.group(group))
    }
    for name, sd in (uncertainty or {}).items():
        if name in declared:
            declared[name]["source"] = (
                f"calibrated (standard uncertainty {sd:.6g}); " + declared[name]["source"]
            )
    return {"version": version, "source": source, "values": params.to_dict(), "declared": declared}


def export_fmu(
    out: Path, description: dict[str, Any], *, overwrite: bool = False, fmi_version: int = 3
) -> Path:
    """Build the unit into ``out`` (atomically), FMI ``fmi_version`` 3 or 2."""
    from twin.outputs import write_atomic

    if fmi_version == 3:
        from pythonfmu3 import FmuBuilder
    else:
        from pythonfmu import FmuBuilder

    with tempfile.TemporaryDirectory(prefix="ballbeam_fmu_") as tmp:
        rig = Path(tmp) / "rig.json"
        rig.write_text(json.dumps(description, indent=1) + "\n")
        # what the unit's Python needs (``pythonfmu3 deploy -f BallBeam.fmu`` installs it)
        requirements = Path(tmp) / "requirements.txt"
        requirements.write_text(f"ballbeam-twin=={description['version']}\n")
        script = Path(tmp) / "script" / SCRIPTS[fmi_version].name  # the module's name: one per version
        script.parent.mkdir()
        shutil.copy2(SCRIPTS[fmi_version], script)
        built = FmuBuilder.build_FMU(script, dest=Path(tmp) / "out", project_files={rig, requirements})
        write_atomic(out, built.read_bytes(), overwrite=overwrite)
    return out
