"""A co-simulation FMU as a controller of the rig (``--controller fmu:FILE.fmu``), run in a process of its own.

``FmuController`` is a ``twin.interface.Controller``: ``start`` steps the unit once on the start block (its
output is not used: the card holds the zero command, as the software's Start does), each ``update`` sets the
block's two readings, takes one step of the period and returns ``dac_v``. The unit runs in ``twin.fmi.host``'s
process, so that a crash in its shared library, an ``exit`` or a hang ends or stalls that process only: the
run fails with a message naming what happened (the engine adds the tick).
"""

from __future__ import annotations

import os
import select
import signal
import struct
import subprocess
import sys
from pathlib import Path

from twin.fmi.host import REQUEST
from twin.interface import Controller, DaqSample
from twin.parameters import SoftwareCalibration

__all__ = ["ANSWER_TIMEOUT_S", "FmuController", "FmuError"]

# A step of a controller is microseconds; a unit that has not answered in this long has hung.
ANSWER_TIMEOUT_S = 30.0


class FmuError(RuntimeError):
    """A controller FMU that cannot be loaded, or whose process ended or stopped answering."""


class FmuController(Controller):
    """The unit at ``path`` stepping once per ``period_s``."""

    def __init__(
        self, path: str | Path, software: SoftwareCalibration | None = None, period_s: float = 0.02
    ) -> None:
        super().__init__()
        self.path = Path(path)
        self.name = f"fmu:{self.path.name}"
        self.period_s = period_s
        self._proc: subprocess.Popen[bytes] | None = None
        self._pending = b""
        self._t = 0.0
        if not self.path.is_file():
            raise FmuError(f"{self.path}: no such FMU")
        self._spawn()

    def _spawn(self) -> None:
        self.close()
        self._pending = b""
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "twin.fmi.host", str(self.path)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            bufsize=0,
        )
        line = self._line()
        if line != b"OK":
            self.close()
            reason = (
                line[3:].decode(errors="replace") if line.startswith(b"NO ") else "its process did not start"
            )
            raise FmuError(f"{self.path}: {reason}")

    # --- the Controller contract --------------------------------------------------------------------------
    def start(self, sample: DaqSample) -> None:
        if self._t:  # a second run of the same controller: a fresh unit
            self._spawn()
        self._t = 0.0
        self._step(sample)

    def update(self, sample: DaqSample) -> float:
        return self._step(sample)

    def close(self) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            if proc.stdin is not None:
                proc.stdin.close()
            proc.wait(timeout=1)  # it ends when its input does, unless the unit hangs
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()

    def __del__(self) -> None:
        self.close()

    # --- internals ----------------------------------------------------------------------------------------
    def _step(self, sample: DaqSample) -> float:
        proc = self._alive()
        assert proc.stdin is not None
        try:
            proc.stdin.write(REQUEST.pack(self._t, self.period_s, sample.ball_v, sample.angle_v))
        except OSError:
            raise FmuError(self._ended()) from None
        self._t += self.period_s
        kind = self._read(1)
        if kind == b"K":
            (dac_v,) = struct.unpack("<d", self._read(8))
            self.telemetry.u_computed = dac_v
            return float(dac_v)
        (length,) = struct.unpack("<H", self._read(2))
        raise FmuError(f"{self.path.name}: {self._read(length).decode(errors='replace')}")

    def _alive(self) -> subprocess.Popen[bytes]:
        if self._proc is None:
            raise FmuError(f"{self.path}: the unit's process is closed")
        return self._proc

    def _ended(self) -> str:
        proc = self._alive()
        code = proc.wait()
        how = f"signal {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
        self._proc = None
        return f"{self.path.name}: the unit's process ended ({how}): a crash in its library, or an exit"

    def _line(self) -> bytes:
        out = b""
        while not out.endswith(b"\n") and len(out) < 1024:
            try:
                out += self._read(1)
            except FmuError:
                break
        return out.strip()

    def _read(self, n: int) -> bytes:
        while len(self._pending) < n:
            proc = self._alive()
            assert proc.stdout is not None
            fd = proc.stdout.fileno()
            ready, _, _ = select.select([fd], [], [], ANSWER_TIMEOUT_S)
            if not ready:
                proc.kill()
                raise FmuError(f"{self.path.name}: the unit did not answer within {ANSWER_TIMEOUT_S:g} s")
            chunk = os.read(fd, 1 << 16)
            if not chunk:
                raise FmuError(self._ended())
            self._pending += chunk
        out, self._pending = self._pending[:n], self._pending[n:]
        return out
