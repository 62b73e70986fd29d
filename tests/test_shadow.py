"""The shadow (``calib.shadow``, ``ballbeam shadow``): the CUSUM's run lengths against the textbook's table, the
false-alarm probability by resampling against a direct simulation, the stream's windows equal to compare's
windows of the same log, the windows it must not score, memory that stays a few windows, and the acceptance:
on a served twin whose motor resistance is 15 % above the shadow's, an alarm within 10 s; on a nominal one
for 10 minutes of lock-step, none."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from cli_checks import refused

from calib.compare import windowed_prediction
from calib.logs import rig_log
from calib.shadow import Band, Cusum, Shadow, WindowScore
from controllers import registry
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.app.shadow import reference_band, watch
from twin.engine import RunResult
from twin.interface import Controller
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop
from twin.serving.observer import Observer
from twin.wire import protocol as p

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
CLI = [sys.executable, "-m", "twin.app.cli"]

P = Parameters()
WARM = P.with_overrides({"motor.resistance_ohm": P.motor.resistance_ohm * 1.15})
X0, TH0 = HARDWARE_STARTS["Fig 6.16 (state feedback)"]


def _sf(params: Parameters) -> Controller:
    c = registry.make("appendix-sf", params)
    assert isinstance(c, Controller)
    return c


@cache
def _band() -> Band:
    return reference_band(P, lambda: _sf(P))


def _feed(
    run: RunResult, shadow: Shadow, *, drop: range = range(0), watchdog: range = range(0)
) -> list[WindowScore]:
    """A run's log as the wire delivers it: SAMPLE k is log row k (row 0 the held block), the DAC during its
    block the command written at tick k − 1 (lock-step); ``drop`` samples lost, ``watchdog`` flagged."""
    log = run.log
    out: list[WindowScore] = []
    for k in range(len(log.timem)):
        if k in drop:
            continue
        flags = (p.FLAG_HELD if k == 0 else 0) | (p.FLAG_WATCHDOG if k in watchdog else 0)
        dac = math.nan if k == 0 else float(log.aout[k - 1])
        shadow.add(k, float(log.timem[k]), float(log.datam1[k]), float(log.datam2[k]), flags, dac)
        if shadow.pending() >= 5:
            out += shadow.process()
    while shadow.pending():
        out += shadow.process()
    return out


@pytest.mark.quick
def test_cusum_run_lengths_are_the_textbooks() -> None:
    """Montgomery, Introduction to Statistical Quality Control, Table 9.3 (Siegmund's approximation): the
    two-sided tabular CUSUM with k = 1/2, h = 5 runs 465 samples in control, 38.0 at a 0.5-sd shift, 10.4 at
    1 sd, 4.01 at 2 sd (within 4 %); with h = 4, 168 in control. Two one-sided CUSUMs signal at the rate of both:
    1/ARL = 1/ARL⁺(δ) + 1/ARL⁺(−δ)."""

    def two_sided(c: Cusum, shift: float) -> float:
        return 1.0 / (1.0 / c.run_length_normal(shift) + 1.0 / c.run_length_normal(-shift))

    c = Cusum(k=0.5, h=5.0)
    for shift, table in ((0.0, 465.0), (0.5, 38.0), (1.0, 10.4)):
        assert two_sided(c, shift) == pytest.approx(table, rel=0.01), shift
    # Far out of control the approximation runs short (the overshoot correction is a small-shift one).
    assert two_sided(c, 2.0) == pytest.approx(4.01, rel=0.04)
    assert two_sided(Cusum(k=0.5, h=4.0), 0.0) == pytest.approx(168.0, rel=0.01)


@pytest.mark.quick
def test_the_false_alarm_probability_by_resampling_is_a_direct_simulations() -> None:
    """A band of independent standard normal scores: the resampled probability of an alarm within 100 windows
    equals a simulation drawing fresh normal scores (an independent computation) within sampling error."""
    rng = np.random.default_rng(5)
    z = rng.standard_normal((20000, 2))
    z = (z - z.mean(axis=0)) / z.std(axis=0, ddof=1)  # standardized, as Band.from_predictions does
    band = Band(mean={"ball": 0.0, "angle": 0.0}, sd={"ball": 1.0, "angle": 1.0}, z=z, source="normal")
    test = Cusum(k=0.5, h=3.0)
    resampled = test.false_alarm_probability(band, 100, chains=20000, seed=1)
    s = np.zeros((20000, 2))
    alarmed = np.zeros(20000, dtype=bool)
    for _ in range(100):
        s = np.maximum(0.0, s + rng.standard_normal((20000, 2)) - test.k)
        alarmed |= np.any(s > test.h, axis=1)
    direct = float(alarmed.mean())
    assert 0.3 < direct < 0.9  # a regime where the two can be told apart
    assert resampled == pytest.approx(direct, abs=4 * math.sqrt(direct * (1 - direct) / 20000) * math.sqrt(2))


def test_the_reference_band_is_the_twins_own_prediction_error() -> None:
    band = _band()
    assert band.windows >= 500
    # The median window errors: the estimate's growth over 0.5 s, well above the sensors' floors
    # (0.049 mm, 1.01 mrad) and far below the verdict's bands (10 mm, 35 mrad).
    assert 0.15e-3 < math.exp(band.mean["ball"]) < 0.6e-3
    assert 1.0e-3 < math.exp(band.mean["angle"]) < 2.0e-3
    # The documented false-alarm rate: under 1 % per hour of windows at the default k = 1, h = 7.
    assert Cusum().false_alarm_probability(band, 3600) < 0.01
    assert Cusum().run_length_normal() > 1e6


@pytest.fixture(scope="module")
def nominal_run() -> RunResult:
    return run_closed_loop(_sf(P), x0_m=X0, theta0_rad=TH0, duration_s=60.0, seed=11, params=P)


def test_the_shadows_windows_are_compares_windows_of_the_same_log(nominal_run: RunResult) -> None:
    shadow = Shadow(P, _band())
    scores = [w for w in _feed(nominal_run, shadow) if not w.skipped]
    wp = windowed_prediction([rig_log(nominal_run.log)], P)
    rms = wp.window_rms(wp.logs[0])
    # The whole log's window j is the stream's window j (window 0 of both has no predecessor).
    assert [w.window for w in scores] == list(range(1, 59))
    for w in scores:
        for c in ("ball", "angle"):
            # Equal within the state fit's convergence (each fit stops at a relative cost change of 1e-10).
            assert w.rms[c] == pytest.approx(float(rms[c][w.window]), rel=1e-3), (w.window, c)
    assert not shadow.alarmed and shadow.scored == 58


def test_a_nominal_rig_raises_no_alarm_and_a_warm_motor_one_within_10_s(nominal_run: RunResult) -> None:
    nominal = Shadow(P, _band())
    _feed(nominal_run, nominal)
    assert not nominal.alarmed and max(nominal.cusum.values()) < Cusum().h
    warm_run = run_closed_loop(_sf(WARM), x0_m=X0, theta0_rad=TH0, duration_s=20.0, seed=11, params=WARM)
    warm = Shadow(P, _band())
    _feed(warm_run, warm)
    assert warm.alarmed and warm.alarms[0].channel == "angle" and warm.alarms[0].time_s <= 10.0


def test_windows_the_model_cannot_be_held_to_are_not_scored(nominal_run: RunResult) -> None:
    shadow = Shadow(P, _band())
    scores = _feed(nominal_run, shadow, drop=range(503, 506), watchdog=range(1200, 1210))
    why = {w.window: w.skipped for w in scores if w.skipped}
    # Window n holds seqs 3 + 50 n … 52 + 50 n; it is scored from window n − 1, whose start guess reads the
    # two samples before it: seqs 1 + 50 (n − 1) … 52 + 50 n must all be clean.
    assert why == {
        10: "samples missing",
        11: "samples missing",
        23: "watchdog",
        24: "watchdog",
        25: "watchdog",  # window 24, its predecessor, starts at seq 1203: its start guess reads seq 1201
    }
    assert shadow.scored == 58 - 5 and not shadow.alarmed


def test_samples_that_are_not_a_log_are_skipped_with_the_reason(nominal_run: RunResult) -> None:
    """A rig whose clock steps back: the windows over it are not scored, and say why; the rest are."""
    shadow = Shadow(P, _band())
    log = nominal_run.log
    for k in range(len(log.timem)):
        t = float(log.timem[k]) - (0.05 if k == 700 else 0.0)
        shadow.add(k, t, float(log.datam1[k]), float(log.datam2[k]), 0, float(log.aout[k - 1]) if k else 2.5)
        if shadow.pending() >= 5:
            shadow.process()
    shadow.process()
    assert shadow.skipped >= 2 and shadow.scored >= 50


@pytest.mark.study  # three minutes of stream scored, ~45 s: run with -m study
def test_a_long_stream_keeps_a_few_windows(nominal_run: RunResult) -> None:
    shadow = Shadow(P, _band())
    log = nominal_run.log
    n = len(log.timem)
    for k in range(3 * n):  # the same minute thrice, as one stream (times shifted)
        i = k % n
        t = float(log.timem[0]) + k * P.daq.period_s
        shadow.add(k, t, float(log.datam1[i]), float(log.datam2[i]), int(k == 0), float(log.aout[i - 1]))
        if shadow.pending() >= 10:
            shadow.process()
            assert len(shadow._time) <= 12 * shadow.W + 2


# --- on the wire ----------------------------------------------------------------------------------------
def _watched(*serve_args: str, duration_s: float) -> Shadow:
    """``ballbeam serve`` (lock-step, ``serve_args`` shaping its rig) driven by ``ballbeam run --rig`` with
    appendix-sf, each its own process (as on a user's machine: three processes, none waiting on another's
    GIL), watched by the shadow at the nominal parameters here."""
    server = subprocess.Popen(
        [*CLI, "serve", "--port", "0", "--x0", str(X0), "--theta0", str(TH0), "--duration", str(duration_s),
         *serve_args],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=ENV,
    )  # fmt: skip
    try:
        assert server.stdout is not None
        first = server.stdout.readline().strip()
        assert first.startswith("serving on udp://127.0.0.1:"), first
        url = first.split()[-1]
        with Observer(url, connect_timeout_s=10.0) as observer:
            shadow = Shadow(observer.parameters(P), _band())
            client = subprocess.Popen(
                [*CLI, "run", "--rig", url, "--controller", "appendix-sf"],
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=ENV,
            )  # fmt: skip
            result = watch(observer, shadow, sessions=1, idle_timeout_s=30.0)
            assert client.wait(120.0) in (0, 1), client.stderr.read() if client.stderr else ""
        assert result.sessions == 1, result.ended
        server.wait(30.0)
    finally:
        server.kill()
    return shadow


@pytest.mark.slow
def test_on_the_wire_a_server_whose_motor_is_warm_alarms_within_10_s() -> None:
    """``motor.resistance_ohm`` +15 % on the server only; the shadow at the nominal parameters."""
    warm = f"motor.resistance_ohm={WARM.motor.resistance_ohm!r}"
    shadow = _watched("--seed", "3", "--set", warm, duration_s=20.0)
    assert shadow.alarmed and shadow.alarms[0].time_s <= 10.0, shadow.summary()


@pytest.mark.study  # 10 minutes of rig time served, ~1 min: run with -m study
def test_on_the_wire_a_nominal_server_for_10_minutes_raises_no_alarm() -> None:
    shadow = _watched("--seed", "4", duration_s=600.0)
    # Every window is accounted for, scored or skipped with its reason; on a loaded machine the observer's
    # datagrams can be dropped (the server does not wait for an observer), which skips a window as "samples
    # missing" (582 of 595 scored beside a busy-loop on each core): 500 windows are still the claim's minutes.
    assert shadow.scored + shadow.skipped >= 595 and shadow.scored >= 500, shadow.summary()
    assert not shadow.alarmed, shadow.summary()
    assert max(shadow.cusum.values()) < Cusum().h


@pytest.mark.quick
def test_cli_shadow_refuses_bad_input_on_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    existing = tmp_path / "mine.jsonl"
    existing.write_text("keep")
    rig = ["shadow", "--rig", "udp://127.0.0.1:9"]
    refused(capsys, ["shadow", "--rig", "serial:///dev/ttyS0"], "UDP")
    refused(capsys, [*rig, "--cusum-h", "0"], "--cusum-h")
    refused(capsys, [*rig, "--log", str(existing)], "exists")
    refused(capsys, [*rig, "--reference", "a.mat", "--reference-controller", "lqr"], "not with")
    refused(capsys, [*rig, "--reference", str(tmp_path / "none.mat")], "none.mat")
    assert existing.read_text() == "keep"


@pytest.mark.quick
def test_the_reference_logs_are_read_checked_and_a_bad_one_named(tmp_path: Path) -> None:
    """``ballbeam shadow --reference``'s logs (twin.app.shadow.load_reference): each read as ``compare`` reads
    it, every tick kept; a file that is not a log is refused naming it, before anything runs."""
    from twin.app.shadow import load_reference
    from twin.log import save_csv

    run = run_closed_loop(registry.make("appendix-sf"), x0_m=0.1, theta0_rad=0.0, duration_s=6.0, seed=2)
    save_csv(run.log, tmp_path / "ref.csv")
    (loaded,) = load_reference([tmp_path / "ref.csv"])
    np.testing.assert_array_equal(loaded.command_v, rig_log(run.log).command_v)
    (tmp_path / "bad.csv").write_text("not a log\n")
    with pytest.raises(ValueError, match="bad.csv"):
        load_reference([tmp_path / "ref.csv", tmp_path / "bad.csv"])


# --- the band's build reported, a session that waits for its controller --------------------------------------
def _stages(calls: list[tuple[int, int, str]]) -> list[str]:
    return list(dict.fromkeys(stage for _, _, stage in calls))


def test_the_bands_build_reports_its_progress_over_the_whole_build(nominal_run: RunResult) -> None:
    """``reference_band`` and ``logs_band`` (a long ``--reference``) report ``(done, total, stage)`` as the
    progress bar takes them: one total for the whole build, never going back, ending at it."""
    from twin.app.shadow import logs_band

    for build in (
        lambda progress: reference_band(P, lambda: _sf(P), duration_s=12.0, progress=progress),
        lambda progress: logs_band(
            [rig_log(nominal_run.log, "a"), rig_log(nominal_run.log, "b")], P, progress=progress
        ),
    ):
        calls: list[tuple[int, int, str]] = []
        band = build(lambda done, total, stage, calls=calls: calls.append((done, total, stage)))
        assert band.windows >= 30 and len(calls) >= 8
        done = [d for d, _, _ in calls]
        assert len({t for _, t, _ in calls}) == 1 and done == sorted(done) and done[-1] == calls[-1][1]
        assert done[len(done) // 2] < done[-1]  # it advances during the build, not only at its end
    assert _stages(calls) == ["predicting the windows of a", "predicting the windows of b"]


def test_a_session_joined_before_its_controller_waits_for_it() -> None:
    """The shadow joins a served session before its controller starts (``ballbeam shadow`` first, as the README's
    recipe has it): the session waits ``start_timeout_s`` for its first sample, not ``idle_timeout_s``; a
    controller that never comes is named in the end's words, with what to do."""
    for controller_after_s in (None, 2.0):
        server = subprocess.Popen(
            [*CLI, "serve", "--port", "0", "--x0", str(X0), "--theta0", str(TH0), "--duration", "4"],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=ENV,
        )  # fmt: skip
        try:
            assert server.stdout is not None
            url = server.stdout.readline().strip().split()[-1]
            with Observer(url, connect_timeout_s=10.0) as observer:
                shadow = Shadow(observer.parameters(P), _band())
                if controller_after_s is None:
                    silent = watch(observer, shadow, idle_timeout_s=0.5, start_timeout_s=1.0)
                    assert (
                        silent.sessions == 0
                        and "no controller started the session within 1 s" in silent.ended
                    )
                    assert "ballbeam run --rig" in silent.ended
                    continue
                time.sleep(controller_after_s)  # far beyond idle_timeout_s: a user switching terminals
                client = subprocess.Popen(
                    [*CLI, "run", "--rig", url, "--controller", "appendix-sf"],
                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV,
                )  # fmt: skip
                result = watch(observer, shadow, idle_timeout_s=0.5, start_timeout_s=120.0)
                client.wait(120.0)
            assert result.sessions == 1 and result.ended == "1 session(s) watched", result.ended
            assert shadow.scored >= 1
            server.wait(30.0)
        finally:
            server.kill()
