"""Every input checked for meaning: numeric options, validation criteria, parameter and spread files, MATLAB
v7.3 logs. Each refusal is exit 2 with one line naming the option, field or file and the value, no
traceback, before any work."""

from __future__ import annotations

import argparse
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io
from cli_checks import refused as _refused

from calib.logs import ADC_STEP_V, DAC_STEP_V, load_rig_log, read_mat73
from twin.app import options
from twin.app.cli import main
from twin.app.validate import ValidationCriteria, check_criteria_for, load_criteria
from twin.engine import RunResult
from twin.log import LogError, load_mat
from twin.parameters import ParameterError, Parameters

PERIOD_S = 0.02


# --- the option types ----------------------------------------------------------------------------------
@pytest.mark.quick
def test_the_types_return_the_number_and_refuse_naming_the_range() -> None:
    duration = options.finite_float(0, 3600, lo_open=True, unit="s", why="memory")
    assert duration("3600") == 3600.0 and duration("1e-9") == 1e-9
    for text, words in [
        ("0", "0 is out of range; expected more than 0 and at most 3600 s (memory)"),
        ("inf", "inf is not a finite number; expected more than 0 and at most 3600 s"),
        ("nan", "nan is not a finite number"),
        ("ten", "'ten' is not a number"),
    ]:
        with pytest.raises(argparse.ArgumentTypeError, match=words.replace("(", r"\(").replace(")", r"\)")):
            duration(text)
    workers = options.count(1, 256)
    assert workers("256") == 256 and isinstance(workers("3"), int)
    for text in ("1.5", "1e3", "0", "257", "nan"):
        with pytest.raises(argparse.ArgumentTypeError):
            workers(text)
    seed = options.seed()
    assert seed(str(options.SEED_MAX)) == 2**63 - 1
    with pytest.raises(argparse.ArgumentTypeError, match="expected 0…9223372036854775807"):
        seed("-1")
    grid = options.GridType("--x0", max_n=lambda: 10)
    assert grid("-0.3:0.3:10") == "-0.3:0.3:10" and grid("0.1") == "0.1"
    for text, words in [
        ("-0.3:0.3:11", "N: 11 is out of range; expected 1…10 points"),
        ("0.3:-0.3:3", "LO 0.3 is above HI -0.3"),
        ("-inf:0.3:3", "-inf is not a finite number"),
        ("0:1", "expected LO:HI:N"),
        ("0:1:2.5", "'2.5' is not an integer"),
    ]:
        with pytest.raises(argparse.ArgumentTypeError, match=words):
            grid(text)


RUN = ["run", "--controller", "lqr", "--x0", "0.1", "--theta0", "0"]
BAD_OPTIONS = [
    ([*RUN, "--seed", "-1"], "--seed", "-1", "0…9223372036854775807"),
    ([*RUN, "--seed", "1.5"], "--seed", "'1.5' is not an integer"),
    (["run", "--controller", "lqr", "--x0", "nan", "--theta0", "0"], "--x0", "nan is not a finite number"),
    ([*RUN, "--duration", "1e12"], "--duration", "1e12", "3600 s", "memory"),
    (["sweep", "--controller", "lqr", "--x0", "-0.1:0.1:100000000000"], "--x0", "100000000000", "250000"),
    (
        ["sweep", "--controller", "lqr", "--x0", "-0.1:0.1:600", "--theta0", "-0.1:0.1:600"],
        "360000",
        "250000",
    ),
    (["sweep", "--controller", "lqr", "--duration", "601"], "--duration", "601", "600 s"),
    (["sweep", "--controller", "lqr", "--workers", "0"], "--workers", "0", "1…256"),
    (["montecarlo", "--controller", "lqr", "--spread", "s.toml", "--n", "0"], "--n", "0", "1…100000"),
    (["montecarlo", "--controller", "lqr", "--spread", "s.toml", "--n", "2.5"], "--n", "'2.5'"),
    (["montecarlo", "--controller", "lqr", "--spread", "s.toml", "--theta0", "inf"], "--theta0", "inf"),
    (["validate", "--controller", "lqr", "--seed", "-3"], "--seed", "-3"),
    (["validate", "--controller", "lqr", "--workers", "1000"], "--workers", "1000"),
    (["view", "--port", "99999"], "--port", "99999", "1…65535"),
    (["view", "--speed", "nan"], "--speed", "nan", "0.1…4"),
    (["view", "--duration", "-1"], "--duration", "-1"),
    (["calibrate", "x.mat", "--fit", "motor.resistance_ohm", "--window", "inf"], "--window", "inf"),
    (["calibrate", "x.mat", "--fit", "motor.resistance_ohm", "--window", "-1"], "--window", "-1"),
    (["experiment", "square", "--out", "x.mat", "--duration", "4"], "--duration", "4", "5…3600 s"),
    (["experiment", "square", "--out", "x.mat", "--seed", "-5"], "--seed", "-5"),
]


@pytest.mark.parametrize(("argv", "needles"), [(a[0], a[1:]) for a in BAD_OPTIONS])
def test_numeric_options_are_refused_naming_the_option_and_value(
    capsys: pytest.CaptureFixture[str], no_work: None, argv: list[str], needles: tuple[str, ...]
) -> None:
    _refused(capsys, argv, *needles)


def _rig_log(path: Path, ticks: int = 400) -> Path:
    """A rig's data_file.mat: row 1 the unwritten zero row, then 20 ms ticks on the converters' steps."""
    t = 12.34 + PERIOD_S * np.arange(ticks)
    rows = {
        "timem": t,
        "datam1": np.round(1.5 * np.sin(2 * np.pi * 0.4 * t) / ADC_STEP_V) * ADC_STEP_V,
        "datam2": np.round(0.3 * np.cos(2 * np.pi * 0.4 * t) / ADC_STEP_V) * ADC_STEP_V,
        "aout": 2.5 + np.round(0.4 * np.sin(2 * np.pi * 0.7 * t) / DAC_STEP_V) * DAC_STEP_V,
    }
    data: dict[str, object] = {name: np.r_[0.0, v] for name, v in rows.items()}
    data["k"] = float(ticks + 1)
    data["sampnumber"] = np.zeros((0, 0))
    scipy.io.savemat(path, data, format="5", oned_as="column")
    return path


@pytest.mark.parametrize("window", ["0", "0.039"])
def test_a_calibration_window_under_two_ticks_is_refused_with_the_minimum(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, window: str
) -> None:
    import calib.identify

    monkeypatch.setattr(calib.identify, "calibrate", lambda *a, **k: pytest.fail("fitted"))
    log = _rig_log(tmp_path / "rig.mat")
    argv = ["calibrate", str(log), "--fit", "motor.resistance_ohm", "--window", window]
    _refused(capsys, argv, f"--window = {float(window):g}", "at least 2 ticks", "20 ms", "0.04 s")


def test_negative_numbers_still_reach_the_new_types() -> None:
    from twin.app.cli import build_parser, join_negative_numbers

    parser = build_parser()
    assert join_negative_numbers(["sweep", "--x0", "-0.3:0.3:7", "--workers", "-2"], parser) == [
        "sweep",
        "--x0=-0.3:0.3:7",
        "--workers=-2",
    ]


# --- validation criteria -------------------------------------------------------------------------------
BAD_CRITERIA = [
    ("nominal_seeds = 0\nlatencies_s = []\nfree_runs_s = []\nzeroing_counts = 0\n", "nominal_seeds = 0"),
    ("nominal_seeds = -2\n", "nominal_seeds = -2"),
    ("zeroing_counts = -1\n", "zeroing_counts = -1"),
    ("montecarlo_runs = -5\n", "montecarlo_runs = -5"),
    ("region_x0 = [-0.3, 0.3]\n", "region_x0 = [-0.3, 0.3]"),
    ("region_x0 = [0.3, -0.3, 5]\n", "region_x0 = [0.3, -0.3, 5]"),
    ("region_x0 = [-0.3, 0.3, 2.5]\n", "region_x0 = [-0.3, 0.3, 2.5]"),
    ("region_x0 = [-0.3, 0.3, 600]\nregion_theta0 = [-0.3, 0.3, 600]\n", "360000 starts"),
    ("required_x0_m = [0.2, -0.2]\n", "required_x0_m = [0.2, -0.2]"),
    ("required_theta0_rad = [-0.3, 0.3, 0.5]\n", "required_theta0_rad = [-0.3, 0.3, 0.5]"),
    ("required_x0_m = [-0.3, 0.3]\nregion_x0 = [-0.2, 0.2, 5]\n", "reaches outside region_x0"),
    ("duration_s = 1e9\n", "duration_s = 1000000000.0", "600 s"),
    ("region_duration_s = 0\n", "region_duration_s = 0.0"),
    ("latencies_s = [-0.001]\n", "latencies_s = [-0.001]"),
    ("max_saturated_fraction = 1.5\n", "max_saturated_fraction = 1.5"),
    ("min_success_lower_bound = 0.97\n", "min_success_lower_bound = 0.97", "0.963783"),
    ("robust_rigs = 0\n", "robust_rigs = 0"),
    ("robust_rigs = 20\n", "robust_rigs = 20", "0.831567"),
]


@pytest.mark.quick
@pytest.mark.parametrize(("text", "needles"), [(c[0], c[1:]) for c in BAD_CRITERIA])
def test_criteria_without_meaning_are_refused_before_any_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_work: None, text: str, needles: tuple[str, ...]
) -> None:
    path = tmp_path / "criteria.toml"
    path.write_text(text)
    with pytest.raises(ParameterError, match=str(path)):
        load_criteria(path)
    _refused(capsys, ["validate", "--controller", "lqr", "--criteria", str(path)], str(path), *needles)


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("region_x0 = [-0.5, 0.5, 5]\nrequired_x0_m = [-0.2, 0.2]\n", ("region_x0", "off the track")),
        ("region_theta0 = [-0.8, 0.8, 5]\n", ("region_theta0", "beyond the stops")),
        ("latencies_s = [0.0, 0.03]\n", ("latencies_s", "0.03", "shorter than the period 0.02 s")),
        ("zeroing_counts = 1000\n", ("zeroing_counts = 1000", "zeroing_error_rad")),
    ],
)
def test_criteria_impossible_for_the_rig_are_refused_before_any_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_work: None, text: str, needles: tuple[str, ...]
) -> None:
    path = tmp_path / "criteria.toml"
    path.write_text(text)
    _refused(capsys, ["validate", "--controller", "lqr", "--criteria", str(path)], str(path), *needles)


def test_the_default_criteria_and_the_monte_carlo_bound_they_can_reach(params: Parameters) -> None:
    check_criteria_for(ValidationCriteria(), params)
    from twin.app.validate import best_success_lower_bound

    # The exact (Clopper–Pearson) 95 % lower bound of n held of n is 0.025^(1/n).
    assert best_success_lower_bound(100) == round(0.025 ** (1 / 100), 6) == 0.963783
    # (the robust region's rigs must reach the bound too)
    assert (
        ValidationCriteria(montecarlo_runs=100, robust_rigs=100, min_success_lower_bound=0.963783).robust_rigs
        == 100
    )
    with pytest.raises(ParameterError, match="montecarlo_runs = 10 even all runs held"):
        ValidationCriteria(montecarlo_runs=10)  # the default 0.9 needs at least 36 runs
    assert ValidationCriteria(montecarlo_runs=36).montecarlo_runs == 36
    with pytest.raises(ParameterError, match="robust_rigs = 35 even all rigs keeping a start"):
        ValidationCriteria(robust_rigs=35)  # the robust region's rigs: the same bound
    assert ValidationCriteria(robust_rigs=36).robust_rigs == 36


# --- parameter and spread files ------------------------------------------------------------------------
BOM = b"\xef\xbb\xbf"


@pytest.mark.parametrize(
    ("name", "body"),
    [("p.toml", b"[motor]\nresistance_ohm = 9.5\n"), ("p.json", b'{"motor": {"resistance_ohm": 9.5}}')],
)
def test_parameter_files_with_a_byte_order_mark_are_read(tmp_path: Path, name: str, body: bytes) -> None:
    path = tmp_path / name
    path.write_bytes(BOM + body)
    assert Parameters.from_file(path).motor.resistance_ohm == 9.5


@pytest.mark.parametrize(
    ("body", "key"),
    [
        ('{"motor": {"resistance_ohm": 9.5, "resistance_ohm": 8.0}}', "'resistance_ohm'"),
        ('{"motor": {"resistance_ohm": 9.5}, "ball": {}, "motor": {}}', "'motor'"),
    ],
)
def test_duplicate_json_keys_are_refused_naming_the_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], body: str, key: str
) -> None:
    path = tmp_path / "p.json"
    path.write_text(body)
    with pytest.raises(ParameterError, match=f"{path}: duplicate key {key}"):
        Parameters.from_file(path)
    _refused(capsys, ["params", "--params", str(path)], str(path), f"duplicate key {key}")


def test_a_spread_file_naming_a_parameter_twice_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_work: None
) -> None:
    path = tmp_path / "spread.json"
    path.write_bytes(
        BOM + b'{"motor": {"resistance_ohm": {"rel_sd": 0.1}, "resistance_ohm": {"rel_sd": 0.2}}}'
    )
    argv = ["montecarlo", "--controller", "lqr", "--spread", str(path), "--n", "2"]
    _refused(capsys, argv, str(path), "duplicate key 'resistance_ohm'")


def test_a_spread_file_with_a_byte_order_mark_is_read(tmp_path: Path, params: Parameters) -> None:
    from twin.app.montecarlo import load_spread

    path = tmp_path / "spread.json"
    path.write_bytes(BOM + b'{"motor": {"resistance_ohm": {"rel_sd": 0.1}}}')
    spread = load_spread(path, params)
    assert spread.names == ("motor.resistance_ohm",)
    assert spread.sd == pytest.approx((0.1 * params.motor.resistance_ohm,), rel=1e-15)


def test_a_relative_spread_of_a_zero_parameter_is_refused(tmp_path: Path, params: Parameters) -> None:
    from twin.app.montecarlo import load_spread

    path = tmp_path / "spread.toml"
    path.write_text("[angle_sensor]\nzeroing_error_rad = { rel_sd = 0.1 }\n")
    assert params.angle_sensor.zeroing_error_rad == 0.0
    with pytest.raises(
        ParameterError, match=r"zeroing_error_rad = \{'rel_sd': 0.1\}: its nominal value is 0"
    ):
        load_spread(path, params)
    path.write_text("[angle_sensor]\nzeroing_error_rad = { sd = 0.003 }\n")
    assert load_spread(path, params).sd == (0.003,)


@pytest.mark.parametrize(
    ("index", "volts", "previous"),
    [(22, 4.34, 4.34), (5, -3.5, -3.045)],  # constant at the end; decreasing in the middle
)
def test_ball_curve_volts_must_increase_strictly(
    params: Parameters, index: int, volts: float, previous: float
) -> None:
    curve = list(params.ball_sensor.curve_volts_v)
    curve[index] = volts
    assert curve[index - 1] == previous
    with pytest.raises(
        ParameterError, match=rf"curve_volts_v\[{index}\] = {volts} V is impossible.*{previous}"
    ):
        params.with_overrides({"ball_sensor.curve_volts_v": curve})
    constant = [1.0] * len(curve)
    with pytest.raises(ParameterError, match=r"curve_volts_v\[1\] = 1.0 V"):
        params.with_overrides({"ball_sensor.curve_volts_v": constant})


def test_the_measured_curve_increases(params: Parameters) -> None:
    assert np.all(np.diff(params.ball_sensor.curve_volts_v) > 0)


# --- MATLAB v7.3 logs ----------------------------------------------------------------------------------
def write_mat73(path: Path, variables: dict[str, np.ndarray]) -> Path:
    """What MATLAB's ``save -v7.3`` writes: HDF5 behind a 512-byte user block holding the MATLAB header,
    each array transposed (MATLAB is column-major: an n × 1 vector is stored 1 × n) with its MATLAB_class,
    an empty array as its dimensions with MATLAB_empty = 1."""
    with h5py.File(path, "w", userblock_size=512) as fh:
        for name, value in variables.items():
            arr = np.atleast_2d(value)
            if arr.size == 0:
                ds = fh.create_dataset(name, data=np.array(arr.shape[::-1], dtype=np.uint64))
                ds.attrs["MATLAB_empty"] = np.uint8(1)
            else:
                ds = fh.create_dataset(name, data=arr.T)
            ds.attrs["MATLAB_class"] = np.bytes_("logical" if arr.dtype == np.uint8 else "double")
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Wed Dec  2 12:00:00 2026 HDF5 schema 1.00 ."
    header = text.ljust(116, b" ") + b"\0" * 8 + b"\x00\x02" + b"IM"
    with path.open("r+b") as fh:
        fh.write(header.ljust(512, b"\0"))
    return path


def test_a_v73_log_reads_equal_to_the_v5_log_of_the_same_data(tmp_path: Path) -> None:
    v5 = _rig_log(tmp_path / "v5.mat")
    raw = {k: v for k, v in scipy.io.loadmat(v5).items() if not k.startswith("__")}
    assert raw["timem"].shape == (401, 1)  # a column vector, as the rig's software saves it
    v73 = write_mat73(tmp_path / "v73.mat", raw)
    with h5py.File(v73, "r") as fh:
        assert fh["timem"].shape == (1, 401)  # HDF5 holds the transpose
    variables = read_mat73(v73)
    assert variables["timem"].shape == (401, 1) and variables["sampnumber"].shape == (0, 0)
    a, b = load_rig_log(v5), load_rig_log(v73)
    for name in ("time_s", "ball_v", "angle_v", "command_v"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.period_s == b.period_s and a.ticks == b.ticks == 400
    assert b.time_s[0] == 12.34 and b.command_v.tobytes() == a.command_v.tobytes()


def test_a_v73_log_is_refused_with_what_to_do_where_it_is_not_read(tmp_path: Path) -> None:
    v73 = write_mat73(tmp_path / "v73.mat", {"timem": np.arange(3.0)})
    with pytest.raises(LogError, match=r"v7.3 \(HDF5\).*calibrate reads it.*-v7"):
        load_mat(v73)
    # calibrate reads it and names what is missing, as for a v5 file
    with pytest.raises(LogError, match="variable 'datam1' is missing"):
        load_rig_log(v73)


def test_a_broken_v73_file_is_one_message(tmp_path: Path) -> None:
    path = write_mat73(tmp_path / "v73.mat", {"timem": np.arange(3.0)})
    data = path.read_bytes()
    path.write_bytes(data[:600])  # the header and HDF5's signature, then nothing
    with pytest.raises(LogError, match=f"{path}: a MATLAB v7.3"):
        load_rig_log(path)


# --- numerical failures --------------------------------------------------------------------------------
TINY_R = {"motor.resistance_ohm": 1e-9}  # 1 nΩ: a torque per volt of 10⁷ N·m, far past what a 1 ms step holds


@pytest.mark.quick
def test_parameters_changed_lists_what_differs_from_the_defaults(params: Parameters) -> None:
    assert params.changed() == {}
    p = params.with_overrides({**TINY_R, "start.free_run_s": 0.02})
    assert p.changed() == {"motor.resistance_ohm": 1e-9, "start.free_run_s": 0.02}


def test_the_stops_yield_bound_is_the_no_load_speed_over_a_step_and_a_time_constant(
    params: Parameters,
) -> None:
    from twin.plant import stop_overshoot_bound_rad

    # rail_v / (N·K_b) = 12 / (7 · 0.022) = 77.9 rad/s at the beam, over 1 ms + 2 ms
    assert stop_overshoot_bound_rad(params) == pytest.approx(12.0 / (7 * 0.022) * 0.003, rel=1e-12)
    assert stop_overshoot_bound_rad(params) == pytest.approx(0.2338, abs=1e-4)


def test_an_unstable_simulation_is_a_numerical_failure_not_a_lost_ball(
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = ["run", "--controller", "lqr", "--x0", "0.1", "--theta0", "0", "--duration", "1", "--json"]
    rc = main([*argv, "--set", "motor.resistance_ohm=1e-9"])
    captured = capsys.readouterr()
    assert rc == 1 and captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    line = lines[0]
    assert line.startswith("ballbeam run: numerical failure: MuJoCo reported an unstable simulation (BADQACC")
    # the step that failed is the first one driven: the free run ends at 10 ms
    assert "at t = 0.010 s" in line
    assert "the parameters differ from the defaults in motor.resistance_ohm = 1e-09" in line
    assert "the physics step is 1 ms" in line and "lost" not in line


def test_mujoco_prints_nothing_of_its_own(tmp_path: Path) -> None:
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parent.parent
    env = {**os.environ, "PYTHONPATH": str(root)}
    argv = ["run", "--controller", "lqr", "--x0", "0.1", "--theta0", "0", "--duration", "1"]
    done = subprocess.run(
        [sys.executable, "-m", "twin.app.cli", *argv, "--set", "motor.resistance_ohm=1e-9"],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=120,
    )
    assert done.returncode == 1
    assert "WARNING" not in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_the_batch_names_the_failing_run_and_the_job_records_it_as_numerical(params: Parameters) -> None:
    from controllers import registry
    from twin.app.fanout import Runs, run_starts
    from twin.plant import NumericalError
    from twin.rigs.batch import run_batch

    bad = params.with_overrides(TINY_R)
    with pytest.raises(NumericalError, match=r"^run 1: numerical failure: MuJoCo reported .*BADQACC.*1e-09"):
        run_batch(
            registry,
            "appendix-clp",
            x0_m=np.array([0.1, 0.1]),
            theta0_rad=np.zeros(2),
            seeds=np.arange(2),
            duration_s=1.0,
            params=[params, bad],
            nthread=1,
        )
    runs = Runs("appendix-clp", params, 4.0, True, "twin", False)
    records, complete = run_starts(
        runs, np.array([[0.1, 0.0], [0.1, 0.0]]), np.array([3, 3]), params=[params, bad]
    )
    assert complete
    good, failed = records
    assert good is not None and failed is not None
    assert good["failed"] is False and "numerical" not in good
    single = twin_run("appendix-clp", params, seed=3)
    steady = single.verdict.steady_x_m
    assert (
        steady is not None and good["held"] == single.verdict.held and good["steady_x_m"] == round(steady, 6)
    )
    assert failed["failed"] is True and failed["numerical"] is True
    assert failed["ball_lost"] is False and failed["held"] is False  # not counted as a lost ball
    assert failed["reason"].startswith("numerical failure: MuJoCo reported an unstable simulation (BADQACC")
    assert "motor.resistance_ohm = 1e-09" in failed["reason"]


def twin_run(name: str, params: Parameters, seed: int) -> RunResult:
    from controllers import registry
    from twin.rigs.sim import run_closed_loop

    return run_closed_loop(registry.make(name, params), x0_m=0.1, theta0_rad=0.0, duration_s=4.0, seed=seed)


def test_an_amplifier_gain_of_1000_hits_the_stops_within_their_softness(params: Parameters) -> None:
    """The beam slammed into its stops yields a few mrad (soft stops, 2 ms, acting from the next 1 ms step):
    physical for the twin, reported as hit_stops; the bound is 0.234 rad."""
    from controllers import registry
    from twin.rigs.sim import run_closed_loop

    p = params.with_overrides({"amplifier.gain_v_per_v": 1000.0})
    r = run_closed_loop(registry.make("appendix-sf", p), x0_m=0.2, theta0_rad=0.3, duration_s=2.0, params=p)
    over_rad = r.verdict.peak_theta_rad - p.beam.stop_angle_rad
    assert r.verdict.hit_stops and 0.001 < over_rad < 0.006  # measured: 3.55 mrad
    assert np.abs(r.log.true_thetadot_rad_s).max() < 8.0  # rad/s, measured 4.9 at the ticks


@pytest.mark.parametrize("where", ["single", "batch"])
def test_a_beam_past_what_the_stops_yield_is_numerical(
    params: Parameters, monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    """With the yield bound shrunk to 1 mrad, the same gain-1000 run (3.55 mrad past the stops) fails
    numerically, in the single run and in the batch: the check reads every step's angle."""
    import twin.plant
    import twin.plant_batch
    import twin.rigs.batch
    from controllers import registry
    from twin.plant import NumericalError
    from twin.rigs.sim import run_closed_loop

    for module in (twin.plant, twin.plant_batch):  # the single run's plant and MuJoCo's batch
        monkeypatch.setattr(module, "stop_overshoot_bound_rad", lambda p: 0.001)
    p = params.with_overrides({"amplifier.gain_v_per_v": 1000.0})
    pattern = r"numerical failure: the beam at 0\.7\d+ rad, past its stops \(0\.7575 rad\) by more than they can yield"
    with pytest.raises(NumericalError, match=pattern):
        if where == "single":
            run_closed_loop(
                registry.make("appendix-sf", p), x0_m=0.2, theta0_rad=0.3, duration_s=2.0, params=p
            )
        else:
            twin.rigs.batch.run_batch(
                registry, "appendix-sf", x0_m=np.array([0.2]), theta0_rad=np.array([0.3]), seeds=np.zeros(1),
                duration_s=2.0, params=p, nthread=1,
            )  # fmt: skip


def test_a_model_mujoco_cannot_compile_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["run", "--controller", "lqr", "--x0", "0.1", "--theta0", "0", "--set", "ball.mass_kg=1e-12"]
    line = _refused(capsys, argv, "MuJoCo cannot build the model from these parameters")
    assert "mass and inertia of moving bodies must be larger than mjMINVAL" in line
    assert "(parameters that differ from the defaults: ball.mass_kg = 1e-12)" in line
