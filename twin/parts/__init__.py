"""The rig's parts as declared contracts (``twin.parts.contract``) and today's parts (``twin.parts.thesis``).

Part, MjcfFragment, BatchForm      what every part declares: name, role, parameter groups, equations' homes,
                                   MJCF fragment, batch form
BallSensorPart, AngleSensorPart,   the parts a simulated rig instantiates per run, with their runtime
IoBoardPart, ActuatorPart          (BallSensorChain, AngleSensorChain)
RigParts, THESIS                   a rig as one part per role; today's rig
ROLES, Role, register, registered  the registry of parts by role; PartError for a part that breaks it
rig_parts, part_named              the rig a set of parameters names (``Parameters.parts``); one part by name
vary                               parameter sets around a base, for a batch form's inputs
"""

from twin.parts.contract import (
    ROLES,
    ActuatorPart,
    AngleSensorChain,
    AngleSensorPart,
    BallSensorChain,
    BallSensorPart,
    BatchForm,
    IoBoardPart,
    MjcfFragment,
    Part,
    PartError,
    RigParts,
    Role,
    part_named,
    register,
    registered,
    rig_parts,
    vary,
)
from twin.parts.thesis import THESIS, is_thesis_rig

# The built-in parts beyond the thesis's: importing the package registers each (its group, fragment and laws),
# after the thesis's, which each role lists first.
# isort: off
from twin.parts import (  # noqa: F401
    arduino,
    as5600,
    bb01_strip,
    gp2y0a21,
    hcsr04,
    linkage,
    no_angle,
    potentiometer,
    quanser_q8,
    rod_strip,
    servo,
    shaft_encoder,
    stepper,
    tube,
    v_groove,
    vl53l0x,
)

# isort: on

__all__ = [
    "ROLES",
    "THESIS",
    "is_thesis_rig",
    "ActuatorPart",
    "AngleSensorChain",
    "AngleSensorPart",
    "BallSensorChain",
    "BallSensorPart",
    "BatchForm",
    "IoBoardPart",
    "MjcfFragment",
    "Part",
    "PartError",
    "RigParts",
    "Role",
    "part_named",
    "register",
    "registered",
    "rig_parts",
    "vary",
]
