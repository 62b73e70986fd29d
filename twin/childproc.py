"""A helper program spoken to over its stdin and stdout: the firmware's co-simulation (``twin.avr.core``), a
controller FMU's host (``twin.fmi.controller``). Native code that can crash, ``exit`` or hang runs there, never
in ballbeam's process; this side reads the answers with a deadline and says how the program ended."""

from __future__ import annotations

import os
import select
import signal
import subprocess

__all__ = ["Child"]


class Child:
    """One helper process. ``name`` starts every message; ``what`` names the process in them ("the
    co-simulation"); ``error`` is the exception raised; ``hint`` is added to the message when it ends."""

    def __init__(
        self,
        argv: list[str],
        *,
        name: str,
        what: str,
        error: type[Exception],
        timeout_s: float,
        hint: str = "",
    ) -> None:
        self.name, self.what, self.error, self.timeout_s, self.hint = name, what, error, timeout_s, hint
        self._pending = b""  # answers read from the pipe, not yet taken
        self.stopped = ""  # why ``line`` ended early: the process ended or did not answer (the message)
        self.proc: subprocess.Popen[bytes] | None = subprocess.Popen(
            argv,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,  # a looping fault prints without bound; never shown
            bufsize=0,  # one write per request: no buffer to flush
        )

    def alive(self) -> subprocess.Popen[bytes]:
        if self.proc is None:
            raise self.error(f"{self.name}: {self.what} is closed")
        return self.proc

    def write(self, data: bytes) -> None:
        proc = self.alive()
        assert proc.stdin is not None
        try:
            proc.stdin.write(data)
        except OSError:
            raise self.error(self.ended()) from None

    def read(self, n: int) -> bytes:
        """The next ``n`` bytes of the answers, read in as large pieces as the pipe holds."""
        while len(self._pending) < n:
            proc = self.alive()
            assert proc.stdout is not None
            fd = proc.stdout.fileno()
            ready, _, _ = select.select([fd], [], [], self.timeout_s)
            if not ready:
                proc.kill()
                raise self.error(f"{self.name}: {self.what} did not answer within {self.timeout_s:g} s")
            chunk = os.read(fd, 1 << 16)
            if not chunk:
                raise self.error(self.ended())
            self._pending += chunk
        out, self._pending = self._pending[:n], self._pending[n:]
        return out

    def line(self) -> bytes:
        """A line of text (its first 1024 bytes), or what came before the process ended."""
        out = b""
        while not out.endswith(b"\n") and len(out) < 1024:
            try:
                out += self.read(1)
            except Exception as exc:  # noqa: BLE001 - ended: what came is the line, how it ended is kept
                self.stopped = str(exc)
                break
        return out.strip()

    def ended(self) -> str:
        """How the process ended (it is waited for), as a message."""
        code = self.alive().wait()
        self.proc = None
        how = f"signal {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
        return f"{self.name}: {self.what} ended ({how}){self.hint}"

    def close(self, goodbye: bytes = b"", wait_s: float = 5.0) -> None:
        """``goodbye`` sent, its input closed, waited for ``wait_s``, then killed."""
        proc, self.proc = self.proc, None
        if proc is None:
            return
        try:
            if proc.poll() is None and proc.stdin is not None:
                if goodbye:
                    proc.stdin.write(goodbye)
                proc.stdin.close()
            proc.wait(timeout=wait_s)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
