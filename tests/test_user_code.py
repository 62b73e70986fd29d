"""User code cannot lie about the verdict (issue 17, item 2): whatever a user's controller raises, however it
blocks and whatever it returns, the run fails with a one-line message naming the controller, the phase and
the tick; exit codes keep their meaning (never 0, never the Ctrl-C's 130); nothing hangs."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twin import guard
from twin.engine import ClosedLoop, ControllerError
from twin.interface import Controller, DaqSample
from twin.parameters import Parameters
from twin.rigs.batch import run_batch
from twin.rigs.sim import make_rig, run_closed_loop

ROOT = Path(__file__).resolve().parents[1]

# A user's module: what it does is chosen by BAD_MODE (one module, many misbehaviours).
USER_MODULE = """
import os, sys, time
from twin.interface import Controller

MODE = os.environ.get("BAD_MODE", "")
if MODE == "import_exit":
    sys.exit(3)


class Bad(Controller):
    name = "bad"

    def __init__(self):
        super().__init__()
        if MODE == "init_exit":
            sys.exit(0)
        if MODE == "period_str":
            self.period_s = "0.02"
        if MODE == "period_nan":
            self.period_s = float("nan")

    def start(self, sample):
        if MODE == "start_exit":
            sys.exit(0)

    def update(self, sample):
        if sample.time_s > 0.05:  # a few healthy ticks first
            if MODE == "update_exit":
                sys.exit(0)
            if MODE == "update_kbi":
                raise KeyboardInterrupt
            if MODE == "sleep":
                if os.environ.get("BAD_MARK"):  # tell the test the controller is asleep
                    open(os.environ["BAD_MARK"], "w").close()
                time.sleep(1e6)
            if MODE == "busy":
                while True:
                    pass
            if MODE == "overflow":
                return 10**400
            if MODE == "seven":
                return 7.0
        return 2.5
"""

# (mode, exit code, what stderr's last line says); the tick is that of the first block after t = 0.05 s.
CASES = [
    ("import_exit", 2, "--controller bad:Bad: importing bad failed: SystemExit: sys.exit(3)"),
    ("init_exit", 2, "--controller bad:Bad: Bad() failed: SystemExit: sys.exit(0)"),
    ("start_exit", 1, "bad.start raised SystemExit"),
    ("update_exit", 1, "bad.update raised SystemExit at tick k = 4 (t = 0.050 s"),
    ("update_kbi", 1, "bad.update raised KeyboardInterrupt at tick k = 4 (t = 0.050 s"),
    ("sleep", 1, "bad.update did not return within 0.2 s at tick k = 4 (t = 0.050 s"),
    ("busy", 1, "bad.update did not return within 0.2 s at tick k = 4 (t = 0.050 s"),
    ("overflow", 1, "bad.update returned 100000000000000000000000… (int, 401 characters) at tick k = 4"),
    ("seven", 1, "bad.update returned 7.0 V at tick k = 4 (t = 0.050 s"),
    ("period_str", 2, "bad: period_s = '0.02' must be a positive finite number of seconds"),
    ("period_nan", 2, "bad: period_s = nan must be a positive finite number of seconds"),
]
COMMANDS = {
    "run": ["run", "--x0", "0", "--theta0", "0", "--duration", "0.5"],
    "sweep": ["sweep", "--x0", "-0.1:0.1:2", "--theta0", "0:0:1", "--duration", "0.5"],
}
BOUND_S = 30.0  # each command, start-up included, ends well within this (a hang would not)


def _cli(cwd: Path, mode: str, argv: list[str]) -> tuple[int, str, float]:
    """``python -m twin.app.cli`` as a user starts it (SIGINT at its default): exit code, stderr, seconds."""
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{cwd}", "BAD_MODE": mode}
    started = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "twin.app.cli", *argv],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=BOUND_S,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    return done.returncode, done.stderr, time.monotonic() - started


@pytest.fixture(scope="module")
def user_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("user")
    (path / "bad.py").write_text(USER_MODULE)
    return path


@pytest.fixture(scope="module")
def outcomes(user_dir: Path) -> dict[tuple[str, str], tuple[int, str, float]]:
    """Every case through every command, four processes at a time (each is mostly Python's start-up)."""
    jobs = {
        (command, mode): [*argv[:1], "--controller", "bad:Bad", *argv[1:], "--controller-timeout", "0.2"]
        for command, argv in COMMANDS.items()
        for mode, _, _ in CASES
    }
    # The fast engine compiles on its first use and keeps it (numba's cache): one sweep first, alone and without
    # the bound, so that the four at once pay Python's start-up and not four cold compiles on two cores
    warm_up = [*COMMANDS["sweep"][:1], "--controller", "appendix-sf", *COMMANDS["sweep"][1:]]
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{user_dir}"}
    subprocess.run(
        [sys.executable, "-m", "twin.app.cli", *warm_up], cwd=user_dir, env=env, capture_output=True
    )
    with ThreadPoolExecutor(4) as pool:
        futures = {key: pool.submit(_cli, user_dir, key[1], argv) for key, argv in jobs.items()}
        return {key: future.result() for key, future in futures.items()}


def _last_line(stderr: str) -> str:
    """The message: the last line (tqdm's bar redraws with carriage returns before it)."""
    return stderr.replace("\r", "\n").strip().splitlines()[-1]


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize(("mode", "code", "says"), CASES)
def test_a_misbehaving_user_controller_fails_the_command(
    outcomes: dict, command: str, mode: str, code: int, says: str
) -> None:
    rc, stderr, seconds = outcomes[command, mode]
    assert rc == code, stderr
    assert "Traceback" not in stderr
    assert says in _last_line(stderr)
    if command == "sweep" and code == 1:  # every run failed, and the job says so
        assert _last_line(stderr).startswith(
            "ballbeam sweep: the controller failed in 2 of 2 runs; the first: "
        )
    assert seconds < BOUND_S


@pytest.mark.parametrize("mode", ["sleep", "update_kbi"])
def test_worker_processes_fail_the_run_too(user_dir: Path, mode: str) -> None:
    """In the fan-out's worker processes (which ignore SIGINT) a stall and a KeyboardInterrupt fail each run."""
    argv = [*COMMANDS["sweep"], "--controller", "bad:Bad", "--controller-timeout", "0.2", "--workers", "2"]
    rc, stderr, seconds = _cli(user_dir, mode, argv)
    says = "did not return within 0.2 s" if mode == "sleep" else "raised KeyboardInterrupt"
    assert rc == 1 and "Traceback" not in stderr and seconds < BOUND_S
    assert _last_line(stderr) == (
        f"ballbeam sweep: the controller failed in 2 of 2 runs; the first: bad.update {says} at tick k = 4 "
        f"(t = 0.050 s)" + (": stalled" if mode == "sleep" else "")
    )


def test_the_users_ctrl_c_still_interrupts_a_blocked_controller(user_dir: Path) -> None:
    """A real Ctrl-C (SIGINT to the process) is 130, a controller's own KeyboardInterrupt is 1 (above)."""
    mark = user_dir / "asleep"
    mark.unlink(missing_ok=True)
    env = {
        **os.environ,
        "PYTHONPATH": f"{ROOT}{os.pathsep}{user_dir}",
        "BAD_MODE": "sleep",
        "BAD_MARK": str(mark),
    }
    argv = ["run", "--controller", "bad:Bad", "--x0", "0", "--theta0", "0", "--controller-timeout", "inf"]
    process = subprocess.Popen(
        [sys.executable, "-m", "twin.app.cli", *argv],
        cwd=user_dir,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + BOUND_S
        while not mark.exists() and time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.02)
        assert mark.exists(), "the controller never went to sleep"
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=BOUND_S)
    finally:
        process.kill()
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr and _last_line(stderr) == "ballbeam: interrupted"


@pytest.mark.quick
@pytest.mark.parametrize("value", ["0", "-1", "nan"])
def test_controller_timeout_option_is_checked(capsys: pytest.CaptureFixture[str], value: str) -> None:
    from twin.app.cli import main

    assert main([*COMMANDS["run"], "--controller", "lqr", "--controller-timeout", value]) == 2
    says = f"--controller-timeout = {float(value)!r}: a positive number of seconds (inf: no watchdog)"
    assert capsys.readouterr().err == f"ballbeam: error: {says}\n"
    assert guard.default_timeout_s() is None  # the process default is the caller's again


# --- the engine -----------------------------------------------------------------------------------------
class _Scripted(Controller):
    """A controller whose update at tick ``at`` (counted from 1) calls ``act``; 2.5 V otherwise."""

    name = "scripted"

    def __init__(
        self, at: int = 3, act: Callable[[], Any] = lambda: 2.5, on_start: Callable[[], Any] | None = None
    ):
        super().__init__()
        self.at, self.act, self.on_start, self.k = at, act, on_start, 0

    def start(self, sample: DaqSample) -> None:
        self.k = 0
        if self.on_start is not None:
            self.on_start()

    def update(self, sample: DaqSample) -> Any:
        self.k += 1
        return self.act() if self.k == self.at else 2.5


def _loop(controller: Controller, timeout_s: float | None = None) -> ClosedLoop:
    rig = make_rig(Parameters(), seed=0)
    rig.reset(0.0, 0.0)
    return ClosedLoop(rig, controller, record=False, controller_timeout_s=timeout_s)


def _run(controller: Controller, timeout_s: float | None = None, ticks: int = 6) -> None:
    loop = _loop(controller, timeout_s)
    loop.start()
    for _ in range(ticks):
        loop.tick()


def _raise(exc: BaseException) -> Callable[[], Any]:
    def act() -> Any:
        raise exc

    return act


@pytest.mark.quick
@pytest.mark.parametrize(
    ("exc", "says"),
    [
        (SystemExit(0), "scripted.update raised SystemExit at tick k = 4 (t = 0.050 s): sys.exit(0)"),
        (SystemExit(), "scripted.update raised SystemExit at tick k = 4 (t = 0.050 s): sys.exit()"),
        (KeyboardInterrupt(), "scripted.update raised KeyboardInterrupt at tick k = 4 (t = 0.050 s)"),
        (GeneratorExit(), "scripted.update raised GeneratorExit at tick k = 4 (t = 0.050 s)"),
        (ValueError("no\ncard"), "scripted.update raised ValueError at tick k = 4 (t = 0.050 s): no card"),
    ],
)
def test_any_base_exception_from_update_fails_the_run(exc: BaseException, says: str) -> None:
    with pytest.raises(ControllerError) as err:
        _run(_Scripted(3, _raise(exc)))
    assert str(err.value) == says
    assert err.value.__cause__ is exc


def test_a_base_exception_from_start_fails_the_run() -> None:
    with pytest.raises(ControllerError, match=r"^scripted\.start raised SystemExit: sys\.exit\(2\)$"):
        _run(_Scripted(on_start=_raise(SystemExit(2))))


def test_the_processs_own_ctrl_c_passes_through() -> None:
    """The SIGINT handler's Interrupted is not the controller's: it is not turned into a failure."""
    with pytest.raises(guard.Interrupted):
        _run(_Scripted(3, _raise(guard.Interrupted())))


@pytest.mark.realtime
@pytest.mark.parametrize("block", ["sleep", "busy"])
def test_a_blocking_update_is_stopped_by_the_watchdog(block: str) -> None:
    def stall() -> None:
        if block == "sleep":
            time.sleep(1e6)
        while True:
            pass

    started = time.monotonic()
    with pytest.raises(ControllerError) as err:
        _run(_Scripted(3, stall), timeout_s=0.2)
    assert (
        str(err.value) == "scripted.update did not return within 0.2 s at tick k = 4 (t = 0.050 s): stalled"
    )
    assert 0.2 <= time.monotonic() - started < 3.0


@pytest.mark.realtime
def test_the_watchdog_works_outside_the_main_thread() -> None:
    """The live view's simulation thread: the call runs in a helper thread, abandoned when it stalls."""
    caught: list[BaseException] = []

    def body() -> None:
        try:
            _run(_Scripted(3, lambda: time.sleep(1e6)), timeout_s=0.2)
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            caught.append(exc)

    thread = threading.Thread(target=body)
    started = time.monotonic()
    thread.start()
    thread.join(5.0)
    assert not thread.is_alive() and time.monotonic() - started < 3.0
    assert len(caught) == 1 and isinstance(caught[0], ControllerError)
    assert "scripted.update did not return within 0.2 s at tick k = 4" in str(caught[0])


def test_a_user_keyboard_interrupt_in_another_thread_is_the_controllers() -> None:
    caught: list[BaseException] = []

    def body() -> None:
        try:
            _run(_Scripted(3, _raise(KeyboardInterrupt())))
        except BaseException as exc:  # noqa: BLE001
            caught.append(exc)

    thread = threading.Thread(target=body)
    thread.start()
    thread.join(10.0)
    assert len(caught) == 1 and isinstance(caught[0], ControllerError), caught
    assert "raised KeyboardInterrupt at tick k = 4" in str(caught[0])


@pytest.mark.quick
@pytest.mark.parametrize(
    ("value", "says"),
    [
        (10**400, "returned 100000000000000000000000… (int, 401 characters) at tick k = 4"),
        (np.array([2.5]), "returned array([2.5]) at tick k = 4 (t = 0.050 s): expected the DAC command"),
        (True, "returned True at tick k = 4"),
        (np.bool_(True), "returned np.True_ at tick k = 4"),
        ("2.5", "returned '2.5' at tick k = 4"),
        (None, "returned None at tick k = 4"),
        (2.5 + 0j, "returned (2.5+0j) at tick k = 4"),
        (math.nan, "returned nan at tick k = 4 (t = 0.050 s): the DAC command must be a finite number"),
        (math.inf, "returned inf at tick k = 4"),
        (np.float64(-math.inf), "returned np.float64(-inf) at tick k = 4"),
        (-1.0, "returned -1.0 V at tick k = 4 (t = 0.050 s): outside the DAC's range"),
        (
            7,
            "returned 7.0 V at tick k = 4 (t = 0.050 s): outside the DAC's range "
            "daq.dac_min_v … daq.dac_max_v = 0.0 … 5.0 V",
        ),
        (5.000001, "returned 5.000001 V"),
    ],
)
def test_a_command_that_is_not_volts_in_the_dac_range_is_refused(value: object, says: str) -> None:
    with pytest.raises(ControllerError) as err:
        _run(_Scripted(3, lambda: value))
    assert str(err.value).startswith("scripted.update ") and says in str(err.value)


@pytest.mark.parametrize("value", [np.float64(1.25), np.float32(1.25), np.int64(3), 3, 0.0, 5.0])
def test_real_numbers_in_the_range_are_the_command(value: object) -> None:
    loop = _loop(_Scripted(1, lambda: value))
    loop.start()
    loop.tick()
    assert type(loop.command_v) is float and loop.command_v == float(value)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("period", "shown"),
    [("0.02", "'0.02'"), (math.nan, "nan"), (0.0, "0.0"), (-0.02, "-0.02"), (True, "True"), (None, "None")],
)
def test_a_bad_period_is_refused_when_the_loop_is_built(period: object, shown: str) -> None:
    controller = _Scripted()
    controller.period_s = period  # type: ignore[assignment]
    with pytest.raises(ControllerError) as err:
        _loop(controller)
    assert str(err.value) == f"scripted: period_s = {shown} must be a positive finite number of seconds"


def test_a_name_or_period_property_that_raises_is_reported() -> None:
    class Nameless(_Scripted):
        @property  # type: ignore[override]
        def name(self) -> str:
            raise SystemExit(1)

        @property  # type: ignore[override]
        def period_s(self) -> float:
            raise KeyboardInterrupt

    with pytest.raises(ControllerError, match=r"^Nameless\.period_s raised KeyboardInterrupt$"):
        _loop(Nameless())


class _Catalogue:
    NAMES = ("scripted",)

    def __init__(self, make: Callable[[], Controller]) -> None:
        self._make = make

    def make(self, name: str, params: Parameters | None = None) -> Controller:
        return self._make()


@pytest.mark.realtime
def test_run_batch_fails_a_scalar_controller_that_exits_or_stalls() -> None:
    starts = {"x0_m": np.array([0.0, 0.05]), "theta0_rad": np.zeros(2), "seeds": np.array([0, 1])}
    with pytest.raises(ControllerError, match=r"raised SystemExit at tick k = 4 \(t = 0\.050 s, run 0\)"):
        run_batch(
            _Catalogue(lambda: _Scripted(3, _raise(SystemExit(0)))), "scripted", duration_s=0.2, **starts
        )
    started = time.monotonic()
    with pytest.raises(ControllerError) as err:
        run_batch(
            _Catalogue(lambda: _Scripted(3, lambda: time.sleep(1e6))),
            "scripted",
            duration_s=0.2,
            controller_timeout_s=0.2,
            **starts,
        )
    assert "scripted.update did not return within 0.2 s at tick k = 4 (t = 0.050 s, run 0): stalled" in str(
        err.value
    )
    assert time.monotonic() - started < 3.0
    with pytest.raises(ControllerError, match=r"returned 7\.0 V at tick k = 4 \(t = 0\.050 s, run 0\)"):
        run_batch(_Catalogue(lambda: _Scripted(3, lambda: 7.0)), "scripted", duration_s=0.2, **starts)


@pytest.mark.quick
def test_healthy_runs_are_unchanged_by_the_guard() -> None:
    """The watchdog and the range check change nothing for a controller that behaves: a built-in's run is
    the same under an infinite and the default budget."""
    from controllers import registry

    a = run_closed_loop(registry.make("appendix-sf"), x0_m=0.1, theta0_rad=0.0, duration_s=1.0)
    b = run_closed_loop(
        registry.make("appendix-sf"), x0_m=0.1, theta0_rad=0.0, duration_s=1.0, controller_timeout_s=math.inf
    )
    assert np.array_equal(a.log.aout, b.log.aout) and np.array_equal(a.log.true_x_m, b.log.true_x_m)
    assert 1.25 <= a.log.aout.min() and a.log.aout.max() <= 3.75  # the software's own limits, inside 0…5 V


@pytest.mark.quick
def test_budgets() -> None:
    assert guard.update_budget_s(0.02) == 1.0  # 10 periods, but at least 1 s
    assert guard.update_budget_s(0.5) == 5.0
    assert guard.update_budget_s(0.02, 0.2) == 0.2
    assert guard.first_call_budget_s() == 30.0 and guard.first_call_budget_s(60.0) == 60.0
    assert guard.first_call_budget_s(0.2) == 30.0
    assert guard.check_timeout_s(math.inf) == math.inf
    for bad in (0, -1.0, math.nan, True, "1"):
        with pytest.raises(ValueError, match="a positive number of seconds"):
            guard.check_timeout_s(bad)  # type: ignore[arg-type]
