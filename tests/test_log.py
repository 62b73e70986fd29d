"""Logs in the thesis software's format (appendix A ``save 'data_file' …``), MAT and CSV."""

import math

import numpy as np
import pytest
import scipy.io

from twin.log import THESIS_FIELDS, TRUTH_FIELDS, LogError, RunLog, load_csv, load_mat, save_csv, save_mat


def make_log(ticks: int = 50, physics_steps: int = 1000, seed: int = 0) -> RunLog:
    rng = np.random.default_rng(seed)
    thesis = {name: rng.normal(size=ticks) * 10.0 ** rng.uniform(-8, 3, ticks) for name in THESIS_FIELDS}
    thesis["timem"] = 0.02 * np.arange(ticks) + rng.uniform(0, 1e-12, ticks)
    thesis["uhesap"][3] = math.nan  # a NaN must survive too
    truth = {name: rng.normal(size=physics_steps) for name in TRUTH_FIELDS}
    truth["ball_lost"] = rng.uniform(size=physics_steps) < 0.1
    return RunLog(**thesis, **truth)


def assert_identical(a: RunLog, b: RunLog) -> None:
    for name in THESIS_FIELDS + TRUTH_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        if x.dtype == bool:
            assert np.array_equal(x, y), name
        else:
            assert np.array_equal(x.view(np.uint64), y.view(np.uint64)), name  # bit-identical, NaN included
    assert a.k == b.k


def test_mat_round_trip_is_bit_identical(tmp_path):
    log = make_log()
    save_mat(log, tmp_path / "data_file.mat")
    assert_identical(load_mat(tmp_path / "data_file.mat"), log)


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
    # As the rig saves it: arrays of sampsize + 1 = 100001 zeros filled up to k, uhesap never written.
    k = 4
    raw = {name: np.zeros(100001) for name in THESIS_FIELDS}
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
    assert path.stat().st_size > 100


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


def test_malformed_csv_files(tmp_path):
    save_csv(make_log(ticks=5, physics_steps=3), tmp_path / "good.csv")
    lines = (tmp_path / "good.csv").read_text().splitlines()

    def write(name: str, new_lines: list[str]) -> str:
        (tmp_path / name).write_text("\n".join(new_lines) + "\n")
        return str(tmp_path / name)

    header = lines[0].split(",")
    col = header.index("x2")
    no_x2 = [",".join(c for i, c in enumerate(line.split(",")) if i != col) for line in lines]
    with pytest.raises(LogError, match="no_x2.csv: column 'x2' is missing"):
        load_csv(write("no_x2.csv", no_x2))
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


def test_runlog_refuses_inconsistent_arrays():
    arrays = {name: np.zeros(3) for name in THESIS_FIELDS}
    arrays["aout"] = np.zeros(4)
    with pytest.raises(LogError, match="field 'aout' has 4 values but 'timem' has 3"):
        RunLog(**arrays)
    arrays["aout"] = np.zeros((3, 1))
    with pytest.raises(LogError, match=r"field 'aout' has shape \(3, 1\)"):
        RunLog(**arrays)
