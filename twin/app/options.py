"""The types of the ``ballbeam`` command's numeric options: every number is checked when it is parsed.

A number that is not finite, outside its range, or not an integer where a count is meant is a usage error
(exit 2) whose one line names the option and the value (argparse prefixes ``argument --NAME:``). One set of
types serves every option, so that no command checks a number its own way.

Nothing heavy is imported here: ``--help`` builds the parser. A limit that lives in a heavy module (the
Monte Carlo's run count, the sweep's grid size) is given as a function, called only when the option is used.
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import re
from collections.abc import Callable

Limit = float | Callable[[], float]

# A run keeps every tick of its log in memory (and the log on disk holds them all): one simulated hour is
# 180 000 ticks at 50 Hz. ``run``'s --duration and the Gymnasium environment's episodes are held to it.
MAX_RUN_S = 3600.0
# One run of a many-run job (sweep, Monte Carlo, validate): its verdict, not its log, is kept.
MAX_JOB_RUN_S = 600.0

# ``sweep --refine``'s coarse step: on random maps step 6 misses fewer boundaries than 8 at a little more
# cost (docs/design.md, boundary refinement).
DEFAULT_REFINE_STEP = 6

# A robust map's rigs (sweep --rigs, validate's robust_rigs): past 1000 it is a typing error, not a study.
MAX_RIGS = 1000

# ``sweep --locate``'s bisections of a grid step: 1/4096 of a step is far below what the ball sensor's noise
# lets one start's verdict resolve.
MAX_LOCATE = 12

# Seeds feed numpy's SeedSequence and are written to JSON reports and int64 arrays: a non-negative int64.
SEED_MAX = 2**63 - 1


def _resolve(limit: Limit) -> float:
    return limit() if callable(limit) else limit


def _number(value: float) -> str:
    """A bound as typed: an integer in full (a seed's 9223372036854775807), a float in %g."""
    return str(value) if isinstance(value, int) else f"{value:g}"


def _describe(lo: float, hi: float, lo_open: bool, unit: str) -> str:
    """The range in words: ``0.1…4``, ``more than 0 and at most 3600 s``, ``at least 1``."""
    u = f" {unit}" if unit else ""
    low = f"more than {_number(lo)}" if lo_open else f"at least {_number(lo)}"
    if math.isinf(lo) and math.isinf(hi):
        return "any finite number"
    if math.isinf(hi):
        return f"{low}{u}"
    if math.isinf(lo):
        return f"at most {_number(hi)}{u}"
    if lo_open:
        return f"{low} and at most {_number(hi)}{u}"
    return f"{_number(lo)}…{_number(hi)}{u}"


class NumberType:
    """An argparse ``type``: the option's text → a finite float (or an int for a count) in ``lo … hi``."""

    def __init__(
        self,
        *,
        integer: bool,
        lo: Limit = -math.inf,
        hi: Limit = math.inf,
        lo_open: bool = False,
        unit: str = "",
        why: str = "",
    ) -> None:
        self.integer = integer
        self.lo, self.hi, self.lo_open = lo, hi, lo_open
        self.unit, self.why = unit, why
        # argparse names the type in its own messages ("invalid finite_float value")
        self.__name__ = "count" if integer else "finite_float"

    def range_text(self) -> str:
        return _describe(_resolve(self.lo), _resolve(self.hi), self.lo_open, self.unit)

    def __call__(self, text: str) -> float | int:
        shown = text if len(text) <= 40 else text[:37] + "..."
        value: float | int
        if self.integer:
            try:
                value = int(text.strip(), 10)
            except ValueError:
                raise argparse.ArgumentTypeError(f"{shown!r} is not an integer") from None
        else:
            try:
                value = float(text)
            except ValueError:
                raise argparse.ArgumentTypeError(f"{shown!r} is not a number") from None
        lo, hi = _resolve(self.lo), _resolve(self.hi)
        why = f" ({self.why})" if self.why else ""
        if not math.isfinite(value):
            bounded = not (math.isinf(lo) and math.isinf(hi))
            in_range = f"; expected {self.range_text()}{why}" if bounded else ""
            raise argparse.ArgumentTypeError(f"{shown} is not a finite number{in_range}")
        below = value <= lo if self.lo_open else value < lo
        if below or value > hi:
            raise argparse.ArgumentTypeError(f"{shown} is out of range; expected {self.range_text()}{why}")
        return value


def finite_float(
    lo: Limit = -math.inf, hi: Limit = math.inf, *, lo_open: bool = False, unit: str = "", why: str = ""
) -> NumberType:
    """A finite number in ``lo … hi`` (``lo`` excluded when ``lo_open``)."""
    return NumberType(integer=False, lo=lo, hi=hi, lo_open=lo_open, unit=unit, why=why)


def count(lo: Limit = 0, hi: Limit = math.inf, *, unit: str = "", why: str = "") -> NumberType:
    """An integer (written as one: ``1.5`` and ``1e3`` are refused) in ``lo … hi``."""
    return NumberType(integer=True, lo=lo, hi=hi, unit=unit, why=why)


def seed() -> NumberType:
    """A seed of the noise and the samples: a non-negative int64."""
    return count(0, SEED_MAX)


class GridType:
    """An argparse ``type`` for ``LO:HI:N`` (or one value) of ``option``: LO and HI finite with LO ≤ HI, N a
    count of 1 … ``max_n`` points. The text is returned as typed: the command builds the grid from it."""

    __name__ = "grid"

    def __init__(self, option: str, max_n: Limit) -> None:
        self.option, self.max_n = option, max_n

    def __call__(self, text: str) -> str:
        parts = text.split(":")
        shown = f"{self.option} {text if len(text) <= 40 else text[:37] + '...'!r}"
        if len(parts) not in (1, 3):
            raise argparse.ArgumentTypeError(f"{shown}: expected LO:HI:N (e.g. -0.3:0.3:31) or one value")
        bound = finite_float()
        try:
            lo = bound(parts[0])
            hi = bound(parts[-1] if len(parts) == 1 else parts[1])
        except argparse.ArgumentTypeError as exc:
            raise argparse.ArgumentTypeError(f"{shown}: LO and HI: {exc}") from None
        if lo > hi:
            raise argparse.ArgumentTypeError(f"{shown}: LO {lo:g} is above HI {hi:g}")
        if len(parts) == 3:
            try:
                count(1, self.max_n, unit="points")(parts[2])
            except argparse.ArgumentTypeError as exc:
                raise argparse.ArgumentTypeError(f"{shown}: N: {exc}") from None
        return text


class SpanType:
    """An argparse ``type`` for ``A:B`` (a range searched or drawn from) or ``A`` (a value) of ``option``: finite,
    A ≤ B. Returns (A, B)."""

    __name__ = "span"

    def __init__(self, option: str) -> None:
        self.option = option

    def __call__(self, text: str) -> tuple[float, float]:
        parts = text.split(":")
        shown = f"{self.option} {text if len(text) <= 40 else text[:37] + '...'!r}"
        if len(parts) not in (1, 2):
            raise argparse.ArgumentTypeError(f"{shown}: expected A:B (e.g. -0.7:-0.3) or one value")
        try:
            lo, hi = finite_float()(parts[0]), finite_float()(parts[-1])
        except argparse.ArgumentTypeError as exc:
            raise argparse.ArgumentTypeError(f"{shown}: {exc}") from None
        if lo > hi:
            raise argparse.ArgumentTypeError(f"{shown}: A:B with A ≤ B ({lo:g} is above {hi:g})")
        return lo, hi


_HOST_NAME = re.compile(
    r"(?=.{1,253}$)[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?(?:\.[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*\.?"
)


def serve_address(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` (``view --serve``): (host, port), the host 127.0.0.1 unless given, an IPv6 host in
    brackets (``[::1]:5750``), port 0 meaning any free one. A host is a name or an address; whether it can be
    bound is the server's to say."""
    shown = text if len(text) <= 60 else text[:57] + "..."
    host, colon, port_text = text.rpartition(":")
    if not colon:
        host = "127.0.0.1"
    elif host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not (port_text.isascii() and port_text.isdigit() and int(port_text) <= 65535):
        raise argparse.ArgumentTypeError(
            f"{shown!r}: expected [HOST:]PORT with PORT an integer 0…65535 (0: a free one)"
        )
    try:
        ipaddress.ip_address(host)
    except ValueError:
        if not _HOST_NAME.fullmatch(host):
            raise argparse.ArgumentTypeError(
                f"{shown!r}: {host[:40]!r} is not a host name or an IP address (expected [HOST:]PORT)"
            ) from None
    return host, int(port_text)
