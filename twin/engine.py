"""The closed-loop engine: the one loop every run goes through (docs/design.md, "One loop, many rigs").

A ``ClosedLoop`` couples any rig behind the hardware contract (``twin.interface.Rig``: a simulated rig of
twin.rigs.sim, a remote one of twin.rigs.remote, an I/O card) to either

* a ``Controller`` (twin.interface): raw blocks in and a DAC command out at the DAQ's period, exactly as on
  the rig — in process, or a host for something foreign (the wire's client, an environment's agent); or
* a ``StateLaw``: simulation only, terminal volts from the plant's true state at the law's own period
  (the thesis's chapter 4 designs, which assume all four states are measured). It never passes through
  the hardware contract and needs a rig with the true state (``TrueState``).

Sequence (appendix A's buttons, twin.rigs.sim's start timing): ``start()`` reads the held rig's block and
starts the controller; each ``tick()`` reads the next block, runs the controller and writes its command;
``run()`` is the episode. A tick records the row the rig software logs (twin.log), plus the true state when
the rig offers it; the verdict (twin.verdict) is computed once, from the true state or the measured volts.
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from array import array
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any, Protocol, runtime_checkable

import numpy as np

from twin.firmware import Firmware
from twin.guard import Fault, Guard, describe, install_interrupt_handler, is_interrupt, safe_name
from twin.interface import CommandRange, Controller, DaqSample, Rig, RigEnded, RigError, Telemetry
from twin.log import THESIS_FIELDS, TRUTH_FIELDS, RunLog
from twin.parameters import Parameters
from twin.physics import PhysicsBlock, whole_steps
from twin.realtime import TickTiming, arrival_timing
from twin.verdict import Criteria, Trace, Verdict, evaluate, evaluate_measured

__all__ = [
    "Catalogue",
    "CatalogueEntry",
    "ClosedLoop",
    "ControllerError",
    "ENDED_BALL_LOST",
    "ENDED_LAST_SAMPLE",
    "ENDED_TICKS",
    "RunResult",
    "Scenario",
    "TrueState",
    "block_peak_abs_theta_rad",
    "StateLaw",
    "check_period_s",
    "checked_start",
    "checked_update",
    "run_on_rig",
    "update_ticks",
]


@dataclass(frozen=True)
class Scenario:
    """What happens in a run beyond its start: a flick of the ball (a velocity kick of ``flick_speed_m_s`` along
    the beam, as the live view's Flick, at the first tick boundary ``flick_time_s`` or more after release:
    after ⌈flick_time_s / period⌉ ticks; a kick of 0 is none) and a setpoint (for a controller that declares one,
    ``twin.interface.Setpoint``; the verdict is then judged about it)."""

    flick_time_s: float | None = None
    flick_speed_m_s: float = 0.0
    setpoint_m: float | None = None

    def __post_init__(self) -> None:
        for name in ("flick_time_s", "flick_speed_m_s", "setpoint_m"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"{name} = {value!r} must be a finite number")
        if self.flick_time_s is not None and self.flick_time_s < 0:
            raise ValueError(f"flick_time_s = {self.flick_time_s!r}: a time after release (≥ 0 s)")

    def flick_tick(self, period_s: float) -> int | None:
        """The ticks run before the flick (None: no flick)."""
        if self.flick_time_s is None:
            return None
        return max(0, math.ceil(self.flick_time_s / period_s - 1e-9))


# Two periods agree when they differ by less than this (they are typed as decimal seconds).
_PERIOD_TOLERANCE_S = 1e-12
_MAX_FLOAT = sys.float_info.max


@runtime_checkable
class StateLaw(Protocol):
    """A simulation-only law on the plant's true state (x, θ, ẋ, θ̇): terminal volts every ``period_s``."""

    name: str
    period_s: float

    @property
    def telemetry(self) -> Telemetry: ...

    def reset(self) -> None: ...

    def motor_volts(self, state: np.ndarray) -> float: ...


@dataclass(frozen=True)
class CatalogueEntry:
    """One named controller as data: what the CLI lists and the live view offers, without building it."""

    name: str
    # designs and builds one for the given rig
    build: Callable[[Parameters], Controller | StateLaw | Firmware]
    description: str  # one line: what it is and where it comes from
    simulation_only: bool  # a law on the true state (chapter 4): it cannot drive the hardware
    batched: bool  # has a vectorized version for the batch engine (twin.rigs.batch)
    setpoint: bool  # the built controller implements twin.interface.Setpoint


class Catalogue(Protocol):
    """The named controllers the application layer hands down (``controllers.registry`` is one)."""

    NAMES: tuple[str, ...]
    ENTRIES: Mapping[str, CatalogueEntry]

    def make(self, name: str, params: Parameters | None = None) -> Controller | StateLaw | Firmware: ...


class Pacer(Protocol):
    """Paces a run's ticks (wall clock, hardware): ``wait(k)`` before tick k, ``done()`` after it."""

    def wait(self, k: int) -> None: ...

    def done(self) -> None: ...


class ControllerError(RuntimeError):
    """A controller raised or returned something the I/O card cannot output; the message names the tick."""


def checked_start(
    controller: Controller, sample: DaqSample, where: str = "", guard: Guard | None = None
) -> None:
    """``controller.start(sample)``; a ``ControllerError`` naming the controller (and ``where``: the run)
    if it raises anything (``SystemExit`` included; only the process's own Ctrl-C passes) or, with a
    ``guard``, does not return within ``twin.guard.first_call_budget_s``."""
    try:
        if guard is None:
            controller.start(sample)
        else:
            guard.call(controller.start, sample, guard.first_budget_s)
    except BaseException as exc:  # noqa: BLE001 - a user's controller may raise anything: report, do not crash
        raise ControllerError(_failure(controller, "start", exc, where)) from _cause(exc)


def checked_update(
    controller: Controller,
    sample: DaqSample,
    where: str | Callable[[], str],
    guard: Guard | None = None,
    limits: CommandRange | None = None,
) -> float:
    """``controller.update(sample)`` as the board's command (DAC volts on the PCI-1712); a ``ControllerError``
    naming the controller and ``where`` (the tick, the run; a function giving it, so that the text is only
    made for an error) if it raises anything (only the process's own Ctrl-C passes), does not return within
    the ``guard``'s update budget, or returns anything but a finite real number (within ``limits``, the
    board's output range, when given)."""
    try:
        if guard is None:
            command = controller.update(sample)
        else:
            command = guard.call(controller.update, sample, guard.update_budget_s)
    except BaseException as exc:  # noqa: BLE001 - a user's controller may raise anything: report, do not crash
        raise ControllerError(_failure(controller, "update", exc, where)) from _cause(exc)
    low, high = (-_MAX_FLOAT, _MAX_FLOAT) if limits is None else (limits.low, limits.high)
    if type(command) is float and low <= command <= high:  # the common case (nan and ±inf fail it)
        return command
    return _refused_command(controller, command, where, limits or CommandRange(low, high))


def _refused_command(
    controller: Controller, command: object, where: str | Callable[[], str], limits: CommandRange
) -> float:
    """A command that is not a plain float in range: a real number converted, anything else refused."""
    name = safe_name(controller)
    if isinstance(command, (bool, np.bool_)) or not isinstance(
        command, (int, float, np.floating, np.integer)
    ):
        raise ControllerError(
            f"{name}.update returned {_short_repr(command)} {_where(where)}: expected the DAC command in "
            "volts (a real number)"
        )
    try:
        volts = float(command)
    except OverflowError:  # an int too large for a float, e.g. 10**400
        volts = math.inf
    if not math.isfinite(volts):
        raise ControllerError(
            f"{name}.update returned {_short_repr(command)} {_where(where)}: the DAC command must be a "
            "finite number of volts"
        )
    if not limits.low <= volts <= limits.high:
        raise ControllerError(
            f"{name}.update returned {volts!r} {limits.unit} {_where(where)}: outside {limits.text()}"
        )
    return volts


def _short_repr(value: object) -> str:
    try:
        text = repr(value)
    except BaseException as exc:  # noqa: BLE001 - a value whose repr fails (user code) is still named
        if is_interrupt(exc):
            raise
        text = f"a {type(value).__name__}"
    text = " ".join(text.split())
    return text if len(text) <= 60 else f"{text[:24]}… ({type(value).__name__}, {len(text)} characters)"


def _failure(controller: object, phase: str, exc: BaseException, where: str | Callable[[], str]) -> str:
    """The one-line report of a failed call, or ``exc`` re-raised when it is the process's own Ctrl-C."""
    if isinstance(exc, Fault):
        return describe(exc, safe_name(controller), phase, _where(where))
    if is_interrupt(exc):
        raise exc
    return describe(Fault(exc), safe_name(controller), phase, _where(where))


def _cause(exc: BaseException) -> BaseException | None:
    return exc.exc if isinstance(exc, Fault) else exc


def check_period_s(controller: object) -> float:
    """The controller's ``period_s`` as a float, or a ``ControllerError`` when it is not a positive finite
    number of seconds (a string, a bool, nan, 0, negative) or reading it raises."""
    name = safe_name(controller)
    try:
        period = controller.period_s  # type: ignore[attr-defined]
    except BaseException as exc:  # noqa: BLE001 - a property of user code may raise anything
        if is_interrupt(exc):
            raise
        raise ControllerError(describe(Fault(exc), name, "period_s", "")) from exc
    if (
        isinstance(period, (bool, np.bool_))
        or not isinstance(period, (int, float, np.floating, np.integer))
        or not math.isfinite(float(period))
        or not period > 0
    ):
        raise ControllerError(
            f"{name}: period_s = {_short_repr(period)} must be a positive finite number of seconds"
        )
    return float(period)


def _where(where: str | Callable[[], str]) -> str:
    return where if isinstance(where, str) else where()


# How a run ended (``ClosedLoop.run``); otherwise it is the message of the rig that ended the session.
ENDED_TICKS = "all ticks"
ENDED_BALL_LOST = "ball lost"
ENDED_LAST_SAMPLE = "last sample"


class RunResult:
    """One run: its verdict and, when it was recorded, its log (``twin.rigs.batch.run_batch`` may keep verdicts
    only); how it ended (``ClosedLoop.run``) and, for a timed run on a remote rig, how it kept the period.
    ``verdict`` may be given as a function, called when the verdict is first read (a run judged from its
    measured volts pays for it only when asked)."""

    def __init__(
        self,
        controller: str,
        log: RunLog | None,
        verdict: Verdict | Callable[[], Verdict],
        *,
        ended: str = ENDED_TICKS,
        timing: TickTiming | None = None,
        firmware: dict[str, Any] | None = None,
    ) -> None:
        self.controller = controller
        self._log = log
        self._verdict = verdict
        self.ended = ended
        self.timing = timing
        self.firmware = firmware  # a firmware's figures (``Firmware.figures``), else None

    @property
    def verdict(self) -> Verdict:
        if not isinstance(self._verdict, Verdict):
            self._verdict = self._verdict()
        return self._verdict

    @verdict.setter
    def verdict(self, value: Verdict) -> None:  # a verdict judged again (about a setpoint)
        self._verdict = value

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
            f"RunResult(controller={self.controller!r}, recorded={self.recorded}, ended={self.ended!r}, "
            f"verdict={self.verdict!r})"
        )


_COLUMNS = tuple(name for name in THESIS_FIELDS + TRUTH_FIELDS if name != "ball_lost")
_TRUE_TIME = _COLUMNS.index("true_time_s")
_TRUE_STATE = slice(_COLUMNS.index("true_x_m"), _COLUMNS.index("true_thetadot_rad_s") + 1)


# Pending ticks are written into the table every 1024: a pending tick's Python objects cost ~1 kB, its
# table row 137 B, so a long session's memory is the table's.
_FLUSH_TICKS = 1024


def block_peak_abs_theta_rad(block: PhysicsBlock | None) -> float:
    """The largest |θ| of a block over its steps with the ball on the track (0 when none, or no block): the
    verdict's peak angle and stops test."""
    if block is None:
        return 0.0
    if block.all_on_track and block.theta_range_rad is not None:  # the common case: the extremes
        lo, hi = block.theta_range_rad
        return max(abs(lo), abs(hi))
    if block.on_track.all():
        return float(np.max(np.abs(block.theta_rad)))
    if block.on_track.any():
        return float(np.max(np.abs(block.theta_rad[block.on_track])))
    return 0.0


@runtime_checkable
class TrueState(Protocol):
    """What a simulated rig offers beyond the hardware contract (``twin.rigs.sim.SimRig`` does): the true state
    for the log and the verdict. A rig without it (``RemoteRig``, a hardware backend) is judged from the
    volts it measured (``twin.verdict.evaluate_measured``). Never passed to a controller."""

    last_block: PhysicsBlock | None  # the physics of the block just read

    @property
    def time_s(self) -> float: ...

    @property
    def motor_volts_v(self) -> float: ...

    @property
    def ball_lost_time_s(self) -> float | None: ...

    def true_state(self) -> np.ndarray: ...

    def true_state_row(self) -> np.ndarray | None: ...

    def true_states_of_rows(self, rows: np.ndarray) -> np.ndarray: ...


class _Recorder:
    """The log's columns. A tick is appended as one tuple of Python floats (per tick, the cost is the number
    of numpy calls, and a tuple needs none) and written into the table when the columns are read
    (``flush``); ``cols`` are views of the table's columns. The true state of a tick on the MuJoCo plant is
    kept as a copy of its state row and computed for all such ticks at once in ``flush``: the same bits
    (``SimRig.true_states_of_rows``), a fraction of the cost. Without ``truth`` (a rig that has none) the
    truth columns stay empty in the log."""

    def __init__(self, capacity: int, truth: TrueState | None, controller: str = "controller") -> None:
        self.truth = truth
        self.controller = controller  # named when its telemetry is not numbers
        self.flushed = 0
        self.table = np.zeros((capacity, len(_COLUMNS)))
        self.cols = {name: self.table[:, j] for j, name in enumerate(_COLUMNS)}
        self.lost = np.zeros(capacity, dtype=bool)
        self.peak_theta = np.zeros(capacity)
        self._ticks: list[tuple[float, ...]] = []  # appended since the last flush
        self._state_rows: list[tuple[int, np.ndarray]] = []  # (tick, state row) whose state is pending

    @property
    def n(self) -> int:
        """Ticks recorded."""
        return self.flushed + len(self._ticks)

    def add(self, sample: DaqSample, command_v: float, tel: Telemetry, ball_lost: bool) -> None:
        truth = self.truth
        if truth is None:
            time_s, state, motor_v, peak = math.nan, _NAN4, math.nan, 0.0
        else:
            state_row = truth.true_state_row()
            if state_row is None:
                time_s, state = truth.time_s, truth.true_state().tolist()
            else:  # the row holds the simulation clock and the state: both computed in ``flush``
                self._state_rows.append((self.n, state_row.copy()))
                time_s, state = math.nan, _NAN4
            motor_v, peak = truth.motor_volts_v, block_peak_abs_theta_rad(truth.last_block)
        estimate, u, u_computed = _logged(tel, self.controller, self.n)
        # timem, datam1, datam2, aout, x1…x4, u, uhesap, true_time_s, true state, motor_volts_v (_COLUMNS),
        # then the lost flag and the peak |θ|
        self._ticks.append(
            (
                sample.time_s,
                sample.ball_v,
                sample.angle_v,
                command_v,
                *estimate,
                u,
                u_computed,
                time_s,
                *state,
                motor_v,
                ball_lost,
                peak,
            )
        )
        if len(self._ticks) >= _FLUSH_TICKS:
            self.flush()

    def flush(self) -> None:
        """Write the appended ticks into the table, their pending true states computed at once."""
        if not self._ticks:
            return
        start, stop = self.flushed, self.n
        while stop > len(self.lost):
            self.table = np.concatenate([self.table, np.zeros_like(self.table)])
            self.cols = {name: self.table[:, j] for j, name in enumerate(_COLUMNS)}
            self.lost = np.concatenate([self.lost, np.zeros_like(self.lost)])
            self.peak_theta = np.concatenate([self.peak_theta, np.zeros_like(self.peak_theta)])
        width = len(self._ticks[0])
        values = np.fromiter(itertools.chain.from_iterable(self._ticks), float, (stop - start) * width)
        values = values.reshape(stop - start, width)
        self.table[start:stop] = values[:, : len(_COLUMNS)]
        self.lost[start:stop] = values[:, -2] != 0.0
        self.peak_theta[start:stop] = values[:, -1]
        if self._state_rows:
            assert self.truth is not None  # only a rig with the true state gives state rows
            ticks = [k for k, _ in self._state_rows]
            rows = np.array([row for _, row in self._state_rows])
            self.table[ticks, _TRUE_STATE] = self.truth.true_states_of_rows(rows)
            self.table[ticks, _TRUE_TIME] = rows[:, 0]  # the row's time is the simulation clock, ``time_s``
        self._ticks, self._state_rows = [], []
        self.flushed = stop

    def trace(self) -> Trace:
        """The recorded ticks as the verdict reads them (views of the table: flushed first)."""
        self.flush()
        n, c = self.n, self.cols
        return Trace(
            c["true_time_s"][:n], c["true_x_m"][:n], c["true_theta_rad"][:n], c["motor_volts_v"][:n],
            self.peak_theta[:n],
        )  # fmt: skip

    def log(self) -> RunLog:
        self.flush()
        n = self.n
        if self.truth is None:  # the rig software's log: what the rig measured and the controller logged
            return RunLog(**{name: self.cols[name][:n].copy() for name in THESIS_FIELDS})
        return RunLog(
            **{name: col[:n].copy() for name, col in self.cols.items()}, ball_lost=self.lost[:n].copy()
        )


_NAN4 = (math.nan,) * 4


def _four(estimate: np.ndarray) -> list[float]:
    """x1…x4 as floats (an estimate given in another shape broadcasts to the four, as into a table row)."""
    if type(estimate) is np.ndarray and estimate.shape == (4,) and estimate.dtype == np.float64:
        return estimate.tolist()
    if isinstance(estimate, (str, bytes)):
        raise TypeError("text, not numbers")
    return np.broadcast_to(np.asarray(estimate, dtype=float), (4,)).tolist()


def _real(value: object) -> float:
    if type(value) is float:  # the common case
        return value
    if isinstance(value, (str, bytes)) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise TypeError("not a number")
    return float(value)


def _logged(tel: Telemetry, controller: str, k: int) -> tuple[list[float], float, float]:
    """What a tick logs of the controller's telemetry as floats: x1…x4, u, uhesap; a ``ControllerError``
    naming the controller, the field, its value and the tick when one is not numbers (as the rig software
    could not log it either)."""
    try:
        return _four(tel.estimate), _real(tel.u), _real(tel.u_computed)
    except (TypeError, ValueError, OverflowError):
        pass
    fields: tuple[tuple[str, Callable[[Any], object], object], ...] = (
        ("estimate", _four, tel.estimate),
        ("u", _real, tel.u),
        ("u_computed", _real, tel.u_computed),
    )
    for field, convert, value in fields:
        try:
            convert(value)
        except (TypeError, ValueError, OverflowError) as exc:
            what = "4 of them, x1…x4" if field == "estimate" else "one"
            raise ControllerError(
                f"{controller}.telemetry.{field} = {_short_repr(value)} at tick k = {k}: the logged values must "
                f"be numbers ({what}): {exc}"
            ) from None
    raise AssertionError("unreachable: a field failed above")


class _StateLawVolts:
    """A ``ClosedLoop``'s state law as the rig calls it: the terminal volts for the plant's state, a
    ``ControllerError`` naming the law and the time when it raises or returns a non-finite value.

    ``of_floats`` takes the state as four Python floats, as the rig then passes it every physics step; a law
    that takes them too (``motor_volts_of_floats``, as ``controllers.loop.TrueStateLaw``) gets them without an
    array."""

    def __init__(self, loop: ClosedLoop, truth: TrueState) -> None:
        self.loop = loop
        self.truth = truth
        law = loop.controller
        self._motor_volts = law.motor_volts  # type: ignore[union-attr]
        self._motor_volts_of_floats = getattr(law, "motor_volts_of_floats", None)

    def __call__(self, state: np.ndarray) -> float:
        return self.of_floats(*np.asarray(state, dtype=float).tolist())

    def of_floats(self, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
        try:
            if self._motor_volts_of_floats is None:
                volts = float(self._motor_volts(np.array([x_m, theta_rad, xdot_m_s, thetadot_rad_s])))
            else:
                volts = float(self._motor_volts_of_floats(x_m, theta_rad, xdot_m_s, thetadot_rad_s))
        except BaseException as exc:  # noqa: BLE001 - only the process's own Ctrl-C passes
            if is_interrupt(exc):
                raise
            raise ControllerError(
                f"{self.loop.name} raised {type(exc).__name__} at t = {self.truth.time_s:.3f} s: {exc}"
            ) from exc
        if not math.isfinite(volts):
            raise ControllerError(
                f"{self.loop.name} returned {volts!r} volts at t = {self.truth.time_s:.3f} s"
            )
        return volts


class ClosedLoop:
    """The closed loop: one controller on one rig, tick by tick, over the ``Rig`` contract only (the rig must
    already be ``reset``). Every run goes through it: ``ballbeam run`` in process and on a remote rig, the
    served twin, the live view (a tick per frame), the environment. The true state is recorded when the rig
    offers it (``TrueState``); a state law needs it."""

    def __init__(
        self,
        rig: Rig,
        controller: Controller | StateLaw | Firmware,
        *,
        record: bool = True,
        record_limit: int | None = None,
        controller_timeout_s: float | None = None,
        params: Parameters | None = None,
        timed: bool = False,
    ) -> None:
        """``record_limit``: the most ticks recorded (a long live session keeps its first ones and its
        memory bounded); ``None`` records every tick. ``controller_timeout_s``: a controller's update that
        does not return within it fails the run (default ``twin.guard.update_budget_s``; ``math.inf``:
        no watchdog); its start gets at least ``twin.guard.FIRST_CALL_BUDGET_S``. ``params``: the rig's
        description for the command's range check and a measured verdict (default ``rig.parameters()``).
        ``timed``: the wall-clock arrival of each block and the controller's time are measured
        (``arrival_timing``: a remote rig's real-time session)."""
        self.rig = rig
        self.controller = controller
        self.params = params if params is not None else rig.parameters()
        self.command_range = rig.command_range()  # what the guard lets through: the board's output range
        self.truth: TrueState | None = rig if isinstance(rig, TrueState) else None
        install_interrupt_handler()  # before any user code runs: its KeyboardInterrupt is not the Ctrl-C
        # (a Controller first: the protocol's check reads attributes, which user code may make raise)
        hardware = isinstance(controller, Controller)
        self.is_firmware = not hardware and isinstance(controller, Firmware)
        self.is_state_law = not hardware and not self.is_firmware and isinstance(controller, StateLaw)
        period_s = check_period_s(controller)
        self._name = safe_name(controller)  # read once: user code's property may raise
        if self.is_state_law:
            self._check_state_law(period_s)
        elif self.is_firmware:
            self._read_with_firmware: Callable[[Firmware], DaqSample] = self._firmware_rig()
        elif abs(period_s - rig.period_s) > _PERIOD_TOLERANCE_S:
            raise RigError(
                f"{self._name}: period_s = {period_s!r} s does not match the DAQ's "
                f"daq.period_s = {rig.period_s!r} s; set daq.period_s to the controller's period (a parameter "
                f"file) or change the controller"
            )
        self.guard = (
            None
            if self.is_state_law or self.is_firmware
            else Guard.for_period(rig.period_s, controller_timeout_s)
        )
        self.recorder = _Recorder(256, self.truth, self._name) if record else None
        self.record_limit = record_limit
        self.last_sample: DaqSample | None = None
        self.command_v = rig.command_v
        self.started = False
        self.reads = 0  # blocks read: the tick k that messages name
        self._arrivals: array[float] | None = array("d") if timed else None
        self._compute: array[float] = array("d")

    def _check_state_law(self, period_s: float) -> None:
        read_with_state_law = getattr(self.rig, "read_with_state_law", None)
        if self.truth is None or read_with_state_law is None:
            raise RigError(
                f"{self._name} is a law on the true state (simulation only): it cannot drive a rig"
            )
        dt = self.params.physics.timestep_s
        law_steps = whole_steps(period_s, dt, f"{self._name} period_s")
        tick_steps = whole_steps(self.rig.period_s, dt, "daq.period_s")
        if law_steps < 1 or tick_steps % law_steps:
            raise RigError(
                f"{self._name}: period_s = {period_s!r} s must divide daq.period_s = "
                f"{self.rig.period_s!r} s into whole physics steps"
            )
        self._read_with_law: Callable[..., DaqSample] = read_with_state_law
        self._law_volts = _StateLawVolts(self, self.truth)

    def _firmware_rig(self) -> Callable[[Firmware], DaqSample]:
        read_with_firmware = getattr(self.rig, "read_with_firmware", None)
        if self.truth is None or read_with_firmware is None:
            raise RigError(
                f"{self._name} is firmware on a simulated microcontroller: it drives the simulated rig only"
            )
        return read_with_firmware

    @property
    def name(self) -> str:
        return self._name

    def firmware_figures(self) -> dict[str, Any] | None:
        """What the target adds to the verdict (``Firmware.figures``), for a firmware; else ``None``."""
        return self.controller.figures() if self.is_firmware else None  # type: ignore[union-attr]

    @property
    def recording(self) -> bool:
        """Whether the next tick is recorded (recording on and the limit not reached)."""
        r = self.recorder
        return r is not None and (self.record_limit is None or r.n < self.record_limit)

    def _read(self) -> DaqSample:
        sample = self.rig.read()
        self.reads += 1
        return sample

    def start(self) -> None:
        """The software's Start/Clear Buffer phase: the held rig's block starts the controller (a firmware's board
        is powered on as the block begins)."""
        if self.is_firmware:
            self.started = True
            self._firmware_tick()
            return
        sample = self._read()
        if self.is_state_law:
            try:
                self.controller.reset()  # type: ignore[union-attr]
            except BaseException as exc:  # noqa: BLE001 - report, do not crash
                raise ControllerError(_failure(self.controller, "start", exc, "")) from exc
        else:
            checked_start(self.controller, sample, guard=self.guard)  # type: ignore[arg-type]
        self.last_sample = sample
        self.started = True
        if self.recorder is not None and self.recording:
            self.recorder.add(sample, self.rig.command_v, self.controller.telemetry, self.rig.ball_lost)

    def tick(self) -> None:
        """One control period: read a block, run the controller, write its command."""
        if not self.started:
            self.start()
        if self.is_state_law:
            self._state_law_tick()
            return
        if self.is_firmware:
            self._firmware_tick()
            return
        sample = self.sense()
        self.answer(
            checked_update(
                self.controller,  # type: ignore[arg-type]
                sample,
                lambda: f"at tick k = {self.reads} (t = {sample.time_s:.3f} s)",
                self.guard,
                self.command_range,
            )
        )

    def sense(self) -> DaqSample:
        """A tick's first half: read the next block. ``tick`` then runs the controller; a host that answers
        from outside the loop (an environment's agent, between its steps) calls ``answer`` itself."""
        if not self.started:
            self.start()
        sample = self._read()
        if self._arrivals is not None:
            self._arrivals.append(time.perf_counter())
        self.last_sample = sample
        return sample

    def answer(self, command_v: float) -> None:
        """A tick's second half: write the command answering the block ``sense`` read, record the tick."""
        rig = self.rig
        rig.write(command_v)
        if self._arrivals is not None:
            self._compute.append(time.perf_counter() - self._arrivals[-1])
        self.command_v = float(command_v)
        if self.recorder is not None and self.recording:
            assert self.last_sample is not None
            self.recorder.add(self.last_sample, self.command_v, self.controller.telemetry, rig.ball_lost)

    def _state_law_tick(self) -> None:
        """A tick of a law on the true state: the rig recomputes the volts from the state within it."""
        rig = self.rig
        if self.reads < 2:  # block 0 ends when the first command reaches the amplifier
            sample = self._read()
        else:
            sample = self._read_with_law(self._law_volts, self.controller.period_s)
            self.reads += 1
        self.last_sample = sample
        self.command_v = float(rig.command_v)
        if self.recorder is not None and self.recording:
            self.recorder.add(sample, self.command_v, self.controller.telemetry, rig.ball_lost)

    def _firmware_tick(self) -> None:
        """A tick of a firmware: the board runs through the block on the rig's signals; its fault names the tick."""
        try:
            sample = self._read_with_firmware(self.controller)  # type: ignore[arg-type]
        except ControllerError as exc:
            raise ControllerError(f"{exc} (tick k = {self.reads - 1})") from None
        self.reads += 1
        self.last_sample = sample
        self.command_v = float(self.rig.command_v)
        if self.recorder is not None and self.recording:
            self.recorder.add(sample, self.command_v, self.controller.telemetry, self.rig.ball_lost)

    def run(
        self, ticks: int | None = None, *, pacer: Pacer | None = None, stop_when_lost: bool = True
    ) -> str:
        """The run from here: ``start`` when not started, then ``ticks`` ticks (``None``: until the rig's
        last sample), each paced by ``pacer``; ``stop_when_lost`` ends it at the tick the rig reports the
        ball lost. How it ended: ``ENDED_TICKS``, ``ENDED_BALL_LOST``, ``ENDED_LAST_SAMPLE`` or the message
        of the rig that ended the session (``RigEnded``). A controller's failure is a ``ControllerError``."""
        if not self.started:
            self.start()
        rig = self.rig
        counter = itertools.count() if ticks is None else range(ticks)
        try:
            for k in counter:
                if pacer is not None:
                    pacer.wait(k)
                self.tick()
                if pacer is not None:
                    pacer.done()
                if rig.is_last:  # the rig ends the session (also when it stops on a lost ball)
                    return ENDED_LAST_SAMPLE
                if stop_when_lost and rig.ball_lost:
                    return ENDED_BALL_LOST
        except RigEnded as exc:
            return str(exc)
        return ENDED_TICKS

    def arrival_timing(self) -> TickTiming | None:
        """How the blocks kept the period on the wall clock (``timed`` loops; else ``None``)."""
        if self._arrivals is None:
            return None
        return arrival_timing(self._arrivals, self._compute, self.rig.period_s)

    def log(self) -> RunLog:
        if self.recorder is None:
            raise RuntimeError("this closed loop was built with record=False")
        return self.recorder.log()

    def verdict(
        self, x0_m: float | None = None, criteria: Criteria | None = None, *, x_ref_m: float = 0.0
    ) -> Verdict:
        """The verdict of the run so far, judged about the ball position ``x_ref_m`` (a setpoint; the offsets
        and the settling band are measured from it): from the recorded true state when the rig gave it
        (``x0_m`` default: the held state's), else from the measured volts through the rig's calibration
        (``x0_m`` default: the first block's reading)."""
        if self.recorder is None:
            raise RuntimeError("this closed loop was built with record=False")
        r = self.recorder
        if self.truth is None:
            return evaluate_measured(r.log(), self.params, x0_m=x0_m, x_ref_m=x_ref_m, criteria=criteria)
        trace = r.trace()
        return judge(
            self.params,
            trace,
            x0_m=float(trace.x_m[0]) if x0_m is None else x0_m,
            ball_lost_time_s=self.truth.ball_lost_time_s,
            criteria=criteria,
            x_ref_m=x_ref_m,
        )

    def result(
        self, ended: str = ENDED_TICKS, x0_m: float | None = None, criteria: Criteria | None = None
    ) -> RunResult:
        """The run's log, verdict (``verdict``), how it ended and, for a timed loop, its timing."""
        log = self.log()
        if self.truth is None:  # judged from the measured volts, when asked
            params = self.params

            def verdict() -> Verdict:
                return evaluate_measured(log, params, x0_m=x0_m, criteria=criteria)

            return RunResult(self.name, log, verdict, ended=ended, timing=self.arrival_timing())
        return RunResult(
            self.name,
            log,
            self.verdict(x0_m, criteria),
            ended=ended,
            timing=self.arrival_timing(),
            firmware=self.firmware_figures(),
        )


def judge(
    params: Parameters,
    trace: Trace,
    *,
    x0_m: float,
    ball_lost_time_s: float | None,
    criteria: Criteria | None = None,
    x_ref_m: float = 0.0,
) -> Verdict:
    """A run's verdict from its recorded ticks on the rig of ``params`` (its rails and stops), judged about
    the ball position ``x_ref_m``: the single run's and the batch's one call of ``twin.verdict.evaluate``."""
    if x_ref_m:
        trace = replace(trace, x_m=trace.x_m - x_ref_m)
    return evaluate(
        trace,
        x0_m=x0_m - x_ref_m,
        ball_lost_time_s=ball_lost_time_s,
        rail_v=params.amplifier.rail_v,
        stop_angle_rad=params.beam.stop_angle_rad,
        criteria=criteria,
    )


def update_ticks(duration_s: float, params: Parameters) -> int:
    """Number of ``update`` ticks so that the last block ends at or after ``duration_s`` after release."""
    free, period = params.start.free_run_s, params.period_s
    return 1 + max(0, math.ceil((duration_s - free) / period - 1e-9))


def run_on_rig(
    controller: Controller,
    rig: Rig,
    *,
    params: Parameters | None = None,
    controller_timeout_s: float | None = None,
) -> RunResult:
    """``controller`` on a rig that runs its own session (a ``RemoteRig``: the served twin, a rig's firmware)
    until the sample flagged last, the first sample the rig reports the ball lost on, a STOP or the rig going
    silent: the one loop, timed, judged from the measured volts unless the rig gives the true state.
    ``params``: the rig's description (default ``rig.parameters()``).

    A rig that stops on a lost ball flags that sample last as well: the run ends ``ENDED_LAST_SAMPLE`` after
    answering it, as the rig expects. One that reports the ball lost and goes on ends ``ENDED_BALL_LOST``,
    also after answering that sample: the caller then tells the rig the session is over (``RemoteRig.stop``
    with ``STOP_BALL_LOST``: ``twin.rigs.session``), so that it does not wait for the next command."""
    loop = ClosedLoop(rig, controller, params=params, controller_timeout_s=controller_timeout_s, timed=True)
    ended = loop.run(None, stop_when_lost=True)
    return loop.result(ended)
