"""The rig as an FMI 3.0 co-simulation unit: the script ``ballbeam export-fmu`` packs into ``BallBeam.fmu``
(pythonfmu3 wraps it in its FMI library; the importer's Python must have ``ballbeam-twin`` installed). The rig,
its variables and the step are ``twin.fmi.unit.RigUnit``'s; this registers them as FMI 3.0 variables."""

from __future__ import annotations

from typing import Any

from pythonfmu3 import (
    Boolean,
    Float64,
    Fmi3Causality,
    Fmi3Slave,
    Fmi3Status,
    Fmi3StepResult,
    Fmi3Variability,
    Int64,
    Unit,
)

from twin.fmi.unit import RigUnit, release_state_at_exit

_KINDS = {"float": Float64, "int": Int64, "bool": Boolean}
_CAUSALITY = {
    "parameter": Fmi3Causality.parameter,
    "input": Fmi3Causality.input,
    "output": Fmi3Causality.output,
}
_VARIABILITY = {
    "parameter": Fmi3Variability.fixed,
    "input": Fmi3Variability.discrete,
    "output": Fmi3Variability.discrete,
}


class BallBeam(Fmi3Slave):
    """The ball-and-beam rig of the thesis: MuJoCo plant, motor, amplifier, sensor chains and the PCI-1712."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        release_state_at_exit(self.resources, type(self).__name__)  # pythonfmu's double free at exit
        self.rig = RigUnit(self.resources)
        self.author = "ballbeam-twin"
        self.description = self.rig.description
        self.version = self.rig.version
        self.time = 0.0
        self.register_variable(
            Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous)
        )
        for var in self.rig.build_variables(_KINDS, _CAUSALITY, _VARIABILITY, units=True):
            self.register_variable(var, nested=False)
        self.register_units([Unit(name) for name in self.rig.units()])

    def exit_initialization_mode(self) -> None:
        self.rig.start()

    def do_step(self, current_time: float, step_size: float) -> Fmi3StepResult:
        refused = self.rig.step(current_time, step_size)
        if refused is not None:
            self.log(refused, status=Fmi3Status.error)
            return Fmi3StepResult(status=Fmi3Status.error)
        self.time = current_time + step_size
        return Fmi3StepResult(status=Fmi3Status.ok)
