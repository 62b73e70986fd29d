"""ballbeam-twin: MuJoCo digital twin of the two-wire ball-and-beam rig.

The public surface (what a user imports; the implementation lives in the modules named, and every other
name of the package's modules is internal and may change):

    Parameters, ParameterError                 twin.parameters: the rig's description, files, overrides
    Rig, RigEnded, Controller, DaqSample,      twin.interface: the hardware contract (volts in, volts out)
      Telemetry, Setpoint
    ClosedLoop, run_on_rig, RunResult,         twin.engine: the one closed loop and its runs
      StateLaw, TrueState, ControllerError
    Verdict, Criteria, Trace,                  twin.verdict: the verdict of a run (true state or measured)
      evaluate_measured
    RunLog, load_mat, load_csv                 twin.log: the run's columns, data_file.mat and CSV
    SimRig, make_rig, run_closed_loop,         twin.rigs: the rigs behind the contract
      RemoteRig, open_remote, BatchRig, run_batch
    Server, SessionSettings                    twin.serving: the twin served over protocol 1
    Plant, ReferenceModel                      twin.plant, twin.reference: the physics

The names load on first use, so that importing a light module of the package (the command line's
``--help``, a hardware controller importing the contract) does not load MuJoCo and scipy."""

from __future__ import annotations

from typing import TYPE_CHECKING

from twin.exports import lazy_exports

if TYPE_CHECKING:  # the names' real types for a type checker; at run time they load on first use (below)
    from twin.engine import ClosedLoop, ControllerError, RunResult, StateLaw, TrueState, run_on_rig
    from twin.interface import Controller, DaqSample, Rig, RigEnded, Setpoint, Telemetry
    from twin.log import RunLog, load_csv, load_mat
    from twin.parameters import ParameterError, Parameters
    from twin.plant import Plant
    from twin.reference import ReferenceModel
    from twin.rigs.batch import BatchRig, run_batch
    from twin.rigs.remote import RemoteRig, open_remote
    from twin.rigs.sim import SimRig, make_rig, run_closed_loop
    from twin.serving.server import Server, SessionSettings
    from twin.verdict import Criteria, Trace, Verdict, evaluate_measured


__all__ = [
    "BatchRig",
    "ClosedLoop",
    "Controller",
    "ControllerError",
    "Criteria",
    "DaqSample",
    "ParameterError",
    "Parameters",
    "Plant",
    "ReferenceModel",
    "RemoteRig",
    "Rig",
    "RigEnded",
    "RunLog",
    "RunResult",
    "Server",
    "SessionSettings",
    "Setpoint",
    "SimRig",
    "StateLaw",
    "Telemetry",
    "Trace",
    "TrueState",
    "Verdict",
    "evaluate_measured",
    "load_csv",
    "load_mat",
    "make_rig",
    "open_remote",
    "run_batch",
    "run_closed_loop",
    "run_on_rig",
]

_HOMES = {
    "ParameterError": "twin.parameters",
    "Parameters": "twin.parameters",
    "Controller": "twin.interface",
    "DaqSample": "twin.interface",
    "Rig": "twin.interface",
    "RigEnded": "twin.interface",
    "Setpoint": "twin.interface",
    "Telemetry": "twin.interface",
    "ClosedLoop": "twin.engine",
    "ControllerError": "twin.engine",
    "RunResult": "twin.engine",
    "StateLaw": "twin.engine",
    "TrueState": "twin.engine",
    "run_closed_loop": "twin.rigs.sim",
    "run_on_rig": "twin.engine",
    "Criteria": "twin.verdict",
    "Trace": "twin.verdict",
    "Verdict": "twin.verdict",
    "evaluate_measured": "twin.verdict",
    "RunLog": "twin.log",
    "load_csv": "twin.log",
    "load_mat": "twin.log",
    "SimRig": "twin.rigs.sim",
    "make_rig": "twin.rigs.sim",
    "RemoteRig": "twin.rigs.remote",
    "open_remote": "twin.rigs.remote",
    "BatchRig": "twin.rigs.batch",
    "run_batch": "twin.rigs.batch",
    "Server": "twin.serving.server",
    "SessionSettings": "twin.serving.server",
    "Plant": "twin.plant",
    "ReferenceModel": "twin.reference",
}

__getattr__ = lazy_exports(__name__, _HOMES)
