"""One check per input kind, refused before any work with a message naming the file, the field and the value:
spread files (``twin.app.montecarlo.load_spread``: read as parameter files are, their distributions inside the
parameters' bounds, nothing a study's rigs share), the robust map's options, and the Gymnasium environment's
actions, options and durations (``twin.learning.ActionSpec``, ``twin.app.envs``)."""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_checks import refused

from twin.app.montecarlo import load_spread, sample_parameters
from twin.parameters import MAX_FILE_BYTES, ParameterError, Parameters

P = Parameters()


def _spread(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "spread.toml"
    path.write_text(text)
    return path


# --- spread files: read as parameter files are -------------------------------------------------------------


@pytest.mark.quick
@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
def test_an_endless_spread_file_is_refused_before_it_is_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_work: None
) -> None:
    with pytest.raises(ParameterError, match="/dev/zero: not a regular file"):
        load_spread("/dev/zero", P)
    link = tmp_path / "zero.toml"
    link.symlink_to("/dev/zero")
    for command in (
        ["montecarlo", "--controller", "lqr", "--n", "2"],
        ["sweep", "--controller", "lqr", "--rigs", "2"],
    ):
        refused(capsys, [*command, "--spread", str(link)], str(link), "not a regular file")


@pytest.mark.quick
@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs")
def test_a_fifo_as_spread_file_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    fifo = tmp_path / "spread.toml"
    os.mkfifo(fifo)
    outcome: list[BaseException] = []
    reader = threading.Thread(
        target=lambda: outcome.append(pytest.raises(ParameterError, load_spread, fifo, P).value), daemon=True
    )
    reader.start()
    reader.join(10.0)
    if reader.is_alive():  # unblock the reader before failing
        with open(fifo, "wb"):
            pass
        pytest.fail("load_spread waited on a FIFO")
    assert outcome and "not a regular file" in str(outcome[0]) and str(fifo) in str(outcome[0])


@pytest.mark.quick
def test_a_spread_file_larger_than_a_parameter_file_may_be_is_refused(tmp_path: Path) -> None:
    path = _spread(tmp_path, "[motor]\nresistance_ohm = { rel_sd = 0.05 }\n# " + "x" * MAX_FILE_BYTES + "\n")
    with pytest.raises(ParameterError, match=f"{path}: larger than {MAX_FILE_BYTES} bytes"):
        load_spread(path, P)
    with pytest.raises(ParameterError, match="not a regular file"):
        load_spread(tmp_path, P)  # a directory


# --- spread files: the distribution stated is the one drawn ------------------------------------------------


@pytest.mark.quick
@pytest.mark.parametrize(
    ("text", "needles"),
    [
        (
            "[ball]\nmass_kg = { low = -0.1, high = 0.02 }\n",
            ("ball.mass_kg", "low = -0.1 is outside the parameter's bounds (> 0 and <= 1)"),
        ),
        ("[ball]\nmass_kg = { low = 0.01, high = 2.0 }\n", ("ball.mass_kg", "high = 2 is outside")),
        (
            "[ball]\nmass_kg = { rel_sd = 0.9 }\n",
            (
                "ball.mass_kg",
                "'rel_sd': 0.9",
                "by 3 standard deviations",
                "outside the parameter's bounds (> 0",
            ),
        ),
        ("[motor]\nresistance_ohm = { sd = 4.0 }\n", ("motor.resistance_ohm", "'sd': 4.0", "below by 3")),
        ("[daq]\nperiod_s = { sd = 0.001 }\n", ("daq.period_s", "the same for every rig")),
        ("[physics]\ntimestep_s = { rel_sd = 0.01 }\n", ("physics.timestep_s", "the same for every rig")),
    ],
)
def test_a_spread_the_rig_cannot_take_is_refused_naming_the_entry_and_value(
    tmp_path: Path, text: str, needles: tuple[str, ...]
) -> None:
    path = _spread(tmp_path, text)
    with pytest.raises(ParameterError) as info:
        load_spread(path, P)
    message = str(info.value)
    assert message.startswith(f"{path}: ")
    for needle in needles:
        assert needle in message, message


@pytest.mark.quick
def test_spreads_inside_the_bounds_and_a_half_normal_at_a_bound_are_kept(tmp_path: Path) -> None:
    mass = P.ball.mass_kg
    path = _spread(
        tmp_path,
        "[ball]\nmass_kg = { rel_sd = 0.3 }\n[beam]\npivot_friction_nm = { sd = 0.001 }\n"
        "[motor]\nresistance_ohm = { low = 9.0, high = 10.0 }\n",
    )
    spread = load_spread(path, P)
    assert spread.sd[0] == pytest.approx(0.3 * mass) and mass - 3 * spread.sd[0] > 0
    _, values = sample_parameters(P, spread, 200, seed=3)
    assert values[:, 1].min() >= 0.0  # the friction's nominal 0 sits on its bound: the half-normal
    assert values[:, 2].min() >= 9.0 and values[:, 2].max() <= 10.0


@pytest.mark.quick
def test_a_spread_of_the_period_is_refused_before_the_nominal_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_work: None
) -> None:
    path = _spread(tmp_path, "[daq]\nperiod_s = { sd = 0.001 }\n")
    for command in (
        ["sweep", "--controller", "lqr", "--rigs", "2", "--x0", "0.1", "--theta0", "0"],
        ["montecarlo", "--controller", "lqr", "--n", "2"],
    ):
        refused(capsys, [*command, "--spread", str(path)], str(path), "daq.period_s", "--set daq.period_s")


@pytest.mark.quick
def test_level_without_rigs_is_refused(capsys: pytest.CaptureFixture[str], no_work: None) -> None:
    refused(capsys, ["sweep", "--controller", "lqr", "--level", "0.5"], "--level 0.5", "--rigs N")


# --- the Gymnasium environment ------------------------------------------------------------------------------


def _env(**options: Any) -> Any:
    from twin.app.envs import BallBeamEnv

    env = BallBeamEnv(duration_s=0.2, **options)
    env.reset(seed=0)
    return env


@pytest.mark.quick
@pytest.mark.parametrize("duration", [1e9, 3600.02, float("inf")])
def test_an_episode_longer_than_a_run_may_be_is_refused(duration: float) -> None:
    from twin.app.envs import BallBeamEnv, BallBeamVectorEnv

    with pytest.raises(ValueError, match=rf"duration_s = {duration!r}: .*at most 3600 s"):
        BallBeamEnv(duration_s=duration)
    with pytest.raises(ValueError, match=rf"duration_s = {duration!r}: .*at most 3600 s"):
        BallBeamVectorEnv(2, duration_s=duration)
    assert BallBeamEnv(duration_s=3600.0).cfg.ticks == 180_000  # the longest run's ticks, not allocated


@pytest.mark.quick
@pytest.mark.parametrize(
    ("action", "shown"),
    [
        (np.array([2.0, 3.0]), "array([2., 3.])"),
        (True, "True"),
        (np.bool_(True), "True"),
        (np.array([True]), "array([ True])"),
        ("2.5", "'2.5'"),
        (np.array(["2.5"]), "array(['2.5']"),
        (None, "None"),
        ([[2.5]], "[[2.5]]"),
        (np.array([], dtype=float), "array([]"),
        (2.5 + 0j, "(2.5+0j)"),
        (float("nan"), "nan"),
        (np.array([np.inf]), "array([inf])"),
    ],
)
def test_an_action_that_is_not_one_real_number_is_refused_naming_it(action: Any, shown: str) -> None:
    env = _env()
    with pytest.raises(ValueError) as info:
        env.step(action)
    message = str(info.value)
    assert shown in message, message
    assert "a finite real number of volts" in message and "shape (1,)" in message, message


@pytest.mark.quick
@pytest.mark.parametrize(
    "action", [2.5, 2, np.float32(2.5), np.int64(2), np.array(2.5), np.array([2.5]), [2.5]]
)
def test_one_real_number_in_any_of_its_forms_is_an_action(action: Any) -> None:
    env = _env()
    env.step(action)
    assert env.rig.command_v == pytest.approx(float(np.asarray(action, dtype=float).reshape(-1)[0]), abs=2e-3)


@pytest.mark.quick
@pytest.mark.parametrize(
    ("actions", "shown"),
    [
        (np.full((2, 2), 2.5), "shape (2, 2)"),
        (np.full(3, 2.5), "shape (3,)"),
        (np.array([True, False]), "array([ True, False])"),
        (np.array(["2.5", "2.5"]), "array(['2.5', '2.5']"),
        ([2.5, None], "[2.5, None]"),
        (np.array([2.5, np.nan]), "array([2.5, nan])"),
        (2.5, "2.5"),
    ],
)
def test_the_vector_envs_actions_are_checked_as_one_per_env(actions: Any, shown: str) -> None:
    from twin.app.envs import BallBeamVectorEnv

    venv = BallBeamVectorEnv(2, duration_s=0.2)
    venv.reset(seed=0)
    with pytest.raises(ValueError) as info:
        venv.step(actions)
    message = str(info.value)
    assert shown in message and "shape (2,) or (2, 1)" in message, message
    venv.step(np.full((2, 1), 2.5))  # both forms step
    venv.step(np.full(2, 2.5))


@pytest.mark.quick
@pytest.mark.parametrize(
    ("options", "needle"),
    [
        ("x0_m=0.1", "options = 'x0_m=0.1': a dict of x0_m, theta0_rad, setpoint_m, noise_seed"),
        ({"x0_m": "0.1"}, "x0_m = '0.1': a number"),
        ({"x0_m": None}, "x0_m = None: a number"),
        ({"setpoint_m": 5.0}, "setpoint_m = 5.0 is off the track (|x| ≤ 0.323 m)"),
        ({"setpoint_m": [0.1]}, "setpoint_m = [0.1]: a number"),
        ({"noise_seed": 1.5}, "noise_seed = 1.5: a whole number"),
    ],
)
def test_bad_reset_options_are_refused_naming_the_option(options: Any, needle: str) -> None:
    from twin.app.envs import BallBeamEnv

    env = BallBeamEnv(duration_s=0.2)
    with pytest.raises(ValueError) as info:
        env.reset(seed=0, options=options)
    assert needle in str(info.value), str(info.value)


@pytest.mark.quick
@pytest.mark.parametrize(
    ("options", "needle"),
    [
        ({"params": 3}, "params = 3: a Parameters, or the path of a parameter file"),
        ({"params": {"ball": {}}}, "params = {'ball': {}}: a Parameters"),
        ({"spread": 3}, "spread = 3: the path of a spread file"),
        ({"calibration": 3}, "calibration = 3: the path of a calibration folder"),
        ({"x0_range_m": 0.1}, "x0_range_m = 0.1: expected (low, high)"),
        ({"stack": "2"}, "stack = '2'"),
        ({"starts": [(0.1,)]}, "starts = [(0.1,)]: pairs (x0_m, theta0_rad)"),
        ({"setpoint_range_m": (0.0, 0.4)}, "setpoint_range_m = 0.4 is off the track"),
        ({"criteria": "strict"}, "criteria = 'strict': a twin.verdict.Criteria"),
    ],
)
def test_bad_env_options_are_refused_naming_the_option(options: dict[str, Any], needle: str) -> None:
    from twin.app.envs import BallBeamEnv

    with pytest.raises(ValueError) as info:
        BallBeamEnv(**options)
    assert needle in str(info.value), str(info.value)


@pytest.mark.quick
def test_the_vector_envs_reset_options_are_one_value_or_one_per_env() -> None:
    from twin.app.envs import BallBeamVectorEnv

    venv = BallBeamVectorEnv(2, duration_s=0.2)
    with pytest.raises(
        ValueError, match=r"options 'x0_m' = \[0.1, 0.2, 0.3\]: one value for every env, or a sequence of 2"
    ):
        venv.reset(seed=0, options={"x0_m": [0.1, 0.2, 0.3]})
    with pytest.raises(ValueError, match="options = 'x0_m': a dict of x0_m"):
        venv.reset(seed=0, options="x0_m")  # type: ignore[arg-type]
    venv.reset(seed=0, options={"x0_m": [0.1, 0.2], "setpoint_m": 0.05})
