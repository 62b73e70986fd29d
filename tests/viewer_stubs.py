"""A controller catalogue for the live view's tests that declares its capabilities as the catalogue's data
(``ENTRIES``, twin.engine.CatalogueEntry) and a controller that declares a settable setpoint
(twin.interface.Setpoint), whatever the registry's own controllers declare."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from controllers import registry
from twin.engine import CatalogueEntry, StateLaw
from twin.interface import Controller, DaqSample, Setpoint, Telemetry
from twin.parameters import Parameters


class Tracking(Controller):
    """A registry controller whose law has a reference position, declaring it as ``setpoint_m``."""

    def __init__(self, inner: Controller) -> None:
        super().__init__()
        self.inner = inner
        self.name, self.period_s = inner.name, inner.period_s

    @property
    def telemetry(self) -> Telemetry:  # type: ignore[override]
        return self.inner.telemetry

    @telemetry.setter
    def telemetry(self, value: Telemetry) -> None:
        pass  # Controller.__init__ sets one; the inner controller's is the one logged

    @property
    def setpoint_m(self) -> float:
        return float(self.inner.law.ref_x_m)  # type: ignore[attr-defined]

    @setpoint_m.setter
    def setpoint_m(self, value: float) -> None:
        self.inner.law.ref_x_m = value  # type: ignore[attr-defined]

    def start(self, sample: DaqSample) -> None:
        self.inner.start(sample)

    def update(self, sample: DaqSample) -> float:
        return self.inner.update(sample)


TRACKING = ("lqr", "sf", "clp")  # the registry's 50 Hz controllers whose law regulates to ref_x_m


class StubCatalogue:
    """The registry's controllers (``TRACKING`` ones declaring a setpoint) plus ``extra`` builders."""

    def __init__(
        self,
        extra: Mapping[str, Callable[[Parameters | None], Any]] | None = None,
        setpoint: tuple[str, ...] = (),
    ) -> None:
        """``setpoint``: the ``extra`` names whose entry declares a setpoint."""
        self.extra = dict(extra or {})
        self.NAMES = (*registry.NAMES, *self.extra)
        self.ENTRIES = {
            name: CatalogueEntry(
                name=name,
                build=lambda params, name=name: self.make(name, params),
                description=name,
                simulation_only=False,
                batched=False,
                setpoint=name in TRACKING or name in setpoint,
            )
            for name in self.NAMES
        }

    def make(self, name: str, params: Parameters | None = None) -> Controller | StateLaw:
        if name in self.extra:
            return self.extra[name](params)
        built = registry.make(name, params)
        if name in TRACKING and not isinstance(built, Setpoint):
            assert isinstance(built, Controller)
            return Tracking(built)
        return built
