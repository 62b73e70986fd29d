"""Closed-loop runs of a controller on the twin, lock-step (as fast as the computer goes), with a log and
the verdict figures."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.interface import Controller
from twin.log import THESIS_FIELDS, TRUTH_FIELDS, RunLog
from twin.parameters import Parameters
from twin.rig import TwinRig

__all__ = ["RunResult", "run_closed_loop", "metrics"]

SETTLE_WINDOW_S = 2.0  # "settled": |x| < 5 mm and |θ| < 0.02 rad over the last 2 s
SETTLED_X_M = 5e-3
SETTLED_THETA_RAD = 0.02
SETTLING_FRACTION = 0.02  # settling time: last time |x| exceeded 2 % of |x0| (at least 4 mm)
SETTLING_FLOOR_M = 4e-3


@dataclass
class RunResult:
    controller: str
    log: RunLog
    metrics: dict[str, Any]


def metrics(log: RunLog, x0_m: float, duration_s: float) -> dict[str, Any]:
    """The verdict figures of one run, from the twin's true state."""
    t, x, th = log.true_time_s, log.true_x_m, log.true_theta_rad
    lost_idx = np.flatnonzero(log.ball_lost)
    lost = bool(lost_idx.size)
    lost_time = float(t[lost_idx[0]]) if lost else None
    on_track = slice(0, lost_idx[0]) if lost else slice(None)
    tail = t >= t[-1] - SETTLE_WINDOW_S + 1e-9
    settled = (
        not lost
        and t[-1] >= SETTLE_WINDOW_S
        and bool(np.all(np.abs(x[tail]) < SETTLED_X_M))
        and bool(np.all(np.abs(th[tail]) < SETTLED_THETA_RAD))
    )
    threshold = max(SETTLING_FRACTION * abs(x0_m), SETTLING_FLOOR_M)
    outside = np.flatnonzero(np.abs(x) > threshold)
    if lost or (outside.size and outside[-1] == len(x) - 1):
        settling_time = None
    else:
        settling_time = float(t[outside[-1] + 1]) if outside.size else 0.0
    return {
        "settled": settled,
        "settling_time_s": settling_time,
        "settling_threshold_m": threshold,
        "ball_lost": lost,
        "ball_lost_time_s": lost_time,
        "peak_motor_voltage_v": float(np.max(np.abs(log.motor_volts_v))),
        "peak_theta_rad": float(np.max(np.abs(th[on_track]))),
        "final_x_m": float(x[-1]),
        "final_theta_rad": float(th[-1]),
        "duration_s": duration_s,
    }


def run_closed_loop(
    controller: Controller,
    *,
    x0_m: float,
    theta0_rad: float,
    duration_s: float = 10.0,
    seed: int = 0,
    noise: bool = True,
    params: Parameters | None = None,
) -> RunResult:
    """Run ``controller`` on a fresh twin from (x0, θ0) at rest, as the rig software runs: one block to
    start (DAC at 2.5 V), then read → update → write every period for ``duration_s``.

    Initial velocities are zero; the controller's observer starts from zero velocity, as on the rig."""
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s = {duration_s!r} must be a positive number of seconds")
    p = params or Parameters()
    if abs(p.daq.period_s - controller.period_s) > 1e-12:
        p = p.with_overrides({"daq.period_s": controller.period_s})
    rig = TwinRig(p, seed=seed, noise=noise)
    rig.reset(x0_m, theta0_rad)
    ticks = int(round(duration_s / rig.period_s))
    n = ticks + 1
    cols = {name: np.zeros(n) for name in THESIS_FIELDS + TRUTH_FIELDS if name != "ball_lost"}
    lost = np.zeros(n, dtype=bool)
    uses_truth = controller.uses_true_state

    def record(k: int, sample, command_v: float) -> None:
        tel = controller.telemetry
        truth = rig.true_state()
        cols["timem"][k], cols["datam1"][k], cols["datam2"][k] = sample.time_s, sample.ball_v, sample.angle_v
        cols["aout"][k] = command_v
        cols["x1"][k], cols["x2"][k], cols["x3"][k], cols["x4"][k] = tel.estimate
        cols["u"][k], cols["uhesap"][k] = tel.u, tel.u_computed
        cols["true_time_s"][k] = rig.time_s
        (
            cols["true_x_m"][k],
            cols["true_theta_rad"][k],
            cols["true_xdot_m_s"][k],
            cols["true_thetadot_rad_s"][k],
        ) = truth
        cols["motor_volts_v"][k] = rig.motor_volts_v
        lost[k] = rig.ball_lost

    sample = rig.read()
    controller.start(sample, rig.true_state() if uses_truth else None)
    record(0, sample, rig.command_v)
    for k in range(1, n):
        sample = rig.read()
        command = controller.update(sample, rig.true_state() if uses_truth else None)
        rig.write(command)
        record(k, sample, command)
    log = RunLog(**cols, ball_lost=lost)
    return RunResult(controller=controller.name, log=log, metrics=metrics(log, x0_m, duration_s))
