"""Logs in the thesis software's format (appendix A ``save 'data_file' …``), MAT and CSV."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from twin.log import THESIS_FIELDS, TRUTH_FIELDS, LogError, RunLog, load_csv, load_mat, save_csv, save_mat
from twin.rigs import measurements


def make_log(ticks: int = 50, physics_steps: int = 1000, seed: int = 0) -> RunLog:
    rng = np.random.default_rng(seed)
    thesis = {name: rng.normal(size=ticks) * 10.0 ** rng.uniform(-8, 3, ticks) for name in THESIS_FIELDS}
    thesis["timem"] = 0.02 * np.arange(ticks) + rng.uniform(0, 1e-12, ticks)
    thesis["uhesap"][3] = math.nan  # a NaN must survive too
    truth = {name: rng.normal(size=physics_steps) for name in TRUTH_FIELDS}
    truth["ball_lost"] = rng.uniform(size=physics_steps) < 0.1
    return RunLog(**thesis, **truth)


def assert_identical(a: RunLog, b: RunLog) -> None:
    """Dtype, shape and every bit (NaN included) of every field, and k."""
    assert set(THESIS_FIELDS + TRUTH_FIELDS) == {f.name for f in dataclasses.fields(RunLog)}
    assert measurements.log_mismatches(a, b) == []


@pytest.mark.quick
def test_log_comparison_sees_one_bit_a_nan_and_a_length():
    log = make_log()
    flipped = make_log()
    flipped.x3[7] = np.nextafter(flipped.x3[7], np.inf)
    assert measurements.log_mismatches(log, flipped) == ["x3"]
    other_nan = make_log()
    other_nan.uhesap[3] = -math.nan  # another NaN's bits: np.array_equal would not see it either way
    assert measurements.log_mismatches(log, other_nan) == ["uhesap"]
    short = RunLog(
        **{name: getattr(log, name)[:-1] for name in THESIS_FIELDS},
        **{name: getattr(log, name) for name in TRUTH_FIELDS},
    )
    assert measurements.log_mismatches(log, short) == [*THESIS_FIELDS, "k"]


@pytest.mark.quick
def test_mat_round_trip_is_bit_identical(tmp_path):
    assert measurements.mat_round_trip_mismatches(make_log(), tmp_path) == []
    assert (tmp_path / "data_file.mat").is_file()


@pytest.mark.quick
def test_mat_has_the_thesis_variables_as_matlab_stores_them(tmp_path):
    log = make_log(ticks=7)
    save_mat(log, tmp_path / "data_file.mat")
    raw = scipy.io.loadmat(tmp_path / "data_file.mat")
    # save 'data_file' timem datam1 datam2 aout sampnumber x1 x2 x3 x4 u uhesap k (appendix A)
    for name in ("timem", "datam1", "datam2", "aout", "x1", "x2", "x3", "x4", "u", "uhesap"):
        assert raw[name].shape == (1, 7) and raw[name].dtype == np.float64, name
        assert np.array_equal(raw[name][0], getattr(log, name), equal_nan=True)
    assert raw["k"].shape == (1, 1) and raw["k"][0, 0] == 7.0
    assert raw["sampnumber"].size == 0
    assert raw["true_x_m"].shape == (1, 1000)


def test_rig_file_with_preallocated_arrays_and_empty_uhesap(tmp_path):
    # As the rig saves it: arrays of sampsize + 1 = 100001 zeros filled up to k, index 1 of timem, datam1,
    # datam2 and aout never written (the zero row), uhesap never written.
    k = 4
    raw = {name: np.zeros(100001) for name in THESIS_FIELDS}
    raw["timem"][1:k] = [7.02, 7.04, 7.06]
    raw["x1"][:k] = [0.1, 0.11, 0.12, 0.13]
    raw["uhesap"] = np.zeros((0, 0))
    raw["sampnumber"] = np.zeros((0, 0))
    raw["k"] = float(k)
    scipy.io.savemat(tmp_path / "rig.mat", raw, oned_as="row")
    log = load_mat(tmp_path / "rig.mat")
    assert log.k == 4
    np.testing.assert_array_equal(log.x1, [0.1, 0.11, 0.12, 0.13])
    assert np.all(np.isnan(log.uhesap))
    assert log.true_x_m.size == 0 and log.ball_lost.size == 0
    np.testing.assert_array_equal(log.timem, [0.0, 7.02, 7.04, 7.06])  # row 1 is kept


@pytest.mark.quick
def test_csv_round_trip_is_bit_identical(tmp_path):
    log = make_log()
    save_csv(log, tmp_path / "run.csv")
    header = (tmp_path / "run.csv").read_text().splitlines()[0].split(",")
    assert header == list(THESIS_FIELDS + TRUTH_FIELDS)
    assert_identical(load_csv(tmp_path / "run.csv"), log)
    rig_like = make_log(physics_steps=0)  # no true state: empty columns
    save_csv(rig_like, tmp_path / "rig.csv")
    assert_identical(load_csv(tmp_path / "rig.csv"), rig_like)


@pytest.mark.parametrize("save", [save_mat, save_csv])
def test_overwrite_refused_unless_asked(tmp_path, save):
    path = tmp_path / "log.out"
    path.write_text("precious")
    with pytest.raises(FileExistsError, match="log.out"):
        save(make_log(), path)
    assert path.read_text() == "precious"
    save(make_log(), path, overwrite=True)
    assert_identical((load_mat if save is save_mat else load_csv)(path), make_log())


@pytest.mark.quick
def test_malformed_mat_files(tmp_path):
    text = tmp_path / "notes.mat"
    text.write_text("this is not a mat file\n")
    with pytest.raises(LogError, match="notes.mat: not a MATLAB .mat file"):
        load_mat(text)
    raw = {name: np.arange(5.0) for name in THESIS_FIELDS}
    raw["k"] = 5.0
    del raw["datam2"]
    scipy.io.savemat(tmp_path / "missing.mat", raw)
    with pytest.raises(LogError, match="missing.mat: variable 'datam2' is missing"):
        load_mat(tmp_path / "missing.mat")
    raw["datam2"] = np.arange(5.0)
    raw["x3"] = np.arange(3.0)
    scipy.io.savemat(tmp_path / "short.mat", raw)
    with pytest.raises(LogError, match="short.mat: variable 'x3' has 3 values but k = 5"):
        load_mat(tmp_path / "short.mat")
    raw["x3"] = np.arange(5.0)
    raw["k"] = 2.5
    scipy.io.savemat(tmp_path / "badk.mat", raw)
    with pytest.raises(LogError, match="badk.mat: variable 'k'"):
        load_mat(tmp_path / "badk.mat")
    raw["k"] = 5.0
    raw["u"] = "text"
    scipy.io.savemat(tmp_path / "text.mat", raw)
    with pytest.raises(LogError, match="text.mat: variable 'u' is not a real numeric array"):
        load_mat(tmp_path / "text.mat")
    with pytest.raises(LogError, match="nowhere.mat: no such file"):
        load_mat(tmp_path / "nowhere.mat")


@pytest.mark.quick
def test_malformed_csv_files(tmp_path):
    save_csv(make_log(ticks=5, physics_steps=3), tmp_path / "good.csv")
    lines = (tmp_path / "good.csv").read_text().splitlines()

    def write(name: str, new_lines: list[str]) -> str:
        (tmp_path / name).write_text("\n".join(new_lines) + "\n")
        return str(tmp_path / name)

    header = lines[0].split(",")
    col = header.index("datam2")
    no_datam2 = [",".join(c for i, c in enumerate(line.split(",")) if i != col) for line in lines]
    with pytest.raises(LogError, match="no_datam2.csv: column 'datam2' is missing"):
        load_csv(write("no_datam2.csv", no_datam2))
    col = header.index("x2")
    bad = [lines[0], lines[1]] + [lines[2].replace(lines[2].split(",")[col], "abc", 1)] + lines[3:]
    with pytest.raises(LogError, match="bad.csv: column 'x2', line 3: 'abc' is not a number"):
        load_csv(write("bad.csv", bad))
    with pytest.raises(LogError, match="ragged.csv: line 4 has"):
        load_csv(write("ragged.csv", lines[:3] + [lines[3] + ",1"] + lines[4:]))
    short = lines[:-1] + [
        ",".join("" if i == header.index("u") else c for i, c in enumerate(lines[-1].split(",")))
    ]
    with pytest.raises(LogError, match="short.csv: field 'u' has 4 values but 'timem' has 5"):
        load_csv(write("short.csv", short))
    (tmp_path / "binary.csv").write_bytes(bytes(range(256)))
    with pytest.raises(LogError, match="binary.csv: not a CSV text file"):
        load_csv(tmp_path / "binary.csv")


@pytest.mark.quick
def test_runlog_refuses_inconsistent_arrays():
    arrays = {name: np.zeros(3) for name in THESIS_FIELDS}
    arrays["aout"] = np.zeros(4)
    with pytest.raises(LogError, match="field 'aout' has 4 values but 'timem' has 3"):
        RunLog(**arrays)
    arrays["aout"] = np.zeros((3, 1))
    with pytest.raises(LogError, match=r"field 'aout' has shape \(3, 1\)"):
        RunLog(**arrays)


# --- What a log must hold: required and optional fields, row 1, finite values, time order, booleans ---


def required(ticks: int = 6) -> dict[str, np.ndarray]:  # ticks ≤ 8
    """The four variables the rig's I/O card writes, for a twin-like log (row 1 a real start block)."""
    return {
        "timem": np.array([-0.01, 0.01, 0.03, 0.05, 0.07, 0.09, 0.11, 0.13][:ticks]),
        "datam1": np.linspace(1.0, 0.5, ticks),
        "datam2": np.linspace(0.3, 0.2, ticks),
        "aout": np.full(ticks, 2.5),
    }


def write_csv(path, columns: dict[str, np.ndarray | list]) -> str:
    """A CSV by hand: one column per entry, every value at repr precision."""
    names = list(columns)
    rows = [",".join(names)]
    for i in range(len(columns[names[0]])):
        rows.append(",".join(repr(float(columns[name][i])) for name in names))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return str(path)


def write_mat(path, variables: dict) -> str:
    scipy.io.savemat(path, variables, oned_as="row")
    return str(path)


def test_mat_with_only_the_required_variables_and_no_k(tmp_path):
    log = load_mat(write_mat(tmp_path / "four.mat", required()))
    assert log.k == 6
    np.testing.assert_array_equal(log.timem, required()["timem"])
    for name in ("x1", "x2", "x3", "x4", "u", "uhesap"):
        assert getattr(log, name).shape == (6,) and np.all(np.isnan(getattr(log, name))), name
    assert log.true_time_s.size == 0 and log.ball_lost.size == 0


def test_rig_log_with_only_the_required_variables(tmp_path):
    """The rig's file: preallocated to 100001, k used, row 1 the unwritten zero row, sampnumber an empty
    matrix, and times that start anywhere, here before the zero row's 0."""
    k = 5
    raw: dict = {name: np.zeros(100001) for name in ("timem", "datam1", "datam2", "aout")}
    raw["timem"][1:k] = [-0.5, -0.48, -0.46, -0.44]
    raw["datam1"][1:k] = [1.0, 1.1, 1.2, 1.3]
    raw["aout"][1:k] = 2.5
    raw["sampnumber"] = np.zeros((0, 0))
    raw["k"] = float(k)
    log = load_mat(write_mat(tmp_path / "rig.mat", raw))
    assert log.k == k
    np.testing.assert_array_equal(log.timem, [0.0, -0.5, -0.48, -0.46, -0.44])  # row 1 kept
    np.testing.assert_array_equal(log.datam1, [0.0, 1.0, 1.1, 1.2, 1.3])
    assert np.all(np.isnan(log.x1)) and np.all(np.isnan(log.uhesap))


def test_row_1_is_exempt_from_the_time_order_only_when_it_is_the_rig_zero_row(tmp_path):
    raw = required()
    raw["timem"][1] = -1.0  # row 1 (a real start block, time -0.01 s) is after row 2
    with pytest.raises(LogError, match=r"start.mat: variable 'timem', index 2 is -1.0 s, not after -0.01 s"):
        load_mat(write_mat(tmp_path / "start.mat", raw))
    raw["timem"][0] = 0.0
    raw["aout"][0] = 0.0
    raw["datam1"][0] = raw["datam2"][0] = 0.0
    assert load_mat(write_mat(tmp_path / "zero.mat", raw)).timem[1] == -1.0  # the rig's unwritten row
    raw["aout"][0] = 2.5  # the twin's start block at t = 0 (DAC at 2.5 V) is a real sample: not exempt
    with pytest.raises(LogError, match=r"not_zero.mat: variable 'timem', index 2 is -1.0 s"):
        load_mat(write_mat(tmp_path / "not_zero.mat", raw))


@pytest.mark.parametrize(
    ("field", "index", "value", "message"),
    [
        ("datam2", 4, math.nan, r"'datam2', index 4{line} is nan: 'datam2' must be finite"),
        ("aout", 6, math.inf, r"'aout', index 6{line} is inf: 'aout' must be finite"),
        ("timem", 1, -math.inf, r"'timem', index 1{line} is -inf: 'timem' must be finite"),
        (
            "timem",
            5,
            0.05,
            r"'timem', index 5{line} is 0.05 s, not after 0.05 s at index 4: .* increase strictly",
        ),
        ("timem", 3, 0.0, r"'timem', index 3{line} is 0.0 s, not after 0.01 s at index 2"),
    ],
)
@pytest.mark.parametrize("fmt", ["mat", "csv"])
def test_bad_required_values_are_refused_with_file_field_and_index(
    tmp_path, fmt, field, index, value, message
):
    raw = required()
    raw[field][index - 1] = value
    if fmt == "mat":
        path, kind, line = write_mat(tmp_path / "bad.mat", raw), "variable", ""
    else:
        path, kind, line = write_csv(tmp_path / "bad.csv", raw), "column", rf" \(line {index + 1}\)"
    load = load_mat if fmt == "mat" else load_csv
    with pytest.raises(LogError, match=rf"bad.{fmt}: {kind} " + message.format(line=line)):
        load(path)


def test_a_missing_k_takes_every_stored_value(tmp_path):
    raw: dict = {name: np.zeros(10) for name in ("timem", "datam1", "datam2", "aout")}
    raw["timem"][1:4] = [0.02, 0.04, 0.06]
    with pytest.raises(LogError, match=r"nok.mat: variable 'timem', index 5 is 0.0 s, .*the file has no 'k'"):
        load_mat(write_mat(tmp_path / "nok.mat", raw))
    raw["k"] = 4.0
    assert load_mat(write_mat(tmp_path / "k.mat", raw)).k == 4
    raw = {name: value[:4] for name, value in raw.items() if name != "k"}
    raw["datam2"] = np.zeros(3)
    with pytest.raises(
        LogError, match=r"short.mat: variable 'datam2' has 3 values but 'timem' has 4 .*index 4"
    ):
        load_mat(write_mat(tmp_path / "short.mat", raw))


def test_vhesap_is_read_as_uhesap(tmp_path):
    raw = required()
    raw["Vhesap"] = np.arange(6.0)
    np.testing.assert_array_equal(load_mat(write_mat(tmp_path / "clp.mat", raw)).uhesap, np.arange(6.0))


@pytest.mark.parametrize("value", [2.0, 0.5, -1.0, math.nan])
def test_ball_lost_other_than_0_or_1_is_refused_in_both_formats(tmp_path, value):
    log = make_log(ticks=5, physics_steps=4)
    save_mat(log, tmp_path / "ok.mat")
    raw = {name: v for name, v in scipy.io.loadmat(tmp_path / "ok.mat").items() if not name.startswith("__")}
    raw["ball_lost"] = np.array([0.0, 1.0, value, 0.0])
    scipy.io.savemat(tmp_path / "lost.mat", raw)
    shown = "nan" if math.isnan(value) else f"{value:g}"
    expected = rf"variable 'ball_lost', index 3 is {shown}: 'ball_lost' must hold 0 or 1"
    with pytest.raises(LogError, match=rf"lost.mat: {expected}"):
        load_mat(tmp_path / "lost.mat")
    save_csv(log, tmp_path / "ok.csv")
    lines = (tmp_path / "ok.csv").read_text().splitlines()
    lines[3] = lines[3][: lines[3].rindex(",") + 1] + repr(value)  # ball_lost is the last column
    (tmp_path / "lost.csv").write_text("\n".join(lines) + "\n")
    expected = rf"column 'ball_lost', index 3 \(line 4\) is {shown}: 'ball_lost' must hold 0 or 1"
    with pytest.raises(LogError, match=rf"lost.csv: {expected}"):
        load_csv(tmp_path / "lost.csv")


def test_csv_with_only_the_required_columns_and_a_byte_order_mark(tmp_path):
    path = tmp_path / "four.csv"
    write_csv(path, required())
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    log = load_csv(path)
    np.testing.assert_array_equal(log.datam1, required()["datam1"])
    assert np.all(np.isnan(log.x3)) and log.true_x_m.size == 0
    full = make_log()
    save_csv(full, tmp_path / "full.csv")
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbf" + (tmp_path / "full.csv").read_bytes())
    assert_identical(load_csv(tmp_path / "bom.csv"), full)


def test_an_empty_optional_column_is_not_recorded(tmp_path):
    path = tmp_path / "empty_u.csv"
    write_csv(path, required(3))
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0] + ",u"] + [line + "," for line in lines[1:]]) + "\n")
    assert np.all(np.isnan(load_csv(path).u))


@pytest.mark.parametrize(("save", "load"), [(save_mat, load_mat), (save_csv, load_csv)])
def test_loading_never_modifies_the_file(tmp_path, save, load):
    path = tmp_path / "log.out"
    save(make_log(), path)
    before = (path.read_bytes(), path.stat().st_mtime_ns)
    load(path)
    assert (path.read_bytes(), path.stat().st_mtime_ns) == before


@pytest.mark.quick
@pytest.mark.parametrize("suffix", [".mat", ".csv"])
def test_a_log_path_that_is_not_a_regular_file_is_named_for_what_it_is(tmp_path: Path, suffix: str) -> None:
    """A directory or a link to a device named like a log is refused for what it is (not "no such file"), and
    a device is never read (``/dev/zero`` would be endless)."""
    load = load_mat if suffix == ".mat" else load_csv
    folder = tmp_path / f"x{suffix}"
    folder.mkdir()
    with pytest.raises(LogError, match=r"x\.\w+: a directory, not a log file"):
        load(folder)
    device = tmp_path / f"z{suffix}"
    device.symlink_to("/dev/zero")
    with pytest.raises(LogError, match=r"z\.\w+: not a regular file \(a device, pipe or socket\)"):
        load(device)
    with pytest.raises(LogError, match="no such file"):
        load(tmp_path / f"missing{suffix}")
