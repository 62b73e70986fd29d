"""Calls into a controller, which may be a user's code: what it raised and how long it took.

A user's controller can raise anything (``SystemExit``, ``KeyboardInterrupt``, …) or block. ``Guard.call``
runs one call under a deadline and turns whatever went wrong into a ``Fault`` (the engine reports it as a
``ControllerError`` naming the controller, the phase and the tick); only the process's own Ctrl-C passes
through as ``KeyboardInterrupt``, so that exit codes keep their meaning.

Budgets (wall clock, per call): an ``update`` gets ``max(10 × period_s, 1 s)`` unless told otherwise: ten
periods is already ten times what the rig allows, and the floor keeps a healthy controller on a loaded
machine from failing on a scheduling pause (a verdict must not depend on the load). The first calls (import,
construction, ``start``) get at least ``FIRST_CALL_BUDGET_S``: they may import libraries and design gains.
``math.inf`` switches the watchdog off (e.g. under a debugger).

How a blocked call is stopped (a Python thread cannot be killed):

* in the main thread, a daemon watcher thread sends SIGALRM to it when the deadline passes and the handler
  raises ``Stalled`` inside the call; a sleep is interrupted, a busy Python loop stops at its next bytecode.
  Per call this costs one clock read and two attribute stores (~0.2 µs), not a timer system call.
* elsewhere (the live view's simulation thread, Dask's worker threads; signals reach the main thread only)
  the call runs in a daemon helper thread and the caller waits with a timeout; a stalled helper is
  abandoned (``Stalled`` is injected into it, which ends a busy Python loop) and never joined, so the
  process still exits.

The real Ctrl-C is told apart from a controller's ``raise KeyboardInterrupt`` by the SIGINT handler
installed here (``install_interrupt_handler``): it raises ``Interrupted``, a ``KeyboardInterrupt``
subclass. A process that ignores SIGINT (the fan-out's workers) cannot receive a Ctrl-C at all. The CLI
installs it for SIGTERM and SIGHUP too (``terminate=True``): ``kill``, ``timeout`` or a closed terminal then
end a long job as Ctrl-C does, keeping the runs done; the exit code says which signal it was
(``interrupt_exit_code``: 128 + the signal's number, 130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP).
"""

from __future__ import annotations

import ctypes
import math
import os
import signal
import threading
import time
import weakref
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

__all__ = [
    "FIRST_CALL_BUDGET_S",
    "MIN_UPDATE_BUDGET_S",
    "UPDATE_BUDGET_PERIODS",
    "Fault",
    "Guard",
    "Interrupted",
    "STOP_SIGNALS",
    "Stalled",
    "check_timeout_s",
    "command_ended",
    "default_timeout_s",
    "describe",
    "fault_text",
    "first_call_budget_s",
    "install_interrupt_handler",
    "interrupt_exit_code",
    "job_runs",
    "pending_interrupt",
    "interrupt_name",
    "is_interrupt",
    "safe_name",
    "set_default_timeout_s",
    "update_budget_s",
]

UPDATE_BUDGET_PERIODS = 10  # an update may take this many control periods …
MIN_UPDATE_BUDGET_S = 1.0  # … but never less than this (a loaded machine's pauses)
FIRST_CALL_BUDGET_S = 30.0  # import, construction, start: lazy imports and designs
_POLL_S = 0.05  # the watcher's idle sleep, and its pause between two alarms to a call still overdue

T = TypeVar("T")


class Stalled(BaseException):
    """Raised into a controller call that did not return within its budget (a BaseException: a
    controller's ``except Exception`` does not swallow it)."""


class Interrupted(KeyboardInterrupt):
    """The process's own Ctrl-C (SIGINT), or SIGTERM/SIGHUP where the CLI asked (``terminate=True``), as
    raised by the handler installed here."""


class Fault(Exception):
    """A controller call went wrong: it raised ``exc``, or it stalled (``exc`` is None, ``budget_s`` set)."""

    def __init__(self, exc: BaseException | None, budget_s: float | None = None) -> None:
        super().__init__(exc)
        self.exc = exc
        self.budget_s = budget_s


def describe(fault: Fault, name: str, phase: str, where: str) -> str:
    """One line: ``<name>.<phase> raised ValueError at tick k = 3 (t = 0.030 s): <its message>``, or
    ``<name>.update did not return within 0.2 s at tick k = 37 (t = 0.740 s): stalled``."""
    place = f" {where}" if where else ""
    if fault.exc is None:
        return f"{name}.{phase} did not return within {fault.budget_s:g} s{place}: stalled"
    kind, text = _exception_parts(fault.exc)
    return f"{name}.{phase} raised {kind}{place}" + (f": {text}" if text else "")


def fault_text(fault: Fault) -> str:
    """What went wrong, without the call: ``SystemExit: sys.exit(3)``, ``ValueError: …``, ``… stalled``."""
    if fault.exc is None:
        return f"did not return within {fault.budget_s:g} s: stalled"
    kind, text = _exception_parts(fault.exc)
    return f"{kind}: {text}" if text else kind


def _exception_parts(exc: BaseException) -> tuple[str, str]:
    """The exception's type name and its message on one line."""
    if isinstance(exc, SystemExit):  # the exit code is the point
        return "SystemExit", f"sys.exit({exc.code!r})" if exc.code is not None else "sys.exit()"
    try:
        text = " ".join(str(exc).split())
    except BaseException as err:  # noqa: BLE001 - an exception whose str fails (user code) is still named
        if is_interrupt(err):
            raise
        text = ""
    return type(exc).__name__, text


def safe_name(obj: object) -> str:
    """``obj.name`` when it is a string (reading it may raise: user code), else the class name."""
    try:
        name = obj.name  # type: ignore[attr-defined]
    except BaseException as exc:  # noqa: BLE001 - a property of user code may raise anything
        if is_interrupt(exc):
            raise
        name = None
    return name if isinstance(name, str) and name else type(obj).__name__


# --- budgets --------------------------------------------------------------------------------------------
_default_timeout_s: float | None = None


def check_timeout_s(timeout_s: float | None, what: str = "controller_timeout_s") -> float | None:
    """``timeout_s`` if it is None, ``math.inf`` or a positive finite number of seconds, else a ValueError."""
    if timeout_s is None:
        return None
    if (
        isinstance(timeout_s, bool)
        or not isinstance(timeout_s, (int, float))
        or math.isnan(timeout_s)
        or timeout_s <= 0
    ):
        raise ValueError(f"{what} = {timeout_s!r}: a positive number of seconds (inf: no watchdog)")
    return float(timeout_s)


def set_default_timeout_s(timeout_s: float | None) -> None:
    """The process's update budget when a run is given none (the CLI's ``--controller-timeout``)."""
    global _default_timeout_s
    _default_timeout_s = check_timeout_s(timeout_s)


def default_timeout_s() -> float | None:
    return _default_timeout_s


def update_budget_s(period_s: float, timeout_s: float | None = None) -> float:
    """The budget of one ``update``: ``timeout_s``, else the process default, else max(10 periods, 1 s)."""
    if timeout_s is None:
        timeout_s = _default_timeout_s
    if timeout_s is not None:
        return timeout_s
    return max(UPDATE_BUDGET_PERIODS * period_s, MIN_UPDATE_BUDGET_S)


def first_call_budget_s(timeout_s: float | None = None) -> float:
    """The budget of an import, a construction or a ``start``: at least ``FIRST_CALL_BUDGET_S``."""
    if timeout_s is None:
        timeout_s = _default_timeout_s
    return FIRST_CALL_BUDGET_S if timeout_s is None else max(timeout_s, FIRST_CALL_BUDGET_S)


# --- Ctrl-C, SIGTERM, SIGHUP -----------------------------------------------------------------------------
# The signal that interrupted this process last (None: none yet): its exit code and name.
_interrupted_by: int | None = None
# Ended as Ctrl-C is: ``kill``'s and ``timeout``'s default signal, and a terminal closing under the job.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
# A command of the CLI (``install_interrupt_handler(terminate=True)``) that has started a job's runs
# (``job_runs``): a first signal between its runs does not raise where the job's code happens to be (its
# results would be lost) but stops its next runs; a signal within its runs raises there (``run_starts``
# keeps what came back). A second signal always raises at once.
_between_runs_deferred = False
_in_job = False
_in_runs = 0
_deferred = False  # a signal came between a job's runs and has stopped no runs yet


def _on_sigint(signum: int, frame: object) -> None:
    global _interrupted_by, _deferred
    first = _interrupted_by is None
    _interrupted_by = signum
    if first and _between_runs_deferred and _in_job and not _in_runs:
        _deferred = True
        return
    raise Interrupted


def install_interrupt_handler(*, terminate: bool = False) -> None:
    """In the main thread, replace Python's default SIGINT handler by one raising ``Interrupted`` (the same
    behaviour, told apart from a controller's own ``KeyboardInterrupt``); any other handler is kept.
    ``terminate`` (the CLI, as a command starts): SIGTERM and SIGHUP at their default (which ends the process
    on the spot, writing nothing) are handled alike, so that a job stopped by ``kill`` or ``timeout`` keeps
    what it did as on Ctrl-C; and once a job's runs have started, a first signal between them waits for its
    next runs (``job_runs``) instead of raising in the job's own code."""
    global _interrupted_by, _between_runs_deferred, _in_job, _in_runs, _deferred
    if threading.current_thread() is threading.main_thread():
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _on_sigint)
        if terminate:  # a command starts: nothing has interrupted it yet
            _interrupted_by, _deferred = None, False
            _between_runs_deferred, _in_job, _in_runs = True, False, 0
            for signum in STOP_SIGNALS:
                if signal.getsignal(signum) is signal.SIG_DFL:
                    signal.signal(signum, _on_sigint)


def command_ended() -> None:
    """Undo what ``install_interrupt_handler(terminate=True)`` added and forget the command's signal: SIGTERM
    and SIGHUP at their defaults, no deferral between runs (``main`` called in a process that goes on)."""
    global _interrupted_by, _deferred, _between_runs_deferred, _in_job
    _interrupted_by, _deferred = None, False
    _between_runs_deferred = _in_job = False
    if threading.current_thread() is threading.main_thread():
        for signum in STOP_SIGNALS:
            if signal.getsignal(signum) is _on_sigint:
                signal.signal(signum, signal.SIG_DFL)


@contextmanager
def job_runs() -> Iterator[bool]:
    """Around a job's runs (``twin.app.fanout.run_starts``): yields whether they must not start (the process
    was interrupted before them: the job winds down with what it has); within the block a signal raises
    ``Interrupted``, which the caller turns into the runs done so far."""
    global _in_job, _in_runs, _deferred
    _in_job = True
    stop = _interrupted_by is not None and (_deferred or _between_runs_deferred)
    _deferred = False
    _in_runs += 1
    try:
        yield stop
    finally:
        _in_runs -= 1


def pending_interrupt() -> bool:
    """Whether a signal came after a job's last runs (while it judged or wrote them) and stopped nothing:
    its outputs are complete, and the process still ends as interrupted (``interrupt_exit_code``)."""
    return _deferred


def interrupt_exit_code() -> int:
    """128 + the number of the signal that interrupted the process (the shell's convention): 130 for Ctrl-C
    (and a ``KeyboardInterrupt`` no signal of ours raised), 143 for SIGTERM, 129 for SIGHUP."""
    return 128 + (_interrupted_by if _interrupted_by is not None else signal.SIGINT)


def interrupt_name() -> str:
    """What interrupted the process, for its message: ``Ctrl-C``, ``SIGTERM`` or ``SIGHUP``."""
    if _interrupted_by is None or _interrupted_by == signal.SIGINT:
        return "Ctrl-C"
    return signal.Signals(_interrupted_by).name


def is_interrupt(exc: BaseException, *, in_helper: bool = False) -> bool:
    """Whether ``exc`` is the process's own Ctrl-C rather than something a controller raised.

    ``in_helper``: raised in a helper thread, which a signal never reaches."""
    if isinstance(exc, Interrupted):
        return True
    if in_helper or not isinstance(exc, KeyboardInterrupt):
        return False
    handler = signal.getsignal(signal.SIGINT)
    # Our handler raises Interrupted; a process ignoring SIGINT gets no Ctrl-C. Any other handler: unknown,
    # so it counts as the user's Ctrl-C (as before).
    return handler is not _on_sigint and handler is not signal.SIG_IGN


# --- the main thread's watchdog -------------------------------------------------------------------------
class _MainWatch:
    """Deadlines of the calls made in the main thread, watched by a daemon thread that sends SIGALRM."""

    def __init__(self) -> None:
        self.active = False
        self.deadline = math.inf
        self.target = threading.get_ident()
        self.pid = os.getpid()
        threading.Thread(target=self._watch, name="controller-watchdog", daemon=True).start()

    def _watch(self) -> None:
        while True:
            if not self.active:
                time.sleep(_POLL_S)
                continue
            left = self.deadline - time.monotonic()
            if left > 0:
                time.sleep(min(left, _POLL_S) + 1e-3)
                continue
            try:
                signal.pthread_kill(self.target, signal.SIGALRM)
            except (OSError, ValueError):  # the main thread is gone: the process is ending
                return
            time.sleep(_POLL_S)  # a call that swallowed Stalled is alarmed again


_main_watch: _MainWatch | None = None


def _on_alarm(signum: int, frame: object) -> None:
    watch = _main_watch
    if watch is not None and watch.active and time.monotonic() >= watch.deadline:
        raise Stalled


def _main_watch_here() -> _MainWatch | None:
    """The main thread's watchdog, when called from the main thread and SIGALRM is free for it."""
    global _main_watch
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_kill"):
        return None
    if _main_watch is not None and _main_watch.pid == os.getpid():
        return _main_watch
    handler = signal.getsignal(signal.SIGALRM)
    if handler is not _on_alarm:
        if handler not in (signal.SIG_DFL, None):
            return None  # someone else's alarm: use a helper thread instead
        signal.signal(signal.SIGALRM, _on_alarm)
    _main_watch = _MainWatch()
    return _main_watch


def _after_fork() -> None:  # the watcher thread does not survive a fork
    global _main_watch
    _main_watch = None


os.register_at_fork(after_in_child=_after_fork)


# --- a helper thread, where signals cannot be used ------------------------------------------------------
class _Helper:
    """One daemon thread running the calls handed to it, one at a time."""

    def __init__(self) -> None:
        self.go = threading.Event()
        self.done = threading.Event()
        self.job: tuple[Callable[[Any], Any], Any] | None = None
        self.result: tuple[bool, Any] = (True, None)
        self.thread = threading.Thread(target=self._serve, name="controller-call", daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        # An abandoned call's Stalled may land after the call returned (between two calls, in a wait): the
        # guard has moved on, so it ends the thread quietly instead of printing a thread's traceback.
        try:
            while True:
                self.go.wait()
                self.go.clear()
                job = self.job
                if job is None:
                    return
                try:
                    self.result = (True, job[0](job[1]))
                except BaseException as exc:  # noqa: BLE001 - handed back to the caller
                    self.result = (False, exc)
                self.done.set()
        except Stalled:
            return

    def stop(self) -> None:
        """End the idle thread (its guard is gone)."""
        self.job = None
        self.go.set()

    def abandon(self) -> None:
        """Stop waiting for a stalled call: a busy Python loop ends with Stalled; a blocked one sleeps on
        (a daemon thread: the process still exits)."""
        self.job = None
        ident = self.thread.ident
        if ident is not None:
            ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(ident), ctypes.py_object(Stalled))
        self.go.set()  # a call that returned meanwhile finds no job and the thread ends


class Guard:
    """Calls into one controller from one thread, each under a budget (``call``): ``update_budget_s`` for
    an update, ``first_budget_s`` for a start (``math.inf``: none)."""

    def __init__(self, update_budget_s: float = math.inf, first_budget_s: float = math.inf) -> None:
        self.update_budget_s = update_budget_s
        self.first_budget_s = first_budget_s
        self._watch = _main_watch_here()
        if self._watch is not None:
            install_interrupt_handler()
        self._helper: _Helper | None = None

    @classmethod
    def for_period(cls, period_s: float, timeout_s: float | None = None) -> Guard:
        """The budgets of a controller of this period (``update_budget_s``, ``first_call_budget_s``)."""
        timeout = check_timeout_s(timeout_s)
        return cls(update_budget_s(period_s, timeout), first_call_budget_s(timeout))

    def call(self, fn: Callable[[Any], T], arg: Any, budget_s: float) -> T:
        """``fn(arg)``; a ``Fault`` if it raises (anything but the process's Ctrl-C) or does not return
        within ``budget_s`` seconds."""
        watch = self._watch
        if watch is not None:  # the main thread: cheap, every tick
            watch.deadline = time.monotonic() + budget_s
            watch.active = True
            try:
                out = fn(arg)
                watch.active = False
                return out
            except Stalled:
                watch.active = False
                raise Fault(None, budget_s) from None
            except BaseException as exc:
                watch.active = False
                if is_interrupt(exc):
                    raise
                raise Fault(exc) from exc
        if math.isinf(budget_s):
            try:
                return fn(arg)
            except BaseException as exc:
                if is_interrupt(exc):
                    raise
                raise Fault(exc) from exc
        return self._in_helper(fn, arg, budget_s)

    def _in_helper(self, fn: Callable[[Any], T], arg: Any, budget_s: float) -> T:
        helper = self._helper
        if helper is None:
            helper = self._helper = _Helper()
            weakref.finalize(self, helper.stop)  # no idle thread outlives its guard
        helper.job = (fn, arg)
        helper.done.clear()
        helper.go.set()
        if not helper.done.wait(budget_s):
            self._helper = None
            helper.abandon()
            raise Fault(None, budget_s)
        ok, value = helper.result
        helper.result = (True, None)
        if ok:
            return value
        if is_interrupt(value, in_helper=True):
            raise value
        raise Fault(value) from value
