"""Named controllers on the twin: every one runs; the thesis's stated behaviour where the twin should show it."""

import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.integrate

from controllers import registry
from controllers import thesis_numbers as T
from twin.parameters import Parameters
from twin.reference import ReferenceModel
from twin.runner import run_closed_loop


@pytest.mark.parametrize("name", registry.NAMES)
def test_every_named_controller_runs_on_the_twin(name: str) -> None:
    controller = registry.make(name)
    assert controller.name == name
    run = run_closed_loop(controller, x0_m=0.05, theta0_rad=0.02, duration_s=1.0, seed=0)
    log = run.log
    assert np.all(np.isfinite(log.aout)) and np.all(np.isfinite(log.true_x_m))
    assert np.all(np.abs(log.motor_volts_v) <= 12.0)
    assert set(run.metrics) >= {
        "settled",
        "settling_time_s",
        "ball_lost",
        "ball_lost_time_s",
        "peak_motor_voltage_v",
        "peak_theta_rad",
        "final_x_m",
        "final_theta_rad",
    }


def test_unknown_controller_is_named_in_the_error() -> None:
    with pytest.raises(KeyError, match="unknown controller 'pid'"):
        registry.make("pid")


def _reference_settling_time(x0: float) -> float:
    """§4.2's loop on the analytic reference model: continuous V = −K x, the same 2 % (4 mm) criterion."""
    ref = ReferenceModel(Parameters())
    k = T.SF_CONT_K[0]
    sol = scipy.integrate.solve_ivp(
        lambda t, s: ref.derivative(s, float(-k @ s), "voltage"),
        (0.0, 8.0),
        [x0, 0.3, 0.0, 0.0],
        max_step=1e-3,
        rtol=1e-8,
    )
    outside = np.flatnonzero(np.abs(sol.y[0]) > 0.004)
    return float(sol.t[outside[-1] + 1])


@pytest.mark.parametrize("x0", [0.2, -0.2])
def test_thesis_sf_continuous_settles_as_the_thesis_says(x0: float) -> None:
    """Figs 4.4/4.5: "reaches the desired value in 2.5–3 s". Twin: 2.44 s and 2.96 s (2 % criterion), the
    reference model the same to 10 ms; the thesis read its 2.5 off a plot."""
    run = run_closed_loop(registry.make("thesis-sf-continuous"), x0_m=x0, theta0_rad=0.3, duration_s=6.0)
    ts = run.metrics["settling_time_s"]
    assert run.metrics["settled"]
    assert 2.4 <= ts <= 3.0
    assert ts == pytest.approx(_reference_settling_time(x0), abs=0.02)


def test_printed_chapter5_state_feedback_fails_as_its_observer_is_unstable() -> None:
    """§5.2.1 as printed (G = [[4, −8], [−15, 12]]): the observer diverges and the ball is lost."""
    run = run_closed_loop(registry.make("thesis-sf"), x0_m=0.2, theta0_rad=0.3, duration_s=5.0)
    assert run.metrics["ball_lost"]


@pytest.mark.parametrize("name", ["sf", "lqr", "appendix-sf"])
def test_redone_designs_bring_the_ball_back_from_the_chapter_4_start(name: str) -> None:
    run = run_closed_loop(registry.make(name), x0_m=0.2, theta0_rad=0.3, duration_s=10.0, seed=2)
    assert not run.metrics["ball_lost"]
    assert abs(run.metrics["final_x_m"]) < 0.01


def test_cli_run_prints_the_verdict_and_saves_the_log(tmp_path) -> None:
    log = tmp_path / "data_file.mat"
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "run",
            "--controller",
            "appendix-clp",
            "--x0",
            "0.1",
            "--theta0",
            "0.1",
            "--duration",
            "3",
            "--seed",
            "4",
            "--log",
            str(log),
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    verdict = json.loads(out.stdout)
    for key in (
        "settled",
        "settling_time_s",
        "ball_lost",
        "ball_lost_time_s",
        "peak_motor_voltage_v",
        "peak_theta_rad",
        "final_x_m",
        "final_theta_rad",
    ):
        assert key in verdict
    assert verdict["ball_lost"] is False and log.exists()
    again = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "run",
            "--controller",
            "appendix-clp",
            "--x0",
            "0.1",
            "--theta0",
            "0.1",
            "--duration",
            "1",
            "--log",
            str(log),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert again.returncode == 2 and "not overwritten" in again.stderr
