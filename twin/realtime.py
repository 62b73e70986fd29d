"""Real-time pacing of a closed loop (hardware-in-the-loop style): each tick starts when its DAQ block
would be complete on the rig, on the wall clock, and the timing is measured.

The rig software's timer fires every ``period_s``; a controller that needs longer than that misses the
next block. ``WallClockPacer`` waits (sleep, then a short spin for the last half millisecond) until tick
k's wall-clock deadline, start + (k + 1)·T, and records how late each tick began (jitter) and how long it
took. An overrun is a tick that began a whole period late or took longer than a period.
"""

from __future__ import annotations

import math
import time
from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "OVERRUN_WARNING_SHARE",
    "TickTiming",
    "WallClockPacer",
    "arrival_timing",
    "overrun_warning",
    "tick_timing",
]

_SPIN_S = 0.0005  # sleep() overshoots by up to a scheduler quantum: spin for the last half millisecond


@dataclass(frozen=True)
class TickTiming:
    """How a real-time run kept time (milliseconds)."""

    ticks: int
    period_ms: float
    jitter_p50_ms: float
    jitter_p99_ms: float
    jitter_max_ms: float
    compute_p50_ms: float
    compute_max_ms: float
    overruns: int

    def to_json(self) -> dict[str, float | int]:
        return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


# Above this share of overrun ticks a run did not keep real time: on the rig those ticks' blocks would have
# been missed. A controller within its period on an idle machine overruns none.
OVERRUN_WARNING_SHARE = 0.01


def overrun_warning(timing: TickTiming) -> str | None:
    """One line saying that a paced run did not keep real time (more than ``OVERRUN_WARNING_SHARE`` of its ticks
    overran), or None. The simulation does not depend on the pace: the verdict stands, the timing does not."""
    if timing.ticks == 0 or timing.overruns <= OVERRUN_WARNING_SHARE * timing.ticks:
        return None
    return (
        f"real time not kept: {timing.overruns} of {timing.ticks} ticks overran "
        f"({100 * timing.overruns / timing.ticks:.0f} %, above {100 * OVERRUN_WARNING_SHARE:g} %): a tick began a "
        f"period late or computed longer than the period ({timing.period_ms:g} ms; longest compute "
        f"{timing.compute_max_ms:.1f} ms, latest start {timing.jitter_max_ms:.1f} ms); the verdict is the "
        "simulation's and stands, the timing figures are this machine's: run on an idle machine"
    )


@dataclass
class WallClockPacer:
    """Call ``wait(k)`` before tick k and ``done()`` after it; ``timing()`` summarises."""

    period_s: float
    clock: Callable[[], float] = time.perf_counter
    sleep: Callable[[float], None] = time.sleep
    _start: float = math.nan
    # Doubles, not Python floats: 16 B per tick over a long session
    _late: array[float] = field(default_factory=lambda: array("d"))
    _compute: array[float] = field(default_factory=lambda: array("d"))
    _began: float = math.nan

    def wait(self, k: int) -> None:
        now = self.clock()
        if math.isnan(self._start):
            self._start = now  # the release: block 0 completes one period later
        deadline = self._start + (k + 1) * self.period_s
        if deadline - now > _SPIN_S:
            self.sleep(deadline - now - _SPIN_S)
        while (now := self.clock()) < deadline:
            pass
        self._began = now
        self._late.append(now - deadline)

    def done(self) -> None:
        self._compute.append(self.clock() - self._began)

    def timing(self) -> TickTiming:
        return tick_timing(self._late, self._compute, self.period_s)


def tick_timing(late_s: Sequence[float], compute_s: Sequence[float], period_s: float) -> TickTiming:
    """The figures of ticks that were ``late_s`` (s after their due time; negative: early) and spent
    ``compute_s`` in the controller: percentiles, maxima, and overruns (late by a period or computing longer)."""
    late = np.array(late_s or [0.0], dtype=float) * 1e3
    compute = np.array(compute_s or [0.0], dtype=float) * 1e3
    period_ms = period_s * 1e3
    return TickTiming(
        ticks=len(late_s),
        period_ms=period_ms,
        jitter_p50_ms=float(np.percentile(late, 50)),
        jitter_p99_ms=float(np.percentile(late, 99)),
        jitter_max_ms=float(late.max()),
        compute_p50_ms=float(np.percentile(compute, 50)),
        compute_max_ms=float(compute.max()),
        overruns=int(np.sum((late >= period_ms) | (compute > period_ms))),
    )


def arrival_timing(arrivals_s: Sequence[float], compute_s: Sequence[float], period_s: float) -> TickTiming:
    """Tick timing from the wall-clock arrivals of the blocks after the first: jitter is an arrival's
    lateness against the first's + k·period (negative: early), compute the controller's update and write."""
    t = np.asarray(arrivals_s, dtype=float)
    late_s = (t - t[0] - np.arange(t.size) * period_s).tolist() if t.size else []
    return tick_timing(late_s, compute_s, period_s)
