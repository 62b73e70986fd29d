"""The shadow in the live view: a drift monitor following the view's own stream, off the simulation loop.

The monitor itself (``calib.shadow.Shadow``: each window predicted by the twin at the parameters it was
started with, a CUSUM drift alarm) is the application's: the core never imports ``calib``, so the view is
handed a ``MonitorFactory`` (parameters → a ``Monitor``), as it is handed the controller catalogue.

``ShadowWorker`` owns the monitor in a daemon thread: building it (the band takes tens of seconds, minutes on a
loaded machine; a factory taking a ``progress`` keyword reports the fraction built, shown in the status) and
predicting windows (~0.6 s a batch) never wait in the 50 Hz loop, which only puts each tick's sample on a
queue. The GUI reads ``snapshot()``: the latest scored windows of the run being watched (measured and
predicted), its sums, the alarms and a status line — all on the run's clock (t from its release, the time
the view shows), each alarm with its run.
"""

from __future__ import annotations

import inspect
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


# Parameters → a monitor; one whose ``progress`` keyword takes the fraction of its build done reports it.
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
    # (channel, t of the run, the run's number), oldest first
    alarms: list[tuple[str, float, int]] = field(default_factory=list)
    run: int = 0  # the view's run the windows and sums are of (0: none yet)


_BUILDING = "shadow: measuring its band (the twin's own runs at these parameters)…"
_STOP = ("stop",)
_SESSION = ("session",)


class _Stopped(Exception):
    """Raised from the build's progress report: the worker was stopped while its band was being built."""


class ShadowWorker:
    """The monitor built from ``factory(params)`` in a daemon thread, fed by ``feed`` (any thread, never
    blocks), working its windows off whenever samples are not waiting. ``run`` is the number of the view's
    run it starts on (``new_session`` gives each next one's).

    ``stop`` ends the thread at its next step (a band being built is abandoned at its next progress report);
    until it has ended, ``resume`` takes the stop back, so that a checkbox toggled on and off never has more
    than one worker building (each build holds a band's memory and a core for tens of seconds)."""

    def __init__(self, factory: MonitorFactory, params: Parameters, run: int = 0) -> None:
        self._queue: queue.SimpleQueue[tuple[Any, ...]] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._status = _BUILDING
        self._ready = False
        self._windows: deque[MonitorWindow] = deque(maxlen=WINDOWS_SHOWN)
        self._sums: deque[tuple[float, float, float]] = deque(maxlen=SUMS_SHOWN)
        self._alarms: list[tuple[str, float, int]] = []
        self._threshold = math.nan
        self._run = run  # the worker thread's: the run of the samples it takes
        self._from_s = math.nan  # t of the first sample it took of that run
        self.scored = 0
        self.skipped = 0
        self._stopping = False  # stop asked for (under the lock); resume takes it back until it is honoured
        self._ended = False  # the thread has ended or honoured a stop (under the lock): it cannot resume
        self._thread = threading.Thread(
            target=self._run_thread, args=(factory, params), name="shadow", daemon=True
        )
        self._thread.start()

    # --- any thread ----------------------------------------------------------------------------------
    def feed(self, seq: int, time_s: float, ball_v: float, angle_v: float, flags: int, dac_v: float) -> None:
        self._queue.put(("sample", seq, time_s, ball_v, angle_v, flags, dac_v))

    def new_session(self, run: int | None = None) -> None:
        """A new run (the view's ``run``, else the next): its ticks count from 0 again (the sums carry on:
        the rig is the same)."""
        self._queue.put((*_SESSION, run))

    def stop(self) -> None:
        with self._lock:
            self._stopping = True
        self._queue.put(_STOP)

    def resume(self) -> bool:
        """Take back a ``stop`` the thread has not honoured yet: True if it goes on (the caller starts a new
        session for it: samples were not fed meanwhile), False if it has ended."""
        with self._lock:
            if self._ended:
                return False
            self._stopping = False
            return True

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
                run=self._run,
            )

    # --- the worker's thread -------------------------------------------------------------------------
    def _build(self, factory: MonitorFactory, params: Parameters) -> Monitor:
        """The monitor; a factory that takes ``progress`` reports the band's build into the status."""

        def progress(fraction: float) -> None:
            with self._lock:
                if self._stopping:
                    self._ended = True
                    raise _Stopped
                self._status = f"{_BUILDING} {100.0 * min(max(fraction, 0.0), 1.0):.0f} %"

        try:
            takes_progress = "progress" in inspect.signature(factory).parameters
        except (TypeError, ValueError):  # a callable without a signature: built without progress
            takes_progress = False
        build: Callable[..., Monitor] = factory  # its keywords are not in MonitorFactory's type
        return build(params, progress=progress) if takes_progress else build(params)

    def _run_thread(self, factory: MonitorFactory, params: Parameters) -> None:
        try:
            self._work(factory, params)
        finally:
            with self._lock:
                self._ended = True

    def _work(self, factory: MonitorFactory, params: Parameters) -> None:
        try:
            monitor = self._build(factory, params)
        except _Stopped:
            return
        except Exception as exc:  # noqa: BLE001 - a monitor that cannot be built is reported, the view goes on
            with self._lock:
                self._status = f"shadow failed: {type(exc).__name__}: {exc}"
            return
        with self._lock:
            self._ready = True
            self._threshold = monitor.threshold
            self._status = f"shadow: watching run {self._run}"
        try:
            self._follow(monitor)
        except Exception as exc:  # noqa: BLE001 - a failing prediction stops the shadow, not the view
            with self._lock:
                self._status = f"shadow failed: {type(exc).__name__}: {exc}"

    def _follow(self, monitor: Monitor) -> None:
        while True:
            try:
                item = self._queue.get(timeout=0.05 if monitor.pending() else None)
            except queue.Empty:
                item = None
            if item is _STOP:
                with self._lock:
                    if self._stopping:
                        self._ended = True
                        return
                continue  # resumed since: this stop was taken back
            if item is not None and item[0] == _SESSION[0]:
                while monitor.pending():  # the run's last complete windows, before its stream is forgotten
                    self._publish(monitor.process())
                monitor.new_session()
                with self._lock:
                    self._run = item[1] if item[1] is not None else self._run + 1
                    self._from_s = math.nan
                    self._windows.clear()
                    self._sums.clear()
                    self._status = f"shadow: watching run {self._run}"
            elif item is not None:
                monitor.add(*item[1:])
                if math.isnan(self._from_s):
                    with self._lock:
                        self._from_s = item[2]
                        if not self._alarms:
                            self._status = (
                                f"shadow: watching run {self._run} from t = {self._from_s:.2f} s (its first "
                                "window is predicted 2 s later)"
                            )
            if item is None or (self._queue.empty() and monitor.pending()):
                self._publish(monitor.process())

    def _publish(self, windows: Sequence[MonitorWindow]) -> None:
        with self._lock:
            for w in windows:
                if w.skipped:
                    self.skipped += 1
                    continue
                self.scored += 1
                self._windows.append(w)
                self._sums.append((w.end_s, w.cusum["ball"], w.cusum["angle"]))
                self._alarms += [(a.channel, a.time_s, self._run) for a in w.alarms]
            if self._alarms:
                channel, at, run = self._alarms[0]
                self._status = (
                    f"**DRIFT ALARM** at t = {at:.2f} s of run {run} ({channel}): the rig no longer behaves "
                    f"as the twin predicts ({len(self._alarms)} alarm(s))"
                )
            elif self._sums:
                upto, ball, angle = self._sums[-1]
                self._status = (
                    f"shadow: no drift in run {self._run} up to t = {upto:.2f} s — CUSUM ball {ball:.1f}, "
                    f"angle {angle:.1f} of {self._threshold:g} ({self.scored} windows scored, {self.skipped} not)"
                )
