"""ballbeam-twin: MuJoCo digital twin of the two-wire ball-and-beam rig.

The names below load on first use, so that importing a light module of the package (the command line's
``--help``) does not load MuJoCo and scipy."""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["ParameterError", "Parameters", "Plant", "ReferenceModel"]

_HOMES = {
    "ParameterError": "twin.parameters",
    "Parameters": "twin.parameters",
    "Plant": "twin.plant",
    "ReferenceModel": "twin.reference",
}


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        return getattr(importlib.import_module(_HOMES[name]), name)
    raise AttributeError(f"module 'twin' has no attribute {name!r}")
