"""The shadow in the live view (``twin.viewer.monitor``): the monitor gets every block of the view's run with
the DAC volts held during it, the real shadow raises no alarm on the nominal rig and one within 10 s when
the rig's motor is warm (the drift slider), the loop never waits on it, and a view without one refuses it."""

from __future__ import annotations

import math
import threading
import time
from functools import cache
from typing import Any

import numpy as np
import pytest

from calib.shadow import Shadow
from controllers import registry
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.app.shadow import reference_band
from twin.interface import Controller
from twin.parameters import Parameters
from twin.viewer.monitor import ShadowWorker
from twin.viewer.session import LiveTwin

X0, TH0 = HARDWARE_STARTS["Fig 6.16 (state feedback)"]


class Recorder:
    """A monitor that keeps what it is given; ``process`` may be made to wait on ``gate``."""

    threshold = 7.0
    alarmed = False

    def __init__(self, gate: threading.Event | None = None) -> None:
        self.added: list[tuple[Any, ...]] = []
        self.sessions = 0
        self.gate = gate
        self.processing = threading.Event()

    def add(self, *sample: Any) -> None:
        self.added.append(sample)

    def new_session(self) -> None:
        self.sessions += 1

    def pending(self) -> int:
        return 1 if self.gate is not None and not self.gate.is_set() else 0

    def process(self) -> list[Any]:
        self.processing.set()
        if self.gate is not None:
            self.gate.wait(60.0)
        return []


def _live(monitor: Any) -> LiveTwin:
    live = LiveTwin(Parameters(), registry, "appendix-sf", 0, 1.0, monitor=lambda _p: monitor)
    live.apply("initial", (X0, TH0))
    live.apply("reset")
    return live


def _wait(predicate: Any, what: str) -> None:
    deadline = time.monotonic() + 120.0
    while not predicate():
        assert time.monotonic() < deadline, what
        time.sleep(0.01)


@pytest.mark.quick
def test_the_monitor_gets_every_block_with_the_dac_held_during_it() -> None:
    rec = Recorder()
    live = _live(rec)
    live.apply("shadow", True)
    live.apply("reset")  # a run from its start: seq 0 is its held block
    for _ in range(150):
        live.tick()
    log = live.loop.log()
    _wait(lambda: len(rec.added) >= 1 + 1 + 150, "the worker took every sample")
    live.close()
    fed = list(rec.added)
    first = next(i for i in range(len(fed) - 1, -1, -1) if fed[i][0] == 0)  # the reset run's seq 0
    run = fed[first:]
    assert [s[0] for s in run] == list(range(151))
    assert run[0][4] & 1  # held
    for k, (_seq, t, ball_v, angle_v, _flags, dac_v) in enumerate(run):
        assert (t, ball_v, angle_v) == (log.timem[k], log.datam1[k], log.datam2[k]), k
        if k:
            assert dac_v == log.aout[k - 1], k  # the command written at tick k − 1 acts during block k
    assert rec.sessions == 1  # the reset's run (switched on, a fresh monitor is its first session)


def test_the_loop_never_waits_on_the_shadow() -> None:
    gate = threading.Event()
    rec = Recorder(gate)
    live = _live(rec)
    live.apply("shadow", True)
    _wait(rec.processing.is_set, "the worker is inside process()")
    for _ in range(300):  # six seconds of ticks while the monitor is stuck: none of them waits on it
        live.tick()
    assert live.rig.time_s > 5.9 and len(rec.added) <= 2
    gate.set()
    _wait(lambda: len(rec.added) >= 301, "the backlog reached the monitor once it was free")
    live.close()


@pytest.mark.quick
def test_a_view_without_a_shadow_refuses_it() -> None:
    live = LiveTwin(Parameters(), registry, "appendix-sf", 0, 1.0)
    live.apply("shadow", True)
    assert live.shadow is None and "without a shadow" in live.refusals[-1].reason


@pytest.mark.quick
def test_a_failing_monitor_is_reported_and_the_view_goes_on() -> None:
    def broken(_p: Parameters) -> Any:
        raise RuntimeError("no band")

    worker = ShadowWorker(broken, Parameters())
    _wait(lambda: not worker.alive, "the worker ended")
    assert worker.snapshot().status == "shadow failed: RuntimeError: no band"


@cache
def _real() -> Any:
    p = Parameters()

    def build() -> Controller:
        c = registry.make("appendix-sf", p)
        assert isinstance(c, Controller)
        return c

    band = reference_band(p, build)
    return lambda params: Shadow(params, band)


@pytest.mark.parametrize(("drift_pct", "alarm"), [(0.0, False), (15.0, True)])
def test_the_views_shadow_catches_a_warm_motor_and_not_a_nominal_one(drift_pct: float, alarm: bool) -> None:
    live = LiveTwin(Parameters(), registry, "appendix-sf", 0, 1.0, monitor=_real())
    live.apply("initial", (X0, TH0))
    live.apply("drift", drift_pct)
    live.apply("shadow", True)
    _wait(lambda: live.shadow is not None and live.shadow.snapshot().ready, "the shadow is built")
    live.apply("reset")  # the drift applies from this run; the shadow keeps the nominal parameters
    expected = Parameters().motor.resistance_ohm * (1 + drift_pct / 100)
    assert live.rig.params.motor.resistance_ohm == pytest.approx(expected)
    for _ in range(20 * 50):  # 20 s of the run
        live.tick()
    shadow = live.shadow
    assert shadow is not None
    _wait(lambda: shadow.scored + shadow.skipped >= 18, "the shadow worked the windows off")
    snap = shadow.snapshot()
    live.close()
    assert bool(snap.alarms) == alarm, snap.status
    if alarm:
        assert snap.alarms[0][1] <= 10.0 and "DRIFT ALARM" in snap.status
    else:
        assert "no drift" in snap.status and np.nanmax(snap.sums["angle"]) < snap.threshold
    w = snap.windows[-1]  # the plot's data: a predicted span against its readings
    assert w.t_s.size == 25 and all(math.isfinite(v) for v in w.predicted["angle"])


@pytest.mark.quick
def test_the_status_reports_the_bands_progress_while_it_is_measured() -> None:
    """A factory taking ``progress`` (``twin.app.shadow.view_monitor``'s) has the fraction of its band in the
    status, in place of a bare "measuring" over blank charts."""
    gate, reached = threading.Event(), threading.Event()
    rec = Recorder()

    def building(_p: Parameters, progress: Any = None) -> Any:
        progress(0.25)
        reached.set()
        gate.wait(60.0)
        progress(1.0)
        return rec

    worker = ShadowWorker(building, Parameters(), run=3)
    _wait(reached.is_set, "the band is a quarter built")
    snap = worker.snapshot()
    assert not snap.ready and snap.status.startswith("shadow: measuring its band") and "25 %" in snap.status
    gate.set()
    _wait(lambda: worker.snapshot().ready, "the shadow is built")
    worker.feed(0, 12.5, 1.0, 2.0, 1, 2.5)
    _wait(lambda: "from t = 12.50 s" in worker.snapshot().status, "the status names where it joined")
    assert worker.snapshot().status.startswith("shadow: watching run 3 from t = 12.50 s")
    worker.stop()


def test_an_alarm_and_the_windows_are_on_the_runs_clock() -> None:
    """The shadow switched on 10 s into a warm-motor run: its windows, sums and alarm are at the times the run
    shows (t from its release, > 10 s), and the alarm names the run."""
    live = LiveTwin(Parameters(), registry, "appendix-sf", 0, 1.0, monitor=_real())
    live.apply("initial", (X0, TH0))
    live.apply("drift", 15.0)
    live.apply("reset")
    for _ in range(10 * 50):  # 10 s of the run before the shadow is asked for
        live.tick()
    on_s = live.rig.time_s
    live.apply("shadow", True)
    shadow = live.shadow
    assert shadow is not None
    _wait(lambda: shadow.snapshot().ready, "the shadow is built")
    for _ in range(15 * 50):
        live.tick()
    _wait(lambda: shadow.scored + shadow.skipped >= 12, "the shadow worked the windows off")
    snap = shadow.snapshot()
    times = live.loop.log().timem
    live.close()
    assert snap.alarms, snap.status
    channel, at, run = snap.alarms[0]
    assert run == live.runs == snap.run
    assert on_s + 2.0 <= at <= on_s + 12.0 and np.min(np.abs(times - at)) < 1e-9  # a time the run showed
    assert f"DRIFT ALARM** at t = {at:.2f} s of run {run} ({channel})" in snap.status
    assert all(on_s < w.t_s[0] and w.t_s[-1] <= times[-1] for w in snap.windows)
    assert snap.sums_t.size and on_s < snap.sums_t[0] and np.all(np.diff(snap.sums_t) > 0)
