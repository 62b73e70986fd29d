"""Real-time pacing: ticks start at their blocks' wall-clock deadlines, lateness and overruns are counted,
and pacing changes no number of the run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controllers import registry
from twin.app.cli import main
from twin.realtime import WallClockPacer
from twin.rigs.sim import run_closed_loop


class FakeClock:
    """A wall clock that moves only when slept on or when a tick 'computes'."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        self.now += 1e-6  # reading the clock takes a microsecond (ends the spin)
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


@pytest.mark.quick
def test_ticks_start_at_their_deadlines_and_overruns_are_counted() -> None:
    clock = FakeClock()
    pacer = WallClockPacer(0.02, clock=clock, sleep=clock.sleep)
    compute_s = [0.001, 0.001, 0.05, 0.001, 0.001]  # the third tick takes 2.5 periods
    starts = []
    for k, spent in enumerate(compute_s):
        pacer.wait(k)
        starts.append(clock.now)
        clock.now += spent
        pacer.done()
    timing = pacer.timing()
    assert timing.ticks == 5
    # Deadlines at 20, 40, 60, 80, 100 ms after the release. Ticks 0–2 start on time (within the clock's
    # microseconds); tick 2 runs 50 ms, so tick 3 starts at 110 ms (30 ms late) and tick 4 at 111 ms (11 ms).
    assert starts[1] - starts[0] == pytest.approx(0.02, abs=1e-5)
    late = np.array(pacer._late) * 1e3
    assert late[:3] == pytest.approx([0, 0, 0], abs=0.01)
    assert late[3:] == pytest.approx([30.0, 11.0], abs=0.01)
    assert timing.overruns == 2  # tick 2 computed longer than a period; tick 3 began more than a period late
    assert timing.jitter_max_ms == pytest.approx(late.max())
    assert timing.compute_max_ms == pytest.approx(50.0, abs=0.01)


def test_pacing_changes_no_number_of_the_run() -> None:
    args = dict(x0_m=0.15, theta0_rad=0.1, duration_s=0.4, seed=3)
    paced = run_closed_loop(registry.make("appendix-sf"), pacer=WallClockPacer(0.02), **args)
    free = run_closed_loop(registry.make("appendix-sf"), **args)
    for name in ("timem", "datam1", "datam2", "aout", "true_x_m"):
        assert np.array_equal(getattr(paced.log, name), getattr(free.log, name))


def test_run_realtime_reports_its_timing(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        [
            "run",
            "--controller",
            "appendix-clp",
            "--x0",
            "0.1",
            "--theta0",
            "0",
            "--duration",
            "0.3",
            "--realtime",
            "--json",
        ]
    )
    out = json.loads(capsys.readouterr().out)
    assert code == 1  # a 0.3 s run is shorter than the verdict's window: not held
    assert out["realtime"]["ticks"] == 16 and out["realtime"]["period_ms"] == 20.0
    assert set(out["realtime"]) >= {"jitter_p50_ms", "jitter_p99_ms", "jitter_max_ms", "overruns"}
