"""The rigs a controller runs on, each behind the hardware contract ``twin.interface.Rig``:

    sim.SimRig         the MuJoCo twin with its I/O chain, with ideal converters, or the reference model
                       (``make_rig(params, plant=PlantKind, ideal_sensors=…)``, ``PlantKind`` the built-in
                       names of the backend registry ``twin.rigs.backends``, where any registered name is taken;
                       ``TwinRig``, ``ReferenceRig``; ``RigError``: a configuration it cannot run), and
                       ``run_closed_loop``: a controller on a fresh one from a start, judged
    remote.RemoteRig   a rig over protocol 1 (UDP or serial): the served twin, or a rig's own firmware
                       (``open_remote(url)``; ``RemoteError``: it cannot be reached or went silent)
    batch.BatchRig     N simulated rigs stepped together (``run_batch``) on a backend's ``BatchPhysics``, each
                       its single rig bit for bit
    vector.VectorRig   N simulated rigs reset one by one and stepped together (the vector environment)

A new kind of rig is one new module here implementing ``Rig`` (docs/design.md, "One loop, many rigs"); the
one loop (``twin.engine.ClosedLoop``) runs any of them. The names load on first use, so that importing the
remote rig does not load the batch engine.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from twin.exports import lazy_exports

if TYPE_CHECKING:  # the names' real types for a type checker; at run time they load on first use (below)
    from twin.interface import RigError
    from twin.rigs.backends import PlantKind
    from twin.rigs.batch import BatchRig, run_batch
    from twin.rigs.remote import RemoteError, RemoteRig, open_remote
    from twin.rigs.sim import ReferenceRig, SimRig, TwinRig, make_rig, run_closed_loop
    from twin.rigs.vector import VectorRig


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
    "run_closed_loop",
]

_HOMES = {
    "BatchRig": "twin.rigs.batch",
    "run_batch": "twin.rigs.batch",
    "PlantKind": "twin.rigs.backends",
    "ReferenceRig": "twin.rigs.sim",
    "RigError": "twin.interface",
    "SimRig": "twin.rigs.sim",
    "TwinRig": "twin.rigs.sim",
    "make_rig": "twin.rigs.sim",
    "run_closed_loop": "twin.rigs.sim",
    "RemoteError": "twin.rigs.remote",
    "RemoteRig": "twin.rigs.remote",
    "open_remote": "twin.rigs.remote",
    "VectorRig": "twin.rigs.vector",
}

__getattr__ = lazy_exports(__name__, _HOMES)
