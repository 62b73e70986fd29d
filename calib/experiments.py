"""Identification experiments: the closed-loop runs that make a good log for calibration.

A good log moves the ball over a good part of the beam (the ball channel is what separates the motor's
resistance from the beam's inertia), tilts the beam both ways, and excites the loop at more than its own
frequencies. Each experiment is a hardware ``Controller`` (raw blocks in, DAC volts out): the stabilising
``lqr`` of the registry, a setpoint programme for the ball, and a seeded PRBS dither added to the command.
The same object runs on the rig as on the twin; ``run_experiment`` runs it on the twin and returns the log
in the thesis software's format.

    square   ball setpoint ±0.10 m, 5 s each side, plus a ±0.5 V (motor) PRBS dither: recommended
    dither   regulation at the centre with a ±1 V PRBS dither (when the ball must not travel)
    sweep    ball setpoint sine, 0.10 m, frequency sweeping 0.05 → 0.4 Hz, plus the ±0.5 V dither
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calib.logs import RigLog
from controllers import registry
from controllers.loop import LoopController
from twin import converters
from twin.engine import RunResult
from twin.interface import Controller, DaqSample, Setpoint
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop

__all__ = [
    "EXPERIMENTS",
    "RECOMMENDED",
    "STUDY_FIT",
    "STUDY_START",
    "Experiment",
    "ExcitedController",
    "make_controller",
    "run_experiment",
]

RECOMMENDED = "square"
# What the calibration studies fit (tests/test_calib_*.py, scripts/calib_coverage.py, scripts/calib_long.py):
# what drifts or is unknown on a rig — the motor, the beam, its bearing's viscous friction, the zeroing.
STUDY_FIT = (
    "motor.resistance_ohm",
    "beam.inertia_pivot_kgm2",
    "beam.pivot_damping_nm_s_per_rad",
    "angle_sensor.zeroing_error_rad",
)
# Their start: the thesis's rig with 1e-3 N·m·s/rad of pivot damping (the thesis neglects it: 0, the bound).
STUDY_START = {"beam.pivot_damping_nm_s_per_rad": 1e-3}


@dataclass(frozen=True)
class Experiment:
    name: str
    description: str
    setpoint_m: Callable[[float], float]  # ball setpoint against time since the first command
    dither_motor_v: float  # PRBS amplitude, as volts at the motor
    dither_hold_ticks: int  # the PRBS holds each level this many ticks


def _square(t: float) -> float:
    return 0.10 if (t // 5.0) % 2 == 0 else -0.10


def _sweep(t: float) -> float:
    # Linear chirp 0.05 → 0.4 Hz over 60 s, then repeating.
    f0, f1, span = 0.05, 0.4, 60.0
    tt = t % span
    return 0.10 * math.sin(2 * math.pi * (f0 * tt + 0.5 * (f1 - f0) / span * tt * tt))


EXPERIMENTS: dict[str, Experiment] = {
    e.name: e
    for e in (
        Experiment(
            "square",
            "ball setpoint ±0.10 m, 5 s each side, ±0.5 V PRBS dither (recommended)",
            _square,
            0.5,
            2,
        ),
        Experiment("dither", "regulation at the centre, ±1 V PRBS dither", lambda t: 0.0, 1.0, 2),
        Experiment(
            "sweep", "ball setpoint sine 0.10 m sweeping 0.05 → 0.4 Hz, ±0.5 V PRBS dither", _sweep, 0.5, 2
        ),
    )
}


class ExcitedController(Controller):
    """A stabilising controller with a ball-setpoint programme and a PRBS dither on its command."""

    def __init__(self, inner: LoopController, experiment: Experiment, seed: int) -> None:
        super().__init__()
        if not isinstance(inner, Setpoint):
            raise ValueError(f"{inner.name} has no ball setpoint: an experiment needs one")
        self.inner = inner
        self._setpoint: Setpoint = inner
        self.experiment = experiment
        self.name = f"{inner.name}+{experiment.name}"
        self.period_s = inner.period_s
        self.seed = seed
        self._rng = np.random.default_rng(seed)

    def start(self, sample: DaqSample) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._ticks = 0
        self._level = 0.0
        self._setpoint.setpoint_m = self.experiment.setpoint_m(0.0)
        self.inner.start(sample)
        self.telemetry = self.inner.telemetry

    def update(self, sample: DaqSample) -> float:
        e = self.experiment
        self._setpoint.setpoint_m = e.setpoint_m(self._ticks * self.period_s)
        command = self.inner.update(sample)
        if self._ticks % e.dither_hold_ticks == 0:
            self._level = float(self._rng.choice((-1.0, 1.0)))
        self._ticks += 1
        sw = self.inner.software
        dithered = command + self._level * e.dither_motor_v / sw.command_gain_v_per_v
        self.telemetry = self.inner.telemetry
        return float(converters.clip_command_v(dithered, sw))


def make_controller(name: str, params: Parameters, seed: int = 0) -> ExcitedController:
    """The experiment ``name`` as a hardware controller (the registry's ``lqr`` designed for ``params``)."""
    if name not in EXPERIMENTS:
        raise ValueError(f"unknown experiment {name!r}; known: {', '.join(EXPERIMENTS)}")
    inner = registry.make("lqr", params)
    assert isinstance(inner, LoopController)
    return ExcitedController(inner, EXPERIMENTS[name], seed)


def run_experiment(
    name: str,
    params: Parameters | None = None,
    *,
    duration_s: float = 60.0,
    seed: int = 0,
    x0_m: float = 0.0,
    theta0_rad: float = 0.0,
) -> RunResult:
    """Run the experiment on the twin (full I/O chain, noise seeded by ``seed``) with ``params`` as the rig.

    The controller is designed for the thesis's nominal rig, as a user's would be before calibration."""
    p = params or Parameters()
    controller = make_controller(name, Parameters().with_overrides({"daq.period_s": p.daq.period_s}), seed)
    return run_closed_loop(
        controller, x0_m=x0_m, theta0_rad=theta0_rad, duration_s=duration_s, seed=seed, params=p
    )


def replay_rms(
    log: RigLog, name: str, seed: int, params: Parameters, *, x0_m: float = 0.0, theta0_rad: float = 0.0
) -> dict[str, float]:
    """Closed-loop replay: the experiment that made ``log`` (same controller, setpoints and dither seed) run
    on the twin with ``params`` and the sensor noise off; the RMS difference of the readings the software
    makes of the two (ball m by eq 6.3.1, beam rad by eq 6.2.10), tick by tick."""
    quiet = params.with_overrides({"ball_sensor.noise_enabled": False})
    replay = run_experiment(
        name, quiet, duration_s=log.duration_s, seed=seed, x0_m=x0_m, theta0_rad=theta0_rad
    )
    n = min(log.ticks, replay.log.k - 1)
    sw = params.software
    sim_b = converters.ball_position_m(replay.log.datam1[1 : n + 1], sw)
    sim_a = converters.beam_angle_rad(replay.log.datam2[1 : n + 1], sw)
    rec_b = converters.ball_position_m(log.ball_v[:n], sw)
    rec_a = converters.beam_angle_rad(log.angle_v[:n], sw)
    return {
        "ball_m": float(np.sqrt(np.mean((sim_b - rec_b) ** 2))),
        "angle_rad": float(np.sqrt(np.mean((sim_a - rec_a) ** 2))),
        "ticks": float(n),
    }
