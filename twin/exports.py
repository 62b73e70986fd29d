"""Names a package re-exports from its modules, imported on first use (PEP 562): importing a light part of
the project (the command line's ``--help``, a hardware controller importing the contract) loads no MuJoCo,
scipy or numpy that it does not use."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(package: str, homes: Mapping[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``package`` that imports each name of ``homes`` (name → module) when it is
    first read; any other name is an ``AttributeError`` naming the package."""

    def __getattr__(name: str) -> Any:
        if name in homes:
            return getattr(importlib.import_module(homes[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
