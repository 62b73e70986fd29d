"""The verdict from what a rig records (twin.verdict.evaluate_measured) against the true-state verdict on the
twin, and ``ballbeam judge`` on saved logs.

The agreement bounds come from the measurement chain, not from a fit: the steady offset differs by what
eq 6.3.1 reads for a ball at the true steady position on Table 6.3's curve, give or take the ADC's and the
contact noise's share; the lost ball is found from the ball channel at most a few ticks from the plant's.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from cli_checks import refused
from test_inputs import write_mat73

from controllers import registry
from controllers.thesis_numbers import CHAPTER4_STARTS, HARDWARE_STARTS
from twin.app.cli import main
from twin.converters import angle_volts_v, ball_position_m, ball_volts_v
from twin.engine import RunResult
from twin.log import THESIS_FIELDS, RunLog, load_mat, save_csv, save_mat
from twin.parameters import Parameters
from twin.rigs.batch import run_batch
from twin.rigs.sim import run_closed_loop
from twin.sensors import wiper_static_v
from twin.verdict import Verdict, ball_step_bound_m, evaluate_measured

P = Parameters()
SEEDS = (0, 1, 2)
# Hardware controllers (they write the DAC command): the fast tier's sample of the registry.
FAST = ("appendix-sf", "appendix-clp", "lqr")


def _runs(names: tuple[str, ...], starts: list[tuple[float, float]]) -> list[tuple[str, RunResult]]:
    out = []
    for name in names:
        x0 = np.array([s[0] for s in starts for _ in SEEDS])
        th = np.array([s[1] for s in starts for _ in SEEDS])
        seeds = np.array([k for _ in starts for k in SEEDS])
        results = run_batch(
            registry, name, x0_m=x0, theta0_rad=th, seeds=seeds, duration_s=15.0, record=True, nthread=1
        )
        out += [(name, r) for r in results]
    return out


def _converter_offset_m(x_m: float) -> float:
    """What eq 6.3.1 reads, minus the position, for a ball resting at x on the wiper's curve (Table 6.3)."""
    return float(ball_position_m(wiper_static_v(x_m, P.ball_sensor), P.software)) - x_m


def _check_agreement(runs: list[tuple[str, RunResult]]) -> dict[str, float]:
    pairs: list[tuple[str, Verdict, Verdict]] = [
        (name, r.verdict, evaluate_measured(r.log, P)) for name, r in runs
    ]
    # Held and lost: the same answer in every run.
    assert [t.held for _, t, _ in pairs] == [m.held for _, _, m in pairs]
    assert [t.ball_lost for _, t, _ in pairs] == [m.ball_lost for _, _, m in pairs]
    assert [t.hit_stops for _, t, _ in pairs] == [m.hit_stops for _, _, m in pairs]
    kept = [(n, t, m) for n, t, m in pairs if t.steady_x_m is not None and m.steady_x_m is not None]
    assert len(kept) == sum(not t.ball_lost and t.duration_s >= 3.0 for _, t, _ in pairs)
    # Steady x of a held ball: the true one read through eq 6.3.1, within the ADC and noise (0.5 mm). (A ball
    # cycling over centimetres averages the curve's bends instead.)
    residual = [
        m.steady_x_m - t.steady_x_m - _converter_offset_m(t.steady_x_m)  # type: ignore[operator, arg-type]
        for _, t, m in kept
        if t.held
    ]
    assert max(abs(r) for r in residual) < 0.5e-3
    dx = np.array([m.steady_x_m - t.steady_x_m for _, t, m in kept])  # type: ignore[operator]
    band_m = np.linspace(-0.010, 0.010, 201)  # the offset band: where a held ball rests
    largest_offset_m = max(abs(_converter_offset_m(float(x))) for x in band_m)
    assert 1.8e-3 < largest_offset_m < 1.9e-3  # eq 6.3.1 at the centre: 0.0693 · 1.2 mV + 1.8 mm
    assert np.all(np.abs(dx[[t.held for _, t, _ in kept]]) < largest_offset_m + 0.5e-3)
    # Limit cycle: the measured p-p adds the ADC steps and the noise that is left, a few mm at most.
    dpp = np.array([m.limit_cycle_x_pp_m - t.limit_cycle_x_pp_m for _, t, m in kept])  # type: ignore[operator]
    assert np.all(np.abs(dpp) < 3.5e-3)
    # Beam: one encoder count (3.5 mrad) of quantization on each side.
    dth = np.array([m.steady_theta_rad - t.steady_theta_rad for _, t, m in kept])  # type: ignore[operator]
    assert np.all(np.abs(dth) < 3.5e-3)
    # Settling: same answer whether it settled; the 1 mm floor of the band is of the converter's size, so
    # most runs agree within a few ticks and a few settle seconds later in the measured signals.
    assert [t.settling_time_s is None for _, t, _ in pairs] == [
        m.settling_time_s is None for _, _, m in pairs
    ]
    dts = np.array(
        [
            m.settling_time_s - t.settling_time_s
            for _, t, m in pairs
            if t.settling_time_s is not None and m.settling_time_s is not None
        ]
    )
    assert float(np.median(np.abs(dts))) <= 0.1
    assert float(np.mean(np.abs(dts) <= 0.5)) >= 0.75
    assert dts.min() >= -2 * P.daq.period_s  # the noisier signal never settles much earlier
    # The lost ball: at most 0.15 s early (it reads at the track's end before it falls) or 2 ticks late.
    dlost = np.array(
        [m.ball_lost_time_s - t.ball_lost_time_s for _, t, m in pairs if t.ball_lost]  # type: ignore[operator]
    )
    if dlost.size:
        assert dlost.min() >= -0.15 and dlost.max() <= 2 * P.daq.period_s
    # Motor volts: the hardware controllers' DAC commands through the output stage are the motor's volts.
    for name, t, m in pairs:
        if not registry.simulation_only(name):
            assert m.peak_motor_voltage_v == t.peak_motor_voltage_v
    return {
        "runs": len(pairs),
        "held": sum(t.held for _, t, _ in pairs),
        "lost": int(dlost.size),
        "steady_x_max_mm": float(np.abs(dx).max() * 1e3),
        "pp_max_mm": float(np.abs(dpp).max() * 1e3),
        "settling_median_s": float(np.median(np.abs(dts))),
        "settling_within_half_s": float(np.mean(np.abs(dts) <= 0.5)),
    }


def test_measured_and_true_verdicts_agree_for_the_hardware_controllers_from_the_hardware_starts() -> None:
    figures = _check_agreement(_runs(FAST, list(HARDWARE_STARTS.values())))
    assert figures["runs"] == 36 and figures["held"] == 36  # these controllers hold every hardware start


@pytest.mark.study  # every controller from many starts, ~1.5 min: run with -m study
def test_measured_and_true_verdicts_agree_over_the_registry() -> None:
    starts = list(CHAPTER4_STARTS) + list(HARDWARE_STARTS.values())
    figures = _check_agreement(_runs(registry.NAMES, starts))
    assert figures["runs"] == len(registry.NAMES) * 6 * 3
    assert figures["lost"] > 0 and 0 < figures["held"] < figures["runs"]  # both outcomes are exercised


# --- the lost ball from the signals --------------------------------------------------------------------


def _tick_s(i: int | np.ndarray) -> np.ndarray:
    """The time of tick i of a rig log from release: the first command at start.free_run_s, then a period."""
    return np.asarray(P.start.free_run_s + P.daq.period_s * np.asarray(i))


def _rig_log(x_m: np.ndarray, *, unwritten_row: bool = True) -> RunLog:
    """A rig-style log (thesis fields only) of a ball at x_m and a level beam, the command at zero volts."""
    n = x_m.size
    t = _tick_s(np.arange(n))
    ball = np.asarray(ball_volts_v(x_m, P.software))
    angle = np.full(n, float(angle_volts_v(0.0, P.software)))
    aout = np.full(n, 2.5)
    if unwritten_row:
        t, ball, angle, aout = (np.concatenate([[0.0], a]) for a in (t, ball, angle, aout))
    nan = np.full(t.size, np.nan)
    return RunLog(t, ball, angle, aout, nan, nan, nan, nan, nan, nan)


def test_a_ball_resting_off_centre_is_held_and_a_dropout_glitch_does_not_lose_it() -> None:
    x = np.full(500, 0.004)
    x[300] = ball_position_m(0.0, P.software)  # one tick of the open wiper
    v = evaluate_measured(_rig_log(x), P)
    assert v.held and not v.ball_lost
    assert v.steady_x_m == pytest.approx(0.004, abs=2e-4)
    assert v.limit_cycle_x_pp_m is not None and v.limit_cycle_x_pp_m < 2e-4  # the glitch is not a cycle
    assert v.duration_s == pytest.approx(_tick_s(499))


def test_the_ball_is_lost_at_the_track_end_at_a_stuck_reading_and_at_the_adc_rail() -> None:
    x = np.concatenate([np.linspace(0.1, 0.315, 50), np.full(200, 0.315)])
    v = evaluate_measured(_rig_log(x), P)
    first = int(np.argmax(x >= P.track.half_length_m - 0.010))
    assert v.ball_lost and v.ball_lost_time_s == pytest.approx(_tick_s(first))
    assert "track's end" in v.reason and not v.held
    # Rolling off between two ticks: from 0.29 m to the open wiper's reading, and it stays there.
    step = ball_step_bound_m(P)
    assert 0.05 < step < 0.07  # √(2·g·sin 43.4°·0.646 m)·20 ms ≈ 60 mm
    x = np.concatenate([np.full(100, 0.29), np.full(300, float(ball_position_m(0.0, P.software)))])
    v = evaluate_measured(_rig_log(x), P)
    assert v.ball_lost and v.ball_lost_time_s == pytest.approx(_tick_s(100)) and "jumped" in v.reason
    # The channel at the ADC's top code.
    log = _rig_log(np.full(400, 0.01))
    log.datam1[200] = 5.0 - 10.0 / 4096
    v = evaluate_measured(log, P)
    assert v.ball_lost and v.ball_lost_time_s == pytest.approx(_tick_s(199)) and "rail" in v.reason


# --- ballbeam judge ----------------------------------------------------------------------------------------


def _judge_json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, dict[str, object]]:
    rc = main(["judge", *argv, "--json"])
    out = capsys.readouterr().out
    return rc, json.loads(out)


def test_judge_a_saved_twin_log_and_the_same_log_without_its_true_state(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    x0, th0 = HARDWARE_STARTS["Fig 6.16 (state feedback)"]
    result = run_closed_loop(registry.make("appendix-sf"), x0_m=x0, theta0_rad=th0, duration_s=15.0, seed=1)
    log = result.log
    expected = evaluate_measured(log, P).to_json()
    assert expected["held"] is True and result.verdict.held
    save_mat(log, tmp_path / "twin.mat")
    save_csv(log, tmp_path / "twin.csv")
    # What a rig records: the thesis fields only, with the rig's unwritten row 1 and its times from Start.
    bare = RunLog(
        *(np.concatenate([[0.0], getattr(log, f)[1:]]) for f in ("timem", "datam1", "datam2", "aout")),
        *(np.full(log.k, np.nan) for _ in range(6)),
    )
    save_mat(bare, tmp_path / "rig.mat")
    assert load_mat(tmp_path / "rig.mat").true_x_m.size == 0
    for name in ("twin.mat", "twin.csv"):
        rc, out = _judge_json(capsys, [str(tmp_path / name)])
        assert rc == 0 and out["source"] == "measured"
        assert {k: out[k] for k in expected} == expected
    rc, out = _judge_json(capsys, [str(tmp_path / "rig.mat")])
    assert rc == 0 and out["held"] is True
    assert out["steady_x_m"] == expected["steady_x_m"]  # the first tick's held block only sets x0
    # A rig's clock starts anywhere: its first tick is taken as the first command after release.
    late = RunLog(
        bare.timem + np.where(bare.timem > 0, 100.0, 0.0), *(getattr(bare, f) for f in THESIS_FIELDS[1:])
    )
    later = evaluate_measured(late, P).to_json()
    assert later["duration_s"] == expected["duration_s"] and later["held"] is True
    for key in ("steady_x_m", "limit_cycle_x_pp_m", "settling_time_s"):
        assert later[key] == pytest.approx(expected[key], abs=1e-3), key
    # The same rig log saved by MATLAB as v7.3 (HDF5) gives the same verdict.
    raw = {k: v for k, v in scipy.io.loadmat(tmp_path / "rig.mat").items() if not k.startswith("__")}
    write_mat73(tmp_path / "rig73.mat", raw)
    rc, out73 = _judge_json(capsys, [str(tmp_path / "rig73.mat")])
    assert rc == 0 and {k: v for k, v in out73.items() if k != "log"} == {
        k: v for k, v in out.items() if k != "log"
    }
    # Judged about a setpoint 5 cm away, the same log is not held.
    rc, out = _judge_json(capsys, [str(tmp_path / "rig.mat"), "--setpoint", "0.05"])
    assert rc == 1 and "offset" in str(out["reason"])
    # --set reaches the software calibration: a 2 cm offset in eq 6.3.1 moves the steady x by 2 cm.
    rc, out = _judge_json(capsys, [str(tmp_path / "rig.mat"), "--set", "software.ball_offset_m=0.0218"])
    assert out["steady_x_m"] == pytest.approx(float(expected["steady_x_m"]) + 0.02, abs=2e-6)  # type: ignore[arg-type]
    assert rc == 1


@pytest.mark.quick
def test_judge_a_lost_ball(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = run_closed_loop(registry.make("appendix-sf"), x0_m=0.3, theta0_rad=-0.7, duration_s=5.0, seed=0)
    assert result.verdict.ball_lost
    save_csv(result.log, tmp_path / "lost.csv")
    rc, out = _judge_json(capsys, [str(tmp_path / "lost.csv")])
    assert rc == 1 and out["ball_lost"] is True and out["held"] is False
    assert abs(float(out["ball_lost_time_s"]) - float(result.verdict.ball_lost_time_s or 0)) <= 0.02  # type: ignore[arg-type]
    rc = main(["judge", str(tmp_path / "lost.csv")])
    assert rc == 1 and "ball lost at" in capsys.readouterr().out


@pytest.mark.quick
def test_judge_refuses_malformed_logs_on_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    junk = tmp_path / "junk.mat"
    junk.write_bytes(b"not a mat file at all")
    refused(capsys, ["judge", str(junk)], "junk.mat")
    short = tmp_path / "short.csv"
    short.write_text("timem,datam1\n0.02,1.0\n")
    refused(capsys, ["judge", str(short)], "short.csv", "datam2")
    nan = tmp_path / "nan.csv"
    nan.write_text("timem,datam1,datam2,aout\n0.02,1.0,0.0,2.5\n0.04,nan,0.0,2.5\n")
    refused(capsys, ["judge", str(nan)], "nan.csv", "datam1")
    refused(capsys, ["judge", str(tmp_path / "missing.mat")], "missing.mat")
    refused(capsys, ["judge", str(tmp_path / "log.txt")], "log.txt", ".mat")
    refused(capsys, ["judge", str(short), "--set", "software.ball_gain_m_per_v=-1"], "ball_gain_m_per_v")


# --- judge checks a log as calibrate, compare and shadow do (calib.logs.load_judged_log) -------------------


def _bad_log(case: str) -> RunLog:
    """A held ball's rig log (10 s at daq.period_s) spoiled in one way."""
    log = _rig_log(np.full(500, 0.004))
    t, ball, angle, aout = log.timem, log.datam1, log.datam2, log.aout
    if case == "period":  # recorded every 10 ms, judged at the parameters' 20 ms
        t = np.concatenate([[0.0], 0.01 * np.arange(1, t.size)])
    elif case == "ms":  # timem in milliseconds: 500 ticks read as 10 000 s
        t = t * 1e3
    elif case == "millivolts":  # the ADC channels in mV: a ball at 4 mm reads hundreds of "volts"
        ball, angle = ball * 1e3, angle * 1e3
    elif case == "counts":  # the angle channel as the card's raw 12-bit code
        angle = np.concatenate([[0.0], np.full(t.size - 1, 2048.0)])
    elif case == "motor volts":  # aout holding the motor's volts (aout − 2.5)·9.6, negative for a push left
        aout = np.concatenate([[0.0], np.full(t.size - 1, -3.0)])
    elif case == "gap":  # ten blocks missing
        keep = np.r_[0:200, 210 : t.size]
        t, ball, angle, aout = t[keep], ball[keep], angle[keep], aout[keep]
    elif case == "one tick":  # the start row and a single tick
        t, ball, angle, aout = t[:2], ball[:2], angle[:2], aout[:2]
    return RunLog(t, ball, angle, aout, *(np.full(t.size, np.nan) for _ in range(6)))


@pytest.mark.quick
@pytest.mark.parametrize(
    "case, needles",
    [
        ("period", ("'timem'", "ticks every 10 ms", "daq.period_s is 20 ms")),
        ("ms", ("'timem'", "ticks every 20000 ms")),
        ("millivolts", ("'datam1'", "index 2", "V is outside the ADC's -5…5 V")),
        ("counts", ("'datam2'", "2048.0 V is outside the ADC's")),
        ("motor volts", ("'aout'", "-3.0 V is outside the DAC's 0.0…5.0 V")),
        ("gap", ("'timem'", "index 201", "0.22 s after the previous tick", "a gap in the ticks")),
        ("one tick", ("'timem'", "the log ends at index 2", "at least 2 ticks")),
    ],
)
def test_judge_refuses_the_logs_the_calibration_refuses(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str, needles: tuple[str, ...]
) -> None:
    good = _rig_log(np.full(500, 0.004))
    save_csv(good, tmp_path / "good.csv")
    rc, out = _judge_json(capsys, [str(tmp_path / "good.csv")])
    assert rc == 0 and out["held"] is True  # the log before it was spoiled
    path = tmp_path / f"{case.replace(' ', '_')}.csv"
    save_csv(_bad_log(case), path)
    line = refused(capsys, ["judge", str(path)], str(path), *needles)
    assert "verdict" not in line and "held" not in line


@pytest.mark.quick
def test_judge_refuses_a_setpoint_off_the_track(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    save_csv(_rig_log(np.full(500, 0.004)), tmp_path / "good.csv")
    refused(
        capsys,
        ["judge", str(tmp_path / "good.csv"), "--setpoint", "5"],
        "--setpoint = 5.0 m is off the track",
        "|x| ≤ 0.323 m",
    )
    rc, _ = _judge_json(
        capsys, [str(tmp_path / "good.csv"), "--setpoint", "0.323"]
    )  # the track's end: judged
    assert rc == 1
