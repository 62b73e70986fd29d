"""Shared fixtures: the default parameters and the analytic reference model; a ``realtime`` test runs alone,
and its pace is judged only when the machine gave it the CPU."""

import fcntl
import os
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from twin.parameters import Parameters
from twin.reference import ReferenceModel


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config: pytest.Config) -> None:
    """The quick tier (``-m quick``) runs in one process unless ``-n`` is given on the command line: each xdist
    worker collects every test file, and for the quick tier's few seconds of tests that second collection costs
    more than the second worker saves (measured: 20–24 s in one process, 30–40 s on two workers, on a shared
    two-core machine)."""
    explicit = any(a.startswith(("-n", "--numprocesses")) for a in config.invocation_params.args)
    if (
        (config.option.markexpr or "").strip() == "quick"
        and not explicit
        and hasattr(config.option, "numprocesses")
    ):
        config.option.numprocesses = 0


@pytest.fixture(scope="session")
def params() -> Parameters:
    return Parameters()


@pytest.fixture(scope="session")
def reference(params: Parameters) -> ReferenceModel:
    return ReferenceModel(params)


# A realtime test's pace is not judged on an overloaded machine. Other programs on a shared machine (not this
# suite: a realtime test runs alone) can take both cores; the kernel's pressure-stall information says for what
# share of the test's wall-clock time some runnable task waited for a CPU. Beyond OVERLOAD_STALL the failure
# of a realtime test is reported as a skip naming that share: the pace it asserts was not the twin's to keep.
# Measured over the 27 realtime tests (docs/design.md): alone on the quiet 2-core machine median 0.9 %, at most
# 25 % (the browser test's own chromium, view and C client); beside a busy-loop on each core median 5.6 %, at
# most 84 % (the same test). A test that waits more than it computes stalls little even then.
OVERLOAD_STALL = 0.5
_STALL = pytest.StashKey[tuple[float, float]]()


def _cpu_stall_s() -> float | None:
    """Seconds some task has waited for a CPU since boot (/proc/pressure/cpu), None where the kernel does
    not tell."""
    try:  # BALLBEAM_TEST_PSI: another file in its format (tests/test_realtime_markers.py)
        with open(os.environ.get("BALLBEAM_TEST_PSI", "/proc/pressure/cpu")) as f:
            some = f.readline().split()
        return float(dict(kv.split("=") for kv in some[1:])["total"]) / 1e6
    except (OSError, KeyError, ValueError, IndexError):
        return None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    outcome = yield
    report = outcome.get_result()  # type: ignore[attr-defined]
    start = item.stash.get(_STALL, None)
    stall = _cpu_stall_s()
    if start is None or stall is None or call.when == "setup":
        return
    share = (stall - start[1]) / max(time.monotonic() - start[0], 1e-9)
    report.user_properties.append(("cpu_stall_share", round(share, 3)))
    if report.failed and share > OVERLOAD_STALL:
        report.outcome = "skipped"
        report.longrepr = (
            str(item.path),
            item.location[1] or 0,
            f"Skipped: the machine was overloaded (a task waited for a CPU {100 * share:.0f} % of the time, "
            f"over {100 * OVERLOAD_STALL:.0f} %): a wall-clock pace cannot be judged",
        )


@pytest.fixture(autouse=True)
def _realtime_runs_alone(request: pytest.FixtureRequest) -> Iterator[None]:
    """Under pytest-xdist (the default run: two workers), a test marked ``realtime`` — one that asserts a
    wall-clock pace: commands late or missing, a watchdog, jitter — waits for the other worker's test to end
    and holds it off until it is done; the others share. A turnstile in front of a shared/exclusive lock
    (flock) keeps new shared holders from starving the exclusive one."""
    alone = request.node.get_closest_marker("realtime") is not None

    def clock_starts() -> None:  # the stall is measured from when the test has the machine to itself
        stall = _cpu_stall_s() if alone else None
        if stall is not None:
            request.node.stash[_STALL] = (time.monotonic(), stall)

    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if run is None:  # one process: nothing else runs
        clock_starts()
        yield
        return
    base = Path(tempfile.gettempdir()) / f"ballbeam-pytest-{run}"
    with open(f"{base}.turnstile", "a") as gate, open(f"{base}.lock", "a") as lock:
        fcntl.flock(gate, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        fcntl.flock(lock, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        if not alone:
            fcntl.flock(gate, fcntl.LOCK_UN)
        clock_starts()
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
            if alone:
                fcntl.flock(gate, fcntl.LOCK_UN)


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """The refusal must come before any run: starting one (a run, a sweep's, Monte Carlo's or validate's runs,
    the live view) fails the test."""

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("the work started although an argument was bad")

    for target in (
        "twin.engine.run_closed_loop",
        "twin.app.validate.run_starts",
        "twin.app.sweep.run_starts",
        "twin.app.montecarlo.run_starts",
        "twin.viewer.serve",
    ):
        monkeypatch.setattr(target, fail)
