"""Controllers of the rig: designs (python-control) and the runtime laws that run on the twin and the rig.

The public surface (the implementation is in the modules named; every other name is internal):

    NAMES, make(name, params), describe(name),  controllers.registry: the catalogue, a table of rows
      make_batch(name, params), simulation_only(name), UnknownControllerError
    LoopController, SetpointLoopController      controllers.loop: observer + law + motor inverse behind
                                                the hardware contract (twin.interface.Controller)
    TrueStateLaw, SetpointTrueStateLaw          controllers.loop: laws on the true state (simulation only)
    AppendixStateFeedback, AppendixControlLaw   controllers.appendix: appendix A's code as printed
    PolicyController, LinearPolicy              controllers.policy: a learned policy on the rig's volts

The names load on first use: the command line's ``--help`` reads the registry's names without numpy."""

from __future__ import annotations

from twin.exports import lazy_exports

__all__ = [
    "NAMES",
    "AppendixControlLaw",
    "AppendixStateFeedback",
    "LinearPolicy",
    "LoopController",
    "PolicyController",
    "SetpointLoopController",
    "SetpointTrueStateLaw",
    "TrueStateLaw",
    "UnknownControllerError",
    "describe",
    "make",
    "make_batch",
    "simulation_only",
]

_HOMES = {
    "NAMES": "controllers.registry",
    "UnknownControllerError": "controllers.registry",
    "describe": "controllers.registry",
    "make": "controllers.registry",
    "make_batch": "controllers.registry",
    "simulation_only": "controllers.registry",
    "LoopController": "controllers.loop",
    "SetpointLoopController": "controllers.loop",
    "SetpointTrueStateLaw": "controllers.loop",
    "TrueStateLaw": "controllers.loop",
    "AppendixControlLaw": "controllers.appendix",
    "AppendixStateFeedback": "controllers.appendix",
    "LinearPolicy": "controllers.policy",
    "PolicyController": "controllers.policy",
}

__getattr__ = lazy_exports(__name__, _HOMES)
