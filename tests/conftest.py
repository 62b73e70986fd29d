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


SLOW_TEST_WEIGHT = (
    40  # a slow-marked test costs about as much as this many others (measured: ~20 s against ~0.5 s)
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The order two workers take the files in (``--dist loadfile --no-loadscope-reorder`` hands files out in
    collection order): the costliest first, so no long test starts late and leaves a core idle at the end, and
    the files holding ``realtime`` tests last. A realtime test waits for the other worker's current test before
    it runs alone; among the last files that wait is short, while next to a minutes-long test one core idles for
    its whole rest. The cost is a file's test count with slow tests weighted; the order is the same in every
    worker (xdist requires it)."""
    if not config.pluginmanager.hasplugin("xdist") or not getattr(config.option, "numprocesses", None):
        return
    by_file: dict[str, list[pytest.Item]] = {}
    for item in items:
        by_file.setdefault(item.nodeid.split("::", 1)[0], []).append(item)

    def order(path: str) -> tuple[bool, int, str]:
        tests = by_file[path]
        realtime = any(t.get_closest_marker("realtime") is not None for t in tests)
        cost = sum(SLOW_TEST_WEIGHT if t.get_closest_marker("slow") is not None else 1 for t in tests)
        return realtime, -cost, path

    items[:] = [item for path in sorted(by_file, key=order) for item in by_file[path]]


@pytest.fixture(scope="session")
def params() -> Parameters:
    return Parameters()


@pytest.fixture(scope="session")
def reference(params: Parameters) -> ReferenceModel:
    return ReferenceModel(params)


# A realtime test's pace is not judged on an overloaded machine. Other programs on a shared machine (not this
# suite: a realtime test runs alone) can take both cores. Two measures, each over the test's time from when it
# has the machine to itself (from its setup when a module fixture fails first), in any phase (setup, call,
# teardown): the kernel's pressure-stall information, for what share of the wall-clock time some runnable task
# waited for a CPU; and the share of the machine's CPU time that went to other programs than the test's own
# process and its children. Beyond OVERLOAD_STALL in either, a realtime test's failure is reported as a skip
# naming both: the pace it asserts was not the twin's to keep. The stall alone missed a busy-loop on each core:
# two loops on two cores make nothing wait until the test's task wakes, which then queues behind a loop for the
# CPU, so a test that waits more than it computes stalled little (median 5.6 %) and still missed its pace; the
# others' share is the loops' then (99 % measured), while the test's own processes (chromium, the view, a C
# client) are never counted as others, so a heavy test on a quiet machine is still judged.
OVERLOAD_STALL = 0.5
# (monotonic s, stall s, machine busy CPU-s, own CPU-s) when the clock started, and when the setup started.
_STALL = pytest.StashKey[tuple[float, float, float, float]]()
_SETUP = pytest.StashKey[tuple[float, float, float, float]]()


def _machine_busy_s() -> tuple[float, int] | None:
    """(CPU-seconds the machine's CPUs were busy since boot, their number) from /proc/stat; None where the
    kernel does not tell."""
    try:  # BALLBEAM_TEST_STAT: another file in its format (tests/test_realtime_markers.py)
        with open(os.environ.get("BALLBEAM_TEST_STAT", "/proc/stat")) as f:
            lines = f.read().splitlines()
        fields = [float(v) for v in lines[0].split()[1:9]]  # user nice system idle iowait irq softirq steal
        cpus = sum(1 for line in lines if line.startswith("cpu") and line[3:4].isdigit())
        busy = fields[0] + fields[1] + fields[2] + fields[5] + fields[6] + fields[7]
        return busy / os.sysconf("SC_CLK_TCK"), max(cpus, 1)
    except (OSError, ValueError, IndexError):
        return None


def _process_cpu_s(stat: str) -> tuple[int, float]:
    """(parent pid, CPU-seconds of the process and its reaped children) of a /proc/PID/stat line."""
    fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) "; comm may hold spaces
    ticks = sum(float(v) for v in fields[11:15])  # utime stime cutime cstime
    return int(fields[1]), ticks / os.sysconf("SC_CLK_TCK")


def _own_cpu_s() -> float:
    """CPU-seconds of this process, its reaped children and its live descendants (a view, a browser)."""
    me = os.getpid()
    parents: dict[int, int] = {}
    cpu: dict[int, float] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                parents[int(entry)], cpu[int(entry)] = _process_cpu_s(f.read())
        except (OSError, ValueError, IndexError):
            continue  # ended meanwhile
    total = 0.0
    for pid, seconds in cpu.items():
        p, seen = pid, 0
        while p not in (0, 1, me) and seen < 64:
            p, seen = parents.get(p, 0), seen + 1
        if p == me:
            total += seconds
    return total


def _clock() -> tuple[float, float, float, float] | None:
    """(monotonic s, stall s, machine busy CPU-s, own CPU-s) now; None where the kernel does not tell."""
    stall, busy = _cpu_stall_s(), _machine_busy_s()
    if stall is None or busy is None:
        return None
    return time.monotonic(), stall, busy[0], _own_cpu_s()


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
def pytest_runtest_setup(item: pytest.Item) -> Iterator[None]:
    """A realtime test's clock from the start of its setup, for a failure before its own clock starts (a
    module fixture's: the view it serves did not start in time)."""
    if item.get_closest_marker("realtime") is not None:
        now = _clock()
        if now is not None:
            item.stash[_SETUP] = now
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    outcome = yield
    report = outcome.get_result()  # type: ignore[attr-defined]
    start = item.stash.get(_STALL, None) or item.stash.get(_SETUP, None)
    if start is None or (call.when == "setup" and not report.failed):
        return
    now, cpus = _clock(), _machine_busy_s()
    if now is None or cpus is None:
        return
    wall = max(now[0] - start[0], 1e-9)
    stall = (now[1] - start[1]) / wall
    others = ((now[2] - start[2]) - (now[3] - start[3])) / (cpus[1] * wall)
    if call.when == "call" or report.failed:
        report.user_properties += [
            ("cpu_stall_share", round(stall, 3)),
            ("others_cpu_share", round(others, 3)),
        ]
    if report.failed and max(stall, others) > OVERLOAD_STALL:
        report.outcome = "skipped"
        report.longrepr = (
            str(item.path),
            item.location[1] or 0,
            f"Skipped: the machine was overloaded (a task waited for a CPU {100 * stall:.0f} % of the time; "
            f"other programs kept its {cpus[1]} CPUs {100 * others:.0f} % busy; the limit is "
            f"{100 * OVERLOAD_STALL:.0f} % for either) in the {call.when} of this test: a wall-clock pace "
            "cannot be judged",
        )


@pytest.fixture(autouse=True)
def _realtime_runs_alone(request: pytest.FixtureRequest) -> Iterator[None]:
    """Under pytest-xdist (the default run: two workers), a test marked ``realtime`` — one that asserts a
    wall-clock pace: commands late or missing, a watchdog, jitter — waits for the other worker's test to end
    and holds it off until it is done; the others share. A turnstile in front of a shared/exclusive lock
    (flock) keeps new shared holders from starving the exclusive one."""
    alone = request.node.get_closest_marker("realtime") is not None

    def clock_starts() -> None:  # the load is measured from when the test has the machine to itself
        now = _clock() if alone else None
        if now is not None:
            request.node.stash[_STALL] = now

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


MANUAL_WIRE_PORT = 5751  # the UDP port the manual's recipes serve on and its C client talks to


@pytest.fixture
def manual_wire_port() -> Iterator[int]:
    """``MANUAL_WIRE_PORT`` for this test alone: under pytest-xdist a test that pastes the manual's serving
    recipes holds an exclusive lock on the port for its duration, so two such tests on the two workers take
    turns instead of one finding it taken."""
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if run is None:
        yield MANUAL_WIRE_PORT
        return
    with open(Path(tempfile.gettempdir()) / f"ballbeam-pytest-{run}.port{MANUAL_WIRE_PORT}", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield MANUAL_WIRE_PORT
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """The refusal must come before any run: starting one (a run, a sweep's, Monte Carlo's or validate's runs,
    the live view) fails the test."""

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("the work started although an argument was bad")

    for target in (
        "twin.rigs.sim.run_closed_loop",
        "twin.app.validate.run_starts",
        "twin.app.sweep.run_starts",
        "twin.app.montecarlo.run_starts",
        "twin.viewer.serve",
    ):
        monkeypatch.setattr(target, fail)
