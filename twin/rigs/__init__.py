"""The rigs a controller runs on, each behind the hardware contract ``twin.interface.Rig``:

    sim.SimRig         the MuJoCo twin with its I/O chain, with ideal converters, or the reference model
                       (``make_rig(params, plant=PlantKind, ideal_sensors=…)``; ``TwinRig``, ``ReferenceRig``;
                       ``RigError``: a configuration it cannot run)
    remote.RemoteRig   a rig over protocol 1 (UDP or serial): the served twin, or a rig's own firmware
                       (``open_remote(url)``; ``RemoteError``: it cannot be reached or went silent)
    batch.BatchRig     N simulated rigs stepped together (``run_batch``), each its single rig bit for bit
    vector.VectorRig   N simulated rigs reset one by one and stepped together (the vector environment)

A new kind of rig is one new module here implementing ``Rig`` (docs/design.md, "One loop, many rigs"); the
one loop (``twin.engine.ClosedLoop``) runs any of them. The names load on first use, so that importing the
remote rig does not load the batch engine.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "BatchRig",
    "PlantKind",
    "ReferenceRig",
    "RemoteError",
    "RemoteRig",
    "RigError",
    "SimRig",
    "TwinRig",
    "VectorRig",
    "make_rig",
    "open_remote",
    "run_batch",
]

_HOMES = {
    "BatchRig": "batch",
    "run_batch": "batch",
    "PlantKind": "sim",
    "ReferenceRig": "sim",
    "RigError": "sim",
    "SimRig": "sim",
    "TwinRig": "sim",
    "make_rig": "sim",
    "RemoteError": "remote",
    "RemoteRig": "remote",
    "open_remote": "remote",
    "VectorRig": "vector",
}


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        return getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
