"""calib.logs: rig logs (.mat as the thesis software saves them, .csv) read for identification, and refused
with the file, the field and the first bad index when identification could not use them."""

import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from calib.logs import (
    ADC_STEP_V,
    DAC_STEP_V,
    MIN_DURATION_S,
    RigLog,
    load_judged_log,
    load_rig_log,
)
from controllers import registry
from twin.daq import adc_lsb_v, dac_lsb_v
from twin.log import TRUTH_FIELDS, LogError, save_csv, save_mat
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop

PERIOD_S = 0.02
REQUIRED = ("timem", "datam1", "datam2", "aout")


def rig_rows(ticks: int = 400, start_s: float = 12.34) -> dict[str, np.ndarray]:
    """k = ticks + 1 rows as the rig writes them: row 1 the unwritten zero row, then one row per 20 ms tick
    (times from wherever the software's clock was), the readings and commands on the converters' steps."""
    t = start_s + PERIOD_S * np.arange(ticks)
    ball = np.round(1.5 * np.sin(2 * np.pi * 0.4 * t) / ADC_STEP_V) * ADC_STEP_V
    angle = np.round(0.3 * np.cos(2 * np.pi * 0.4 * t) / ADC_STEP_V) * ADC_STEP_V
    command = 2.5 + np.round(0.4 * np.sin(2 * np.pi * 0.7 * t) / DAC_STEP_V) * DAC_STEP_V
    return {name: np.r_[0.0, v] for name, v in zip(REQUIRED, (t, ball, angle, command), strict=True)}


def write_rig_mat(path: Path, rows: dict[str, np.ndarray], **extra: object) -> Path:
    """The rig's data_file.mat with only the four required variables: preallocated to 100001 values, k the
    number used, ``sampnumber`` the empty matrix."""
    k = len(rows["timem"])
    data: dict[str, object] = {}
    for name, values in rows.items():
        preallocated = np.zeros(100001)
        preallocated[: len(values)] = values
        data[name] = preallocated
    data["sampnumber"] = np.zeros((0, 0))
    data["k"] = float(k)
    data.update(extra)
    scipy.io.savemat(path, data, format="5", oned_as="row")
    return path


def write_csv(path: Path, rows: dict[str, np.ndarray]) -> Path:
    """A CSV by hand: the four required columns, values at repr precision."""
    lines = [",".join(rows)]
    for i in range(len(rows["timem"])):
        lines.append(",".join(repr(float(rows[name][i])) for name in rows))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def refused(path: Path, *parts: str) -> str:
    """Load and expect a refusal whose message names the file and every part (field, index)."""
    with pytest.raises(LogError) as info:
        load_rig_log(path)
    message = str(info.value)
    assert message.startswith(f"{path}: "), message
    for part in parts:
        assert part in message, (part, message)
    assert "Traceback" not in message
    return message


# --- Good logs ---


@pytest.mark.quick
@pytest.mark.parametrize("fmt", ["mat", "csv"])
def test_a_rig_log_round_trips(tmp_path: Path, fmt: str) -> None:
    rows = rig_rows()
    path = (
        write_rig_mat(tmp_path / "data_file.mat", rows)
        if fmt == "mat"
        else write_csv(tmp_path / "r.csv", rows)
    )
    rig = load_rig_log(path)
    assert rig.path == path and rig.ticks == 400
    np.testing.assert_array_equal(rig.time_s, rows["timem"][1:])  # row 1, the start sample, is dropped
    np.testing.assert_array_equal(rig.ball_v, rows["datam1"][1:])
    np.testing.assert_array_equal(rig.angle_v, rows["datam2"][1:])
    np.testing.assert_array_equal(rig.command_v, rows["aout"][1:])
    assert rig.period_s == pytest.approx(PERIOD_S, abs=1e-12)
    assert rig.duration_s == pytest.approx(399 * PERIOD_S)
    assert not rig.time_s.flags.writeable
    with pytest.raises(AttributeError):
        rig.period_s = 1.0  # type: ignore[misc]


@pytest.mark.quick
def test_the_rig_file_as_saved_with_every_variable(tmp_path: Path) -> None:
    """The full ``save 'data_file' …`` list, uhesap never written (an empty matrix): the same RigLog."""
    rows = rig_rows()
    k = len(rows["timem"])
    extra = {name: np.r_[np.full(k, 0.1), np.zeros(100001 - k)] for name in ("x1", "x2", "x3", "x4", "u")}
    path = write_rig_mat(tmp_path / "data_file.mat", rows, uhesap=np.zeros((0, 0)), **extra)
    only_four = load_rig_log(write_rig_mat(tmp_path / "four.mat", rows))
    rig = load_rig_log(path)
    for name in ("time_s", "ball_v", "angle_v", "command_v", "period_s"):
        np.testing.assert_array_equal(getattr(rig, name), getattr(only_four, name), err_msg=name)


def test_a_twin_log_loads_without_its_truth(tmp_path: Path, twin_log_path: Path) -> None:
    rig = load_rig_log(twin_log_path)
    assert {f.name for f in fields(RigLog)} == {
        "path",
        "time_s",
        "ball_v",
        "angle_v",
        "command_v",
        "period_s",
        "whole",  # a whole log or a span of a stream (calib.shadow): a flag, no signal
        "board",  # the board's output range a log is held to (a rig of other parts): no signal
    }
    for name in TRUTH_FIELDS:
        assert not hasattr(rig, name), name
    raw = scipy.io.loadmat(twin_log_path)
    assert "true_x_m" in raw  # the file has the truth; the RigLog does not
    np.testing.assert_array_equal(rig.time_s, raw["timem"][0, 1:])
    np.testing.assert_array_equal(rig.command_v, raw["aout"][0, 1:])
    assert rig.period_s == pytest.approx(PERIOD_S, abs=1e-9) and rig.duration_s >= MIN_DURATION_S


@pytest.fixture(scope="module")
def twin_log_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = run_closed_loop(registry.make("appendix-sf"), x0_m=0.1, theta0_rad=0.1, duration_s=6.0)
    path = tmp_path_factory.mktemp("twin") / "data_file.mat"
    save_mat(run.log, path)
    save_csv(run.log, path.with_suffix(".csv"))
    return path


@pytest.mark.quick
def test_a_twin_csv_gives_the_same_rig_log(twin_log_path: Path) -> None:
    a, b = load_rig_log(twin_log_path), load_rig_log(twin_log_path.with_suffix(".csv"))
    for name in ("time_s", "ball_v", "angle_v", "command_v", "period_s"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("fmt", ["mat", "csv"])
def test_loading_never_modifies_the_file(tmp_path: Path, fmt: str) -> None:
    rows = rig_rows()
    path = (
        write_rig_mat(tmp_path / "data_file.mat", rows)
        if fmt == "mat"
        else write_csv(tmp_path / "r.csv", rows)
    )
    before = (path.read_bytes(), path.stat().st_mtime_ns)
    load_rig_log(path)
    rows["aout"][50] = 7.0  # a refused file is not touched either
    bad = write_rig_mat(tmp_path / "bad.mat", rows) if fmt == "mat" else write_csv(tmp_path / "bad.csv", rows)
    bad_before = (bad.read_bytes(), bad.stat().st_mtime_ns)
    with pytest.raises(LogError):
        load_rig_log(bad)
    assert (path.read_bytes(), path.stat().st_mtime_ns) == before
    assert (bad.read_bytes(), bad.stat().st_mtime_ns) == bad_before


@pytest.mark.quick
def test_the_thresholds_are_the_io_cards_steps() -> None:
    daq = Parameters().daq
    assert DAC_STEP_V == dac_lsb_v(daq) and ADC_STEP_V == adc_lsb_v(daq)


# --- Bad logs: one case each, the message names the file, the field and the index ---


def write(tmp_path: Path, fmt: str, rows: dict[str, np.ndarray]) -> Path:
    return (
        write_rig_mat(tmp_path / "bad.mat", rows) if fmt == "mat" else write_csv(tmp_path / "bad.csv", rows)
    )


@pytest.mark.quick
@pytest.mark.parametrize("fmt", ["mat", "csv"])
@pytest.mark.parametrize(("name", "value"), [("datam1", math.nan), ("aout", math.inf), ("timem", -math.inf)])
def test_not_finite(tmp_path: Path, fmt: str, name: str, value: float) -> None:
    rows = rig_rows()
    rows[name][39] = value  # k = 40
    refused(write(tmp_path, fmt, rows), f"'{name}'", "index 40", "finite")


@pytest.mark.parametrize("fmt", ["mat", "csv"])
def test_time_not_strictly_increasing(tmp_path: Path, fmt: str) -> None:
    rows = rig_rows()
    rows["timem"][99] = rows["timem"][98]  # k = 100 repeats k = 99
    refused(write(tmp_path, fmt, rows), "'timem'", "index 100", "increase strictly")


def test_mismatched_lengths_mat(tmp_path: Path) -> None:
    rows = rig_rows()
    data: dict[str, object] = dict(rows)
    data["datam2"] = rows["datam2"][:300]
    data["k"] = 401.0  # no preallocation here: the arrays are as long as the ticks
    scipy.io.savemat(tmp_path / "bad.mat", data, oned_as="row")
    refused(tmp_path / "bad.mat", "'datam2'", "300 values", "k = 401", "index 301")
    del data["k"]
    scipy.io.savemat(tmp_path / "nok.mat", data, oned_as="row")
    refused(tmp_path / "nok.mat", "'datam2'", "300 values", "'timem' has 401", "index 301")


def test_mismatched_lengths_csv(tmp_path: Path) -> None:
    path = write_csv(tmp_path / "bad.csv", rig_rows())
    lines = path.read_text().splitlines()
    lines[-1] = ",".join(lines[-1].split(",")[:3] + [""])  # the last aout (k = 401) is missing
    path.write_text("\n".join(lines) + "\n")
    refused(path, "'aout'", "400 values", "index 401")


def test_mismatched_lengths_rig_log() -> None:
    t = np.arange(300) * PERIOD_S
    with pytest.raises(LogError, match=r"built.mat: 'datam1' \(ball_v\), index 102: has 100 values"):
        RigLog(Path("built.mat"), t, t[:100], t, t)


@pytest.mark.parametrize("fmt", ["mat", "csv"])
def test_irregular_tick_spacing(tmp_path: Path, fmt: str) -> None:
    rows = rig_rows()
    rows["timem"][150:] += PERIOD_S  # a block missed before k = 151
    refused(write(tmp_path, fmt, rows), "'timem' (time_s)", "index 151", "1.5 × the median period")


@pytest.mark.quick
@pytest.mark.parametrize("fmt", ["mat", "csv"])
def test_too_short(tmp_path: Path, fmt: str) -> None:
    rows = {name: v[:201] for name, v in rig_rows().items()}  # 200 ticks: 3.98 s
    refused(write(tmp_path, fmt, rows), "'timem' (time_s)", "index 201", f"at least {MIN_DURATION_S} s")


def test_only_the_start_sample(tmp_path: Path) -> None:
    rows = {name: v[:1] for name, v in rig_rows().items()}
    refused(write_rig_mat(tmp_path / "one.mat", rows), "'timem' (time_s)", "ends at index 1", "0 tick(s)")
    rows = {name: v[:2] for name, v in rig_rows().items()}
    refused(write_rig_mat(tmp_path / "two.mat", rows), "'timem' (time_s)", "ends at index 2", "1 tick(s)")


@pytest.mark.parametrize("fmt", ["mat", "csv"])
def test_command_never_moves(tmp_path: Path, fmt: str) -> None:
    rows = rig_rows()
    rows["aout"][1:] = 2.5 + DAC_STEP_V * (np.arange(400) % 3)  # a dither of 2 DAC steps
    refused(write(tmp_path, fmt, rows), "'aout' (command_v)", "indices 2…401", "no excitation")


@pytest.mark.parametrize("fmt", ["mat", "csv"])
def test_ball_never_moves(tmp_path: Path, fmt: str) -> None:
    rows = rig_rows()
    rows["datam1"][1:] = 0.5 + ADC_STEP_V * (np.arange(400) % 10)  # 9 ADC steps of noise
    refused(write(tmp_path, fmt, rows), "'datam1' (ball_v)", "indices 2…401", "10 ADC steps")


@pytest.mark.parametrize("fmt", ["mat", "csv"])
@pytest.mark.parametrize("value", [5.2, -0.1])
def test_command_outside_the_dac_range(tmp_path: Path, fmt: str, value: float) -> None:
    rows = rig_rows()
    rows["aout"][76] = value  # k = 77
    refused(write(tmp_path, fmt, rows), "'aout' (command_v)", "index 77", "outside the DAC's 0.0…5.0 V")


@pytest.mark.parametrize("fmt", ["mat", "csv"])
@pytest.mark.parametrize(
    ("name", "field", "value"), [("datam1", "ball_v", 12.7), ("datam2", "angle_v", -27.5)]
)
def test_a_channel_outside_the_adc_range_is_refused(
    tmp_path: Path, fmt: str, name: str, field: str, value: float
) -> None:
    """A channel in other units (a ball channel in mm, an angle in degrees) leaves the ADC's ±5 V."""
    rows = rig_rows()
    rows[name][40] = value  # k = 41
    refused(write(tmp_path, fmt, rows), f"'{name}' ({field})", "index 41", "outside the ADC's -5…5 V")


@pytest.mark.quick
@pytest.mark.parametrize(("name", "shown"), [("data_file.txt", "suffix '.txt'"), ("data_file", "no suffix")])
def test_unknown_suffix(tmp_path: Path, name: str, shown: str) -> None:
    path = write_rig_mat(tmp_path / "x.mat", rig_rows()).rename(tmp_path / name)
    refused(path, shown, ".mat", ".csv")


@pytest.mark.quick
def test_a_rig_of_other_parts_log_is_held_to_its_boards_range(tmp_path: Path) -> None:
    """An Arduino rig's log carries servo pulses (µs): held to the board's pulse range, not the DAC's volts,
    and a pulse outside it refused naming the tick, the value and the range's parameters."""
    from twin.parts.description import preset

    obb = preset("open-ball-and-beam")
    rows = rig_rows()
    rows["aout"] = np.full(len(rows["timem"]), 1500.0)
    path = write_rig_mat(tmp_path / "obb.mat", rows)
    assert load_judged_log(path, obb).aout[2] == 1500.0
    with pytest.raises(LogError, match="'aout' .*index 2: 1500.0 V is outside the DAC"):
        load_judged_log(path, Parameters())  # the thesis's card: volts
    rows["aout"][5] = 3000.0
    with pytest.raises(
        LogError, match=r"index 6: 3000.0 µs is outside the servo pulse.s range arduino.servo_min_us"
    ):
        load_judged_log(write_rig_mat(tmp_path / "far.mat", rows), obb)
