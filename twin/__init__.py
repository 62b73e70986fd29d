"""ballbeam-twin: MuJoCo digital twin of the two-wire ball-and-beam rig."""

from twin.parameters import ParameterError, Parameters
from twin.plant import Plant
from twin.reference import ReferenceModel

__all__ = ["Parameters", "ParameterError", "Plant", "ReferenceModel"]
