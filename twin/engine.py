"""The closed-loop engine: the one stepper that ``ballbeam run``, the live view and the reproduction use.

A ``ClosedLoop`` couples a simulated rig (twin.rig: the MuJoCo twin with its I/O chain or with ideal
converters, or the reference model) to either

* a ``Controller`` (twin.interface): the hardware contract, raw blocks in and a DAC command out at the
  DAQ's period, exactly as on the rig; or
* a ``StateLaw``: simulation only, terminal volts from the plant's true state at the law's own period
  (the thesis's chapter 4 designs, which assume all four states are measured). It never passes through
  the hardware contract.

Sequence (appendix A's buttons, twin.rig's start timing): ``start()`` reads the held rig's block and starts
the controller; each ``tick()`` reads the next block, runs the controller and writes its command. A tick
records the row the rig software logs (twin.log) plus the true state; ``run_closed_loop`` runs a whole
episode and computes the verdict (twin.verdict) once.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from twin.interface import Controller, DaqSample, Telemetry
from twin.log import THESIS_FIELDS, TRUTH_FIELDS, RunLog
from twin.parameters import Parameters
from twin.rig import PlantKind, RigError, SimRig, make_rig, whole_steps
from twin.verdict import Criteria, Verdict, evaluate

__all__ = [
    "Catalogue",
    "ClosedLoop",
    "ControllerError",
    "RunResult",
    "StateLaw",
    "run_closed_loop",
    "update_ticks",
]

# Two periods agree when they differ by less than this (they are typed as decimal seconds).
_PERIOD_TOLERANCE_S = 1e-12


@runtime_checkable
class StateLaw(Protocol):
    """A simulation-only law on the plant's true state (x, θ, ẋ, θ̇): terminal volts every ``period_s``."""

    name: str
    period_s: float

    @property
    def telemetry(self) -> Telemetry: ...

    def reset(self) -> None: ...

    def motor_volts(self, state: np.ndarray) -> float: ...


class Catalogue(Protocol):
    """The named controllers the application layer hands down (``controllers.registry`` is one)."""

    NAMES: tuple[str, ...]

    def make(self, name: str, params: Parameters | None = None) -> Controller | StateLaw: ...


class Pacer(Protocol):
    """Paces a run's ticks (wall clock, hardware): ``wait(k)`` before tick k, ``done()`` after it."""

    def wait(self, k: int) -> None: ...

    def done(self) -> None: ...


class ControllerError(RuntimeError):
    """A controller raised or returned something the I/O card cannot output; the message names the tick."""


def checked_start(controller: Controller, sample: DaqSample, where: str = "") -> None:
    """``controller.start(sample)``; a ``ControllerError`` naming the controller (and ``where``: the run)
    if it raises."""
    try:
        controller.start(sample)
    except Exception as exc:  # noqa: BLE001 - a user's controller may raise anything: report, do not crash
        place = f" {where}" if where else ""
        raise ControllerError(f"{controller.name}.start raised {type(exc).__name__}{place}: {exc}") from exc


def checked_update(controller: Controller, sample: DaqSample, where: str) -> float:
    """``controller.update(sample)`` as a DAC command in volts; a ``ControllerError`` naming the controller
    and ``where`` (the tick, the run) if it raises or returns anything but a finite number."""
    try:
        command = controller.update(sample)
    except Exception as exc:  # noqa: BLE001 - a user's controller may raise anything: report, do not crash
        raise ControllerError(f"{controller.name}.update raised {type(exc).__name__} {where}: {exc}") from exc
    if isinstance(command, bool) or not isinstance(command, (int, float, np.floating, np.integer)):
        raise ControllerError(
            f"{controller.name}.update returned {command!r} {where}: expected the DAC command in volts"
        )
    if not math.isfinite(command):
        raise ControllerError(
            f"{controller.name}.update returned {command!r} {where}: the DAC command must be a finite number of volts"
        )
    return float(command)


class RunResult:
    """One run's verdict and, when it was recorded, its log (``twin.batch.run_batch`` may keep verdicts only)."""

    def __init__(self, controller: str, log: RunLog | None, verdict: Verdict) -> None:
        self.controller = controller
        self._log = log
        self.verdict = verdict

    @property
    def recorded(self) -> bool:
        return self._log is not None

    @property
    def log(self) -> RunLog:
        if self._log is None:
            raise RuntimeError(f"{self.controller}: this run kept its verdict only (run_batch record=False)")
        return self._log

    def __repr__(self) -> str:
        return (
            f"RunResult(controller={self.controller!r}, recorded={self.recorded}, verdict={self.verdict!r})"
        )


_COLUMNS = tuple(name for name in THESIS_FIELDS + TRUTH_FIELDS if name != "ball_lost")
_ESTIMATE = slice(_COLUMNS.index("x1"), _COLUMNS.index("x4") + 1)
_TRUE_STATE = slice(_COLUMNS.index("true_x_m"), _COLUMNS.index("true_thetadot_rad_s") + 1)


class _Recorder:
    """The log's columns, grown in place (one row per tick, written in a few assignments: per tick, the
    cost is the number of numpy calls). ``cols`` are views of the table's columns."""

    def __init__(self, capacity: int) -> None:
        self.n = 0
        self.table = np.zeros((capacity, len(_COLUMNS)))
        self.cols = {name: self.table[:, j] for j, name in enumerate(_COLUMNS)}
        self.lost = np.zeros(capacity, dtype=bool)
        self.peak_theta = np.zeros(capacity)

    def _grow(self) -> None:
        self.table = np.concatenate([self.table, np.zeros_like(self.table)])
        self.cols = {name: self.table[:, j] for j, name in enumerate(_COLUMNS)}
        self.lost = np.concatenate([self.lost, np.zeros_like(self.lost)])
        self.peak_theta = np.concatenate([self.peak_theta, np.zeros_like(self.peak_theta)])

    def add(self, sample: DaqSample, command_v: float, tel: Telemetry, rig: SimRig) -> None:
        if self.n == len(self.lost):
            self._grow()
        k = self.n
        row = self.table[k]
        # timem, datam1, datam2, aout, x1…x4, u, uhesap, true_time_s, true state, motor_volts_v (_COLUMNS)
        row[:4] = (sample.time_s, sample.ball_v, sample.angle_v, command_v)
        row[_ESTIMATE] = tel.estimate
        row[8:11] = (tel.u, tel.u_computed, rig.time_s)
        row[_TRUE_STATE] = rig.true_state()
        row[-1] = rig.motor_volts_v
        self.lost[k] = rig.ball_lost
        block = rig.last_block
        if block is not None:
            on = block.on_track
            if on.all():  # the common case: no mask to apply
                self.peak_theta[k] = float(np.max(np.abs(block.theta_rad)))
            elif on.any():
                self.peak_theta[k] = float(np.max(np.abs(block.theta_rad[on])))
        self.n += 1

    def log(self) -> RunLog:
        n = self.n
        return RunLog(
            **{name: col[:n].copy() for name, col in self.cols.items()}, ball_lost=self.lost[:n].copy()
        )


class ClosedLoop:
    """One closed-loop run on a simulated rig, tick by tick (the rig must already be ``reset``)."""

    def __init__(
        self,
        rig: SimRig,
        controller: Controller | StateLaw,
        *,
        record: bool = True,
        record_limit: int | None = None,
    ) -> None:
        """``record_limit``: the most ticks recorded (a long live session keeps its first ones and its
        memory bounded); ``None`` records every tick."""
        self.rig = rig
        self.controller = controller
        self.is_state_law = isinstance(controller, StateLaw) and not isinstance(controller, Controller)
        if self.is_state_law:
            law_steps = whole_steps(
                controller.period_s, rig.params.physics.timestep_s, f"{controller.name} period_s"
            )
            tick_steps = whole_steps(rig.period_s, rig.params.physics.timestep_s, "daq.period_s")
            if law_steps < 1 or tick_steps % law_steps:
                raise RigError(
                    f"{controller.name}: period_s = {controller.period_s!r} s must divide daq.period_s = "
                    f"{rig.period_s!r} s into whole physics steps"
                )
        elif abs(controller.period_s - rig.period_s) > _PERIOD_TOLERANCE_S:
            raise RigError(
                f"{controller.name}: period_s = {controller.period_s!r} s does not match the DAQ's "
                f"daq.period_s = {rig.period_s!r} s; set daq.period_s to the controller's period (a parameter "
                f"file) or change the controller"
            )
        self.recorder = _Recorder(256) if record else None
        self.record_limit = record_limit
        self.last_sample: DaqSample | None = None
        self.command_v = rig.command_v
        self.started = False

    @property
    def name(self) -> str:
        return self.controller.name

    @property
    def recording(self) -> bool:
        """Whether the next tick is recorded (recording on and the limit not reached)."""
        r = self.recorder
        return r is not None and (self.record_limit is None or r.n < self.record_limit)

    def start(self) -> None:
        """The software's Start/Clear Buffer phase: the held rig's block starts the controller."""
        sample = self.rig.read()
        if self.is_state_law:
            try:
                self.controller.reset()  # type: ignore[union-attr]
            except Exception as exc:  # noqa: BLE001 - report, do not crash
                raise ControllerError(f"{self.name}.start raised {type(exc).__name__}: {exc}") from exc
        else:
            checked_start(self.controller, sample)  # type: ignore[arg-type]
        self.last_sample = sample
        self.started = True
        if self.recorder is not None and self.recording:
            self.recorder.add(sample, self.rig.command_v, self.controller.telemetry, self.rig)

    def tick(self) -> None:
        """One control period: read a block, run the controller, write its command."""
        if not self.started:
            self.start()
        rig = self.rig
        if self.is_state_law:
            law = self.controller
            if rig.ticks < 2:  # block 0 ends when the first command reaches the amplifier
                sample = rig.read()
            else:
                sample = rig.read_with_state_law(self._law_volts, law.period_s)
            command = rig.command_v
        else:
            sample = rig.read()
            command = checked_update(
                self.controller,  # type: ignore[arg-type]
                sample,
                f"at tick k = {rig.ticks} (t = {sample.time_s:.3f} s)",
            )
            rig.write(command)
        self.last_sample = sample
        self.command_v = float(command)
        if self.recorder is not None and self.recording:
            self.recorder.add(sample, self.command_v, self.controller.telemetry, rig)

    def _law_volts(self, state: np.ndarray) -> float:
        try:
            volts = float(self.controller.motor_volts(state))  # type: ignore[union-attr]
        except Exception as exc:  # noqa: BLE001
            raise ControllerError(
                f"{self.name} raised {type(exc).__name__} at t = {self.rig.time_s:.3f} s: {exc}"
            ) from exc
        if not math.isfinite(volts):
            raise ControllerError(f"{self.name} returned {volts!r} volts at t = {self.rig.time_s:.3f} s")
        return volts

    def log(self) -> RunLog:
        if self.recorder is None:
            raise RuntimeError("this closed loop was built with record=False")
        return self.recorder.log()

    def verdict(self, x0_m: float, criteria: Criteria | None = None, *, x_ref_m: float = 0.0) -> Verdict:
        """The verdict of the run so far (from the recorded true state), judged about the ball position
        ``x_ref_m`` (a setpoint; the offsets and the settling band are measured from it)."""
        if self.recorder is None:
            raise RuntimeError("this closed loop was built with record=False")
        r, n = self.recorder, self.recorder.n
        return judge(
            self.rig.params,
            r.cols["true_time_s"][:n],
            r.cols["true_x_m"][:n],
            r.cols["true_theta_rad"][:n],
            r.cols["motor_volts_v"][:n],
            r.peak_theta[:n],
            x0_m=x0_m,
            ball_lost_time_s=self.rig.ball_lost_time_s,
            criteria=criteria,
            x_ref_m=x_ref_m,
        )


def judge(
    params: Parameters,
    t_s: np.ndarray,
    x_m: np.ndarray,
    theta_rad: np.ndarray,
    motor_volts_v: np.ndarray,
    peak_abs_theta_rad: np.ndarray,
    *,
    x0_m: float,
    ball_lost_time_s: float | None,
    criteria: Criteria | None = None,
    x_ref_m: float = 0.0,
) -> Verdict:
    """A run's verdict from its recorded ticks on the rig of ``params`` (its rails and stops), judged about
    the ball position ``x_ref_m``: the single run's and the batch's one call of ``twin.verdict.evaluate``."""
    return evaluate(
        t_s,
        x_m - x_ref_m,
        theta_rad,
        motor_volts_v,
        peak_abs_theta_rad,
        x0_m=x0_m - x_ref_m,
        ball_lost_time_s=ball_lost_time_s,
        rail_v=params.amplifier.rail_v,
        stop_angle_rad=params.beam.stop_angle_rad,
        criteria=criteria,
    )


def update_ticks(duration_s: float, params: Parameters) -> int:
    """Number of ``update`` ticks so that the last block ends at or after ``duration_s`` after release."""
    free, period = params.start.free_run_s, params.daq.period_s
    return 1 + max(0, math.ceil((duration_s - free) / period - 1e-9))


def run_closed_loop(
    controller: Controller | StateLaw,
    *,
    x0_m: float,
    theta0_rad: float,
    duration_s: float = 10.0,
    seed: int = 0,
    noise: bool = True,
    params: Parameters | None = None,
    plant: PlantKind = "twin",
    ideal_sensors: bool = False,
    stop_when_lost: bool = True,
    criteria: Criteria | None = None,
    pacer: Pacer | None = None,
) -> RunResult:
    """Run ``controller`` on a fresh simulated rig from (x0, θ0) at rest for ``duration_s`` after release.

    The rig is held while the controller's ``start`` reads it, released at t = 0 and driven from
    t = ``start.free_run_s`` on (twin.rig). Initial velocities are zero; the controller's observer starts
    from zero velocity, as on the rig. ``stop_when_lost`` ends the run at the tick the ball is lost."""
    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s = {duration_s!r} must be a positive number of seconds")
    p = params or Parameters()
    rig = make_rig(p, plant=plant, ideal_sensors=ideal_sensors, seed=seed, noise=noise)
    rig.reset(x0_m, theta0_rad)
    loop = ClosedLoop(rig, controller)
    loop.start()
    for k in range(update_ticks(duration_s, rig.params)):
        if pacer is not None:
            pacer.wait(k)
        loop.tick()
        if pacer is not None:
            pacer.done()
        if stop_when_lost and rig.ball_lost:
            break
    return RunResult(controller=controller.name, log=loop.log(), verdict=loop.verdict(x0_m, criteria))
