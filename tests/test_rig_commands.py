"""A user's rig written from the manual alone (docs/rigs.md's tube, lever, MG996R, potentiometer, VL53L0X and
Uno: no preset) through the commands a user of it runs: each either does its job on that rig or refuses with
a message naming why (never a traceback, never the thesis's volts applied to another board's units)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from twin.app.cli import main
from twin.log import RunLog, load_mat
from twin.parts.description import rig_from_text
from twin.parts.measured import measured_channels
from twin.verdict import evaluate_measured

ROOT = Path(__file__).parents[1]


def _tube_rig_text() -> str:
    """The manual's worked description (the block naming ``part = "tube"``), as a user would save it."""
    blocks = re.findall(r"```toml\n(.*?)```", (ROOT / "docs" / "rigs.md").read_text(), re.S)
    (text,) = [b for b in blocks if 'part = "tube"' in b]
    return text


@pytest.fixture(scope="module")
def tube(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rig") / "tube-rig.toml"
    path.write_text(_tube_rig_text())
    rig_from_text(path.read_text(), origin=str(path))  # it loads
    return path


@pytest.fixture(scope="module")
def held_log(tube: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("run") / "run.mat"
    code = main(
        ["run", "--rig-file", str(tube), "--controller", "rig-lqg", "--x0", "0.05", "--theta0", "0"]
        + ["--duration", "8", "--log", str(out)]
    )
    assert code == 0 and out.is_file()
    return out


def test_judge_reads_the_rigs_log_in_its_boards_units(
    tube: Path, held_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The log's command is the servo pulse (µs) and its ball channel the VL53L0X's mm: judged through the
    parts' conversions, not refused as volts outside the PCI-1712's DAC. The ball was kept, and the measured
    steady x is the true one within the sensor's noise (its noise is what the verdict's band sees too)."""
    capsys.readouterr()
    main(["judge", "--rig-file", str(tube), "--json", str(held_log)])
    judged = json.loads(capsys.readouterr().out)
    assert judged["ball_lost"] is False
    log = load_mat(held_log)
    true_steady_m = float(np.mean(log.x1[-100:]))
    assert judged["steady_x_m"] == pytest.approx(true_steady_m, abs=0.004)
    # the peak control is the servo's target angle (rad), within its ±60° travel
    assert 0 < judged["peak_motor_voltage_v"] < 1.0472


def test_a_lost_ball_is_judged_lost_from_the_readings_alone(tube: Path) -> None:
    """A servo starved of its supply (0.1 V: it cannot move the beam) and the ball released off centre on the
    tilted tube: it rolls out, and the rig's log goes on (as a real rig's does). The measured verdict finds the
    loss from the readings alone (the sensor reads no ball, or x at the track's end) within 0.25 s of the true
    time."""
    from controllers.rig_lqg import rig_lqg
    from twin.rigs.sim import run_closed_loop

    params = rig_from_text(tube.read_text(), origin=str(tube)).with_overrides({"servo.supply_v": 0.1})
    result = run_closed_loop(
        rig_lqg(params), x0_m=0.12, theta0_rad=0.04, duration_s=4.0, params=params, stop_when_lost=False
    )
    true_s = result.verdict.ball_lost_time_s
    assert result.verdict.ball_lost and true_s is not None
    log: RunLog = result.log
    judged = evaluate_measured(log, params, channels=measured_channels(params))
    assert judged.ball_lost and judged.ball_lost_time_s is not None
    assert abs(judged.ball_lost_time_s - true_s) < 0.25


def test_the_commands_run_on_the_rig_or_say_why(
    tube: Path, held_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = ["--rig-file", str(tube)]
    assert main(["params", *rig]) == 0
    assert "vl53l0x" in capsys.readouterr().out
    sweep = ["sweep", *rig, "--controller", "rig-lqg", "--x0", "-0.05:0.05:2", "--theta0", "0:0:1"]
    assert main([*sweep, "--duration", "3", "--out", str(tmp_path / "sw")]) in (0, 1)
    assert (tmp_path / "sw" / "sweep.json").is_file()
    spread = tmp_path / "spread.toml"
    spread.write_text("[servo]\nstall_torque_nm = { rel_sd = 0.1 }\n")
    mc = ["montecarlo", *rig, "--controller", "rig-lqg", "--n", "2", "--x0", "0.05", "--theta0", "0"]
    assert main([*mc, "--duration", "3", "--spread", str(spread), "--out", str(tmp_path / "mc")]) in (0, 1)
    assert (tmp_path / "mc" / "montecarlo.json").is_file()
    assert main(["export-fmu", *rig, "--out", str(tmp_path / "tube.fmu")]) == 0
    capsys.readouterr()
    # the reference model's linearization about the control that holds the level beam, in the servo's rad
    assert main(["linearize", *rig, "--source", "reference", "--input", "voltage", "--json"]) == 0
    lin = json.loads(capsys.readouterr().out)
    assert lin["A"][3][1] < 0 and lin["B"][3][0] > 0  # the servo pulls the beam toward its target
    # the MuJoCo linearization of this rig does not separate its modes: said in one line, exit 1
    assert main(["linearize", *rig, "--input", "voltage"]) == 1
    assert "cannot be linearized here" in capsys.readouterr().err
    # a torque input has no meaning on a servo rig: refused naming the option
    assert main(["linearize", *rig]) == 2
    assert "--input torque" in capsys.readouterr().err
    spec = tmp_path / "spec.toml"
    spec.write_text('[requirements]\nstays_on = "always[0:3] (abs(x_m) < 0.14)"\n')
    search = ["--controller", "rig-lqg", "--spec", str(spec), "--spread", str(spread), "--duration", "3"]
    falsify = ["falsify", *rig, *search, "--budget", "8", "--population", "4", "--x0", "-0.1:0.1"]
    assert main([*falsify, "--theta0", "-0.03:0.03", "--out", str(tmp_path / "fz")]) == 0
    assert json.loads((tmp_path / "fz" / "falsify.json").read_text())["runs_spent"] == 8
    certify = ["certify", *rig, *search, "--x0", "-0.05:0.05", "--theta0", "-0.02:0.02", "--guarantee", "0.5"]
    assert main([*certify, "--confidence", "0.5", "--out", str(tmp_path / "cert")]) == 0
    # the commands whose model is the thesis rig's identification refuse the rig, saying what to use instead
    for command in (
        ["compare", "--out", str(tmp_path / "cmp"), str(held_log)],
        ["calibrate", "--fit", "servo.no_load_speed_rad_s", str(held_log)],
        ["shadow", "--rig", "udp://127.0.0.1:9"],
    ):
        capsys.readouterr()
        assert main([*command, *rig]) == 2, command
        err = capsys.readouterr().err
        assert "the thesis rig's identification model" in err and "parts.actuator = 'hobby_servo'" in err


@pytest.mark.quick
def test_a_rigs_measured_channels_are_its_parts_conversions() -> None:
    """The thesis's rig has none (its own eq 6.3.1, 6.2.10 and output stage); Open Ball & Beam's: the VL53L0X's
    inverse curve (its out-of-range code carries no position), no angle, the servo's target for a pulse."""
    from twin.parameters import Parameters
    from twin.parts import rig_parts
    from twin.parts.description import preset

    assert measured_channels(Parameters()) is None
    obb = preset("open-ball-and-beam")
    channels = measured_channels(obb)
    assert channels is not None and channels.theta_rad is None and channels.angle_step_rad == 0.0
    parts = rig_parts(obb)
    assert parts.ball_sensor.position_of is not None and parts.actuator.control_of is not None
    x = channels.x_m(np.array([142.3, 8190.0]))
    assert x[0] == parts.ball_sensor.position_of(obb)(142.3) and np.isnan(x[1])
    control_of = parts.actuator.control_of(obb)
    assert channels.control(np.array([1500.0]))[0] == control_of(1500.0)
    limits = parts.io_board.output_range(obb)
    assert channels.control_limit == max(abs(control_of(limits.low)), abs(control_of(limits.high)))
