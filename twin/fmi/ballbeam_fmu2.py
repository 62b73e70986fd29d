"""The rig as an FMI 2.0 co-simulation unit: the script ``ballbeam export-fmu --fmi 2`` packs into ``BallBeam.fmu``
(pythonfmu wraps it in its FMI library; the importer's Python must have ``ballbeam-twin`` installed). The rig,
its variables and the step are ``twin.fmi.unit.RigUnit``'s, as for FMI 3.0 (``ballbeam_fmu.py``)."""

from __future__ import annotations

from typing import Any

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status

from twin.fmi.unit import RigUnit, release_state_at_exit

_KINDS = {"float": Real, "int": Integer, "bool": Boolean}
_CAUSALITY = {
    "parameter": Fmi2Causality.parameter,
    "input": Fmi2Causality.input,
    "output": Fmi2Causality.output,
}
_VARIABILITY = {
    "parameter": Fmi2Variability.fixed,
    "input": Fmi2Variability.discrete,
    "output": Fmi2Variability.discrete,
}


class BallBeam(Fmi2Slave):
    """The ball-and-beam rig of the thesis: MuJoCo plant, motor, amplifier, sensor chains and the PCI-1712."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        release_state_at_exit(self.resources, type(self).__name__)  # pythonfmu's double free at exit
        self.rig = RigUnit(self.resources)
        self.author = "ballbeam-twin"
        self.description = self.rig.description
        self.version = self.rig.version
        for var in self.rig.build_variables(_KINDS, _CAUSALITY, _VARIABILITY, units=False):
            self.register_variable(var, nested=False)

    def to_xml(self, model_options: dict[str, str] | None = None) -> Any:
        """pythonfmu's description plus the InitialUnknowns FMI 2.0 requires (§2.2.8): every output, whose
        initial value is calculated at initialization's end."""
        from xml.etree.ElementTree import SubElement

        root = super().to_xml(model_options or {})
        structure = root.find("ModelStructure")
        unknowns = SubElement(structure, "InitialUnknowns")
        for index, var in enumerate(self.vars.values(), start=1):
            if var.causality == Fmi2Causality.output:
                SubElement(unknowns, "Unknown", attrib={"index": str(index)})
        return root

    def exit_initialization_mode(self) -> None:
        self.rig.start()

    def do_step(self, current_time: float, step_size: float) -> bool:
        refused = self.rig.step(current_time, step_size)
        if refused is not None:
            self.log(refused, status=Fmi2Status.error)
            return False
        return True
