"""A co-simulation FMU as a controller of the rig (``--controller fmu:FILE.fmu``), run in a process of its own.

``FmuController`` is a ``twin.interface.Controller``: ``start`` steps the unit once on the start block (its
output is not used: the card holds the zero command, as the software's Start does), each ``update`` sets the
block's two readings, takes one step of the period and returns ``dac_v``. The unit runs in ``twin.fmi.host``'s
process, so that a crash in its shared library, an ``exit`` or a hang ends or stalls that process only: the
run fails with a message naming what happened (the engine adds the tick).
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path

from twin.childproc import Child
from twin.fmi.archive import UnitError, unpack
from twin.fmi.host import REQUEST
from twin.interface import Controller, DaqSample

__all__ = ["ANSWER_TIMEOUT_S", "FmuController", "FmuError"]

# A step of a controller is microseconds; a unit that has not answered in this long has hung.
ANSWER_TIMEOUT_S = 30.0
_LOADED: set[Path] = set()  # the extracted units this process has started once (each is checked so once)


class FmuError(RuntimeError):
    """A controller FMU that cannot be loaded, or whose process ended or stopped answering."""


class FmuController(Controller):
    """The unit at ``path`` stepping once per ``period_s``. The unit is checked and extracted when the controller
    is built (``twin.fmi.archive.unpack``: once per process; its first build here also starts the unit once, so
    that a unit that cannot load is refused before any run); its process starts with a run (``start``) and ends
    with ``close``, so that a batch of built controllers holds no process until each one runs."""

    own_process = True  # twin.rigs.batch runs it one run at a time

    def __init__(self, path: str | Path, period_s: float = 0.02) -> None:
        super().__init__()
        self.path = Path(path)
        self.name = f"fmu:{self.path.name}"
        self.period_s = period_s
        self._child: Child | None = None
        self._t = 0.0
        try:
            self._folder = unpack(self.path)
        except UnitError as exc:
            raise FmuError(str(exc)) from None
        if self._folder not in _LOADED:
            self._spawn()
            self.close()
            _LOADED.add(self._folder)

    def _spawn(self) -> None:
        self.close()
        self._child = Child(
            [sys.executable, "-m", "twin.fmi.host", str(self._folder)],
            name=self.path.name,
            what="the unit's process",
            error=FmuError,
            timeout_s=ANSWER_TIMEOUT_S,
            hint=": a crash in its library, or an exit",
        )
        line = self._child.line()
        if line != b"OK":
            if line.startswith(b"NO "):
                reason = line[3:].decode(errors="replace")
            else:  # how it ended: "the unit's process ended (signal SIGSEGV): a crash in its library, …"
                reason = self._child.stopped.partition(": ")[2] or "its process did not start"
            self.close()
            raise FmuError(f"{self.path}: {reason}")

    # --- the Controller contract --------------------------------------------------------------------------
    def start(self, sample: DaqSample) -> None:
        if (
            self._child is None or self._t
        ):  # a run's own unit; a second run of the same controller: a fresh one
            self._spawn()
        self._t = 0.0
        self._step(sample)

    def update(self, sample: DaqSample) -> float:
        return self._step(sample)

    def close(self) -> None:
        child, self._child = self._child, None
        if child is not None:
            child.close(wait_s=1.0)  # it ends when its input does, unless the unit hangs

    def __del__(self) -> None:
        self.close()

    # --- internals ----------------------------------------------------------------------------------------
    def _step(self, sample: DaqSample) -> float:
        if self._child is None:
            raise FmuError(f"{self.path}: the unit's process is not running (a step before start, or closed)")
        child = self._child
        child.write(REQUEST.pack(self._t, self.period_s, sample.ball_v, sample.angle_v))
        self._t += self.period_s
        kind = child.read(1)
        if kind == b"K":
            (dac_v,) = struct.unpack("<d", child.read(8))
            self.telemetry.u_computed = dac_v
            return float(dac_v)
        (length,) = struct.unpack("<H", child.read(2))
        raise FmuError(f"{self.path.name}: {child.read(length).decode(errors='replace')}")
