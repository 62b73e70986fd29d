"""The shadow in the live view: a drift monitor following the view's own stream, off the simulation loop.

The monitor itself (``calib.shadow.Shadow``: each window predicted by the twin at the parameters it was
started with, a CUSUM drift alarm) is the application's: the core never imports ``calib``, so the view is
handed a ``MonitorFactory`` (parameters → a ``Monitor``), as it is handed the controller catalogue.

``ShadowWorker`` owns the monitor in a daemon thread: building it (the band takes seconds) and predicting
windows (~0.6 s a batch) never wait in the 50 Hz loop, which only puts each tick's sample on a queue. The
GUI reads ``snapshot()``: the latest scored windows (measured and predicted), the sums against time, the
alarms and a status line.
"""

from __future__ import annotations

import math
import queue
import threading
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from twin.parameters import Parameters

__all__ = ["Monitor", "MonitorFactory", "MonitorWindow", "ShadowSnapshot", "ShadowWorker"]

WINDOWS_SHOWN = 5  # predicted spans drawn (the last five seconds of predictions)
SUMS_SHOWN = 120  # windows of CUSUM history drawn (two minutes)


class MonitorWindow(Protocol):
    """A processed window (``calib.shadow.WindowScore``), read only."""

    @property
    def end_s(self) -> float: ...
    @property
    def skipped(self) -> str: ...  # why it was not scored ("" when it was)
    @property
    def t_s(self) -> np.ndarray: ...
    @property
    def measured(self) -> Mapping[str, np.ndarray]: ...
    @property
    def predicted(self) -> Mapping[str, np.ndarray]: ...
    @property
    def cusum(self) -> Mapping[str, float]: ...
    @property
    def alarms(self) -> Sequence[Any]: ...  # each with .channel and .time_s


class Monitor(Protocol):
    """A drift monitor of a sample stream (``calib.shadow.Shadow``)."""

    @property
    def alarmed(self) -> bool: ...

    @property
    def threshold(self) -> float: ...

    def add(
        self, seq: int, time_s: float, ball_v: float, angle_v: float, flags: int, dac_v: float
    ) -> None: ...

    def new_session(self) -> None: ...

    def pending(self) -> int: ...

    def process(self) -> Sequence[MonitorWindow]: ...


MonitorFactory = Callable[[Parameters], Monitor]


@dataclass
class ShadowSnapshot:
    """What the GUI shows of the shadow, copied under the worker's lock."""

    status: str
    ready: bool
    windows: list[MonitorWindow] = field(default_factory=list)  # the last scored ones, oldest first
    sums_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sums: dict[str, np.ndarray] = field(default_factory=dict)
    threshold: float = math.nan
    alarms: list[tuple[str, float]] = field(default_factory=list)  # (channel, rig time), oldest first


_STOP = ("stop",)
_SESSION = ("session",)


class ShadowWorker:
    """The monitor built from ``factory(params)`` in a daemon thread, fed by ``feed`` (any thread, never
    blocks), working its windows off whenever samples are not waiting."""

    def __init__(self, factory: MonitorFactory, params: Parameters) -> None:
        self._queue: queue.SimpleQueue[tuple[Any, ...]] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._status = "shadow: measuring its band (the twin's own runs at these parameters)…"
        self._ready = False
        self._windows: deque[MonitorWindow] = deque(maxlen=WINDOWS_SHOWN)
        self._sums: deque[tuple[float, float, float]] = deque(maxlen=SUMS_SHOWN)
        self._alarms: list[tuple[str, float]] = []
        self._threshold = math.nan
        self.scored = 0
        self.skipped = 0
        self._thread = threading.Thread(target=self._run, args=(factory, params), name="shadow", daemon=True)
        self._thread.start()

    # --- any thread ----------------------------------------------------------------------------------
    def feed(self, seq: int, time_s: float, ball_v: float, angle_v: float, flags: int, dac_v: float) -> None:
        self._queue.put(("sample", seq, time_s, ball_v, angle_v, flags, dac_v))

    def new_session(self) -> None:
        """A new run: its ticks count from 0 again (the sums carry on: the rig is the same)."""
        self._queue.put(_SESSION)

    def stop(self) -> None:
        self._queue.put(_STOP)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def snapshot(self) -> ShadowSnapshot:
        with self._lock:
            sums = np.array(self._sums).reshape(-1, 3)
            return ShadowSnapshot(
                status=self._status,
                ready=self._ready,
                windows=list(self._windows),
                sums_t=sums[:, 0].copy(),
                sums={"ball": sums[:, 1].copy(), "angle": sums[:, 2].copy()},
                threshold=self._threshold,
                alarms=list(self._alarms),
            )

    # --- the worker's thread -------------------------------------------------------------------------
    def _run(self, factory: MonitorFactory, params: Parameters) -> None:
        try:
            monitor = factory(params)
        except Exception as exc:  # noqa: BLE001 - a monitor that cannot be built is reported, the view goes on
            with self._lock:
                self._status = f"shadow failed: {type(exc).__name__}: {exc}"
            return
        with self._lock:
            self._ready = True
            self._threshold = monitor.threshold
            self._status = "shadow: watching (the first window is predicted 2 s into a run)"
        while True:
            try:
                item = self._queue.get(timeout=0.05 if monitor.pending() else None)
            except queue.Empty:
                item = None
            if item is _STOP:
                return
            if item is _SESSION:
                monitor.new_session()
            elif item is not None:
                monitor.add(*item[1:])
            if item is None or (self._queue.empty() and monitor.pending()):
                try:
                    self._publish(monitor, monitor.process())
                except Exception as exc:  # noqa: BLE001 - a failing prediction stops the shadow, not the view
                    with self._lock:
                        self._status = f"shadow failed: {type(exc).__name__}: {exc}"
                    return

    def _publish(self, monitor: Monitor, windows: Sequence[MonitorWindow]) -> None:
        with self._lock:
            for w in windows:
                if w.skipped:
                    self.skipped += 1
                    continue
                self.scored += 1
                self._windows.append(w)
                self._sums.append((w.end_s, w.cusum["ball"], w.cusum["angle"]))
                self._alarms += [(a.channel, a.time_s) for a in w.alarms]
            if self._alarms:
                channel, at = self._alarms[0]
                self._status = (
                    f"**DRIFT ALARM** at {at:.2f} s ({channel}): the rig no longer behaves as the twin "
                    f"predicts ({len(self._alarms)} alarm(s))"
                )
            elif self._sums:
                _, ball, angle = self._sums[-1]
                self._status = (
                    f"shadow: no drift — CUSUM ball {ball:.1f}, angle {angle:.1f} of {self._threshold:g} "
                    f"({self.scored} windows scored, {self.skipped} not)"
                )
