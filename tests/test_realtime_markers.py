"""A test that asserts a wall-clock pace is marked ``realtime`` (it then runs while no other test does:
tests/conftest.py). Read from the test sources with ``ast``, so nothing runs.

The rule. A *clock reading* is a call of ``time.perf_counter``, ``time.monotonic`` or ``time.time`` (or their
``_ns`` forms, also imported bare). A name is a reading when it is bound (``=``, ``:=``, ``+=``, a ``for``
target, a container it is appended to) from an expression holding a reading. A *measurement* is a
difference of readings (``a - b`` with a reading on either side, ``np.diff`` of one), or a name bound from an
expression holding a measurement, or a function of the file whose ``return`` or ``yield`` holds one (called,
passed on, or a fixture's value in the test that asks for it). A test asserts a pace
when one of its ``assert`` statements holds a measurement, or reads one of the counters the wire counts
against the wall clock (``late_commands``, ``missing_commands``, ``watchdog_trips``: commands that missed
their deadline) — in its own body, in a function or method of its file it calls (by name, to any depth), or
in a fixture it asks for (of its file or of tests/conftest.py, to any depth). Such a test carries
``@pytest.mark.realtime`` (itself, its class or its module's ``pytestmark``), or is listed in ``LOAD_PROOF``
below with the reason load cannot fail its measurement (a hang guard far above the time taken, a lower bound
that a slower machine only helps).

A wait's time-out written as a deadline (``assert time.monotonic() < deadline`` in a polling loop) compares a
reading with a reading, not a measurement: it bounds a hang, and is not caught. The rule is a floor: a test
whose pace shows only in what it asserts of the simulated time against a ``sleep`` (the live view's pacing
under a bypassed speed) is marked by hand."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
CLOCKS = {"perf_counter", "monotonic", "time", "perf_counter_ns", "monotonic_ns", "time_ns"}
COUNTERS = {"late_commands", "missing_commands", "watchdog_trips"}  # counted against the wall clock

# Tests whose asserted measurement load cannot fail, with the reason.
LOAD_PROOF = {
    "test_user_code.py::test_a_misbehaving_user_controller_fails_the_command": (
        "seconds < BOUND_S (30 s) for commands of a few seconds, and subprocess.run(timeout=BOUND_S) enforces the"
        " same bound; measured in a module fixture, which a realtime mark (a function fixture) would not cover"
    ),
    "test_user_code.py::test_worker_processes_fail_the_run_too": (
        "seconds < BOUND_S (30 s) around one command of a few seconds, which subprocess.run(timeout=BOUND_S)"
        " enforces too"
    ),
    "test_wire.py::test_a_ten_second_flood_leaves_the_session_alive_and_its_state_unchanged": (
        "wall_s > flood_s: a lower bound that load only helps (the _Paced controller sleeps to each block's"
        " deadline, so the 12 s session lasts at least 12 s); the session is lock-step, so its numbers do not"
        " depend on time"
    ),
}


def _dotted(node: ast.AST) -> str:
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    return ".".join([node.id, *reversed(parts)]) if isinstance(node, ast.Name) else ""


def _is_clock(node: ast.AST) -> bool:
    if not isinstance(node, ast.Call):
        return False
    name = _dotted(node.func)
    return name in {f"time.{c}" for c in CLOCKS} or name in CLOCKS - {"time"}


@dataclass
class _Taint:
    """The names of one function that hold readings and measurements; the functions that return one."""

    measuring: set[str]  # functions of the file whose return holds a measurement
    readings: set[str] = field(default_factory=set)
    measures: set[str] = field(default_factory=set)

    def reads(self, node: ast.AST) -> bool:
        return any(
            _is_clock(n) or (isinstance(n, ast.Name) and n.id in self.readings | self.measures)
            for n in ast.walk(node)
        )

    def measures_in(self, node: ast.AST) -> bool:
        for n in ast.walk(node):
            if isinstance(n, ast.Name) and n.id in self.measures | self.measuring:
                return True
            if (
                isinstance(n, ast.BinOp)
                and isinstance(n.op, ast.Sub)
                and (self.reads(n.left) or self.reads(n.right))
            ):
                return True
            if isinstance(n, ast.Call):
                name = _dotted(n.func)
                if name.endswith(".diff") and any(self.reads(a) for a in n.args):
                    return True
                if name.split(".")[-1] in self.measuring:
                    return True
        return False


def _names(target: ast.AST) -> Iterator[str]:
    for n in ast.walk(target):
        if isinstance(n, ast.Name):
            yield n.id


def _bindings(function: ast.AST) -> Iterator[tuple[list[str], ast.AST]]:
    """(names bound, the expression bound from) for every binding in a function, nested ones included."""
    for n in ast.walk(function):
        if isinstance(n, ast.Assign):
            yield [x for t in n.targets for x in _names(t)], n.value
        elif isinstance(n, (ast.AnnAssign, ast.AugAssign)) and n.value is not None:
            yield list(_names(n.target)), n.value
        elif isinstance(n, ast.NamedExpr):
            yield [n.target.id], n.value
        elif isinstance(n, (ast.For, ast.comprehension)):
            yield list(_names(n.target)), n.iter
        elif (
            isinstance(n, ast.Call)
            and isinstance(n.func, ast.Attribute)
            and n.func.attr in {"append", "extend", "add"}
            and isinstance(n.func.value, ast.Name)
        ):
            yield [n.func.value.id], ast.Tuple(elts=list(n.args), ctx=ast.Load())


def _taint(function: ast.AST, measuring: set[str]) -> _Taint:
    taint = _Taint(measuring)
    changed = True
    while changed:
        changed = False
        for names, value in _bindings(function):
            into = (
                taint.measures if taint.measures_in(value) else taint.readings if taint.reads(value) else None
            )
            if into is not None and not set(names) <= into:
                into.update(names)
                changed = True
    return taint


def _asserts_pace(function: ast.AST, measuring: set[str]) -> bool:
    taint = _taint(function, measuring)
    for n in ast.walk(function):
        if isinstance(n, ast.Assert) and (
            taint.measures_in(n.test)
            or any(isinstance(a, ast.Attribute) and a.attr in COUNTERS for a in ast.walk(n.test))
        ):
            return True
    return False


def _functions(tree: ast.Module) -> dict[str, ast.FunctionDef | ast.AsyncFunctionDef]:
    """The file's functions and methods by name (a method by its own name)."""
    found = {}
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found.setdefault(node.name, node)
    return found


def _called(function: ast.AST) -> set[str]:
    """The names a function calls (``f()``, ``obj.f()``) or passes on (``key=f``)."""
    names = set()
    for n in ast.walk(function):
        if isinstance(n, ast.Call):
            names.add(n.func.attr if isinstance(n.func, ast.Attribute) else getattr(n.func, "id", ""))
        elif isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load):
            names.add(n.id)
    return names


def _marks(decorators: Iterable[ast.expr]) -> set[str]:
    found = set()
    for d in decorators:
        name = _dotted(d.func if isinstance(d, ast.Call) else d)
        if name.startswith("pytest.mark."):
            found.add(name.removeprefix("pytest.mark."))
    return found


def _is_fixture(function: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    return any(
        _dotted(d.func if isinstance(d, ast.Call) else d) == "pytest.fixture" for d in function.decorator_list
    )


def _pacing(functions: dict[str, ast.FunctionDef | ast.AsyncFunctionDef]) -> set[str]:
    """The functions of a file that assert a pace, themselves or through the functions they call."""
    measuring: set[str] = set()
    changed = True
    while changed:  # functions returning a measurement, through each other
        changed = False
        for name, f in functions.items():
            if name not in measuring:
                taint = _taint(f, measuring)
                if any(
                    isinstance(n, (ast.Return, ast.Yield)) and n.value and taint.measures_in(n.value)
                    for n in ast.walk(f)
                ):
                    measuring.add(name)
                    changed = True
    pacing = {name for name, f in functions.items() if _asserts_pace(f, measuring)}
    changed = True
    while changed:
        changed = False
        for name, f in functions.items():
            if name not in pacing and _called(f) & pacing:
                pacing.add(name)
                changed = True
    return pacing


def _paces(
    function: ast.FunctionDef | ast.AsyncFunctionDef,
    pacing: set[str],
    fixtures: dict[str, ast.FunctionDef | ast.AsyncFunctionDef],
    seen: frozenset[str] = frozenset(),
) -> bool:
    """The function asserts a pace, or a fixture it asks for does (to any depth)."""
    if function.name in pacing:
        return True
    asked = [a.arg for a in function.args.args + function.args.kwonlyargs]
    return any(
        _paces(fixtures[a], pacing, fixtures, seen | {a})
        for a in asked
        if a in fixtures and a not in seen and a != function.name
    )


def unmarked_pace_tests(paths: Iterable[Path], conftest: Path | None = TESTS / "conftest.py") -> list[str]:
    """``file::test`` for every test in ``paths`` that asserts a pace, is not marked realtime and is not listed as
    load-proof."""
    shared: dict[str, ast.FunctionDef | ast.AsyncFunctionDef] = {}
    if conftest is not None and conftest.exists():
        shared = {n: f for n, f in _functions(ast.parse(conftest.read_text())).items() if _is_fixture(f)}
    found = []
    for path in paths:
        tree = ast.parse(path.read_text())
        functions = _functions(tree)
        fixtures = {**shared, **{n: f for n, f in functions.items() if _is_fixture(f)}}
        pacing = _pacing({**shared, **functions})
        module_marks = {
            m
            for node in tree.body
            if isinstance(node, ast.Assign)
            and any(getattr(t, "id", "") == "pytestmark" for t in node.targets)
            for m in _marks(node.value.elts if isinstance(node.value, ast.List) else [node.value])
        }

        owners: list[tuple[set[str], ast.FunctionDef | ast.AsyncFunctionDef]] = []
        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                owners.append((set(), node))
            elif isinstance(node, ast.ClassDef) and node.name.startswith("Test"):
                owners += [
                    (_marks(node.decorator_list), m)
                    for m in node.body
                    if isinstance(m, (ast.FunctionDef, ast.AsyncFunctionDef))
                ]
        for class_marks, test in owners:
            if not test.name.startswith("test") or _is_fixture(test):
                continue
            marked = "realtime" in _marks(test.decorator_list) | class_marks | module_marks
            key = f"{path.name}::{test.name}"
            if not marked and key not in LOAD_PROOF and _paces(test, pacing, fixtures):
                found.append(key)
    return found


@pytest.mark.quick
def test_every_test_that_asserts_a_pace_is_marked_realtime() -> None:
    unmarked = unmarked_pace_tests(sorted(TESTS.glob("test_*.py")))
    assert not unmarked, f"these assert a wall-clock pace: mark them @pytest.mark.realtime: {unmarked}"


@pytest.mark.quick
def test_the_tests_listed_as_load_proof_still_measure() -> None:
    """A listed test that no longer asserts a measurement (or is marked realtime now) leaves the list."""
    for key in LOAD_PROOF:
        name, test = key.split("::")
        saved = LOAD_PROOF.pop(key)
        try:
            assert unmarked_pace_tests([TESTS / name]).count(key) == 1, f"{key} measures nothing now"
        finally:
            LOAD_PROOF[key] = saved


@pytest.mark.quick
def test_the_rule_bites(tmp_path: Path) -> None:
    """A crafted file: the forms the rule catches, unmarked, are found; the same tests marked, the time-out of a
    wait, a fake clock's reading and a test that measures without asserting are not."""
    body = """
import time
import numpy as np
import pytest
from time import perf_counter


class Server:
    def ticking(self):
        stamps = []
        for _ in range(3):
            stamps.append(time.perf_counter())
        assert np.max(np.diff(stamps)) < 0.03


def _elapsed(f):
    start = time.monotonic()
    f()
    return time.monotonic() - start


@pytest.fixture
def server():
    s = Server()
    yield s
    s.ticking()


@pytest.fixture
def client(server):
    return 1


def test_direct():
    start = perf_counter()
    assert perf_counter() - start < 1.0


def test_walrus_and_a_derived_name():
    start = time.time()
    while (now := time.time()) - start < 0.1:
        pass
    rate = 5 / (now - start)
    assert rate > 1


def test_through_a_helper_that_returns_a_measurement():
    seconds = _elapsed(lambda: None)
    assert seconds < 3.0


def test_through_a_method(server):
    server.ticking()


def test_through_a_fixture_of_a_fixture(client):
    assert client == 1


@pytest.fixture
def outcomes():
    return {"run": _elapsed(lambda: None)}


def test_through_a_fixtures_value(outcomes):
    assert outcomes["run"] < 30.0


def test_a_counter(counts):
    assert counts.missing_commands == 0


@pytest.mark.realtime
def test_marked(server):
    start = time.perf_counter()
    assert time.perf_counter() - start < 1.0


def test_a_waits_time_out():
    deadline = time.monotonic() + 120.0
    while False:
        assert time.monotonic() < deadline


def test_measured_but_not_asserted():
    start = time.perf_counter()
    print(time.perf_counter() - start)


def test_a_fake_clock():
    clock = [100.0]
    assert clock[0] - 100.0 == 0.0


@pytest.mark.realtime
class TestMarked:
    def test_in_a_marked_class(self):
        start = time.monotonic()
        assert time.monotonic() - start < 1.0
"""
    path = tmp_path / "test_crafted.py"
    path.write_text(body)
    assert unmarked_pace_tests([path], conftest=None) == [
        f"test_crafted.py::{name}"
        for name in (
            "test_direct",
            "test_walrus_and_a_derived_name",
            "test_through_a_helper_that_returns_a_measurement",
            "test_through_a_method",
            "test_through_a_fixture_of_a_fixture",
            "test_through_a_fixtures_value",
            "test_a_counter",
        )
    ]
    path.write_text("import pytest\npytestmark = [pytest.mark.realtime]\n" + body)
    assert unmarked_pace_tests([path], conftest=None) == []


def test_a_realtime_failure_on_an_overloaded_machine_is_a_skip_naming_the_load(tmp_path: Path) -> None:
    """tests/conftest.py judges a realtime test's pace only when the machine gave it the CPU: a failure while
    tasks waited for a CPU more than OVERLOAD_STALL of the test's time is a skip saying so; the same failure
    on a machine that did not wait stays a failure. The kernel's pressure file is a stand-in here, advanced
    by the test itself (0.2 s of stall over ~0.3 s)."""
    psi = tmp_path / "cpu"
    psi.write_text("some avg10=0.00 avg60=0.00 avg300=0.00 total=0\n")
    (tmp_path / "test_pace.py").write_text(
        "import pathlib, time, pytest\n\n"
        "@pytest.mark.realtime\n"
        "def test_overloaded():\n"
        "    time.sleep(0.3)\n"
        f"    pathlib.Path({str(psi)!r}).write_text('some avg10=0 avg60=0 avg300=0 total=200000\\n')\n"
        "    assert False, 'pace missed'\n\n"
        "@pytest.mark.realtime\n"
        "def test_idle():\n"
        "    time.sleep(0.3)\n"
        "    assert False, 'pace missed'\n"
    )
    stat = tmp_path / "stat"  # a machine whose CPUs are never busy: the others' share is nil
    stat.write_text(_STAT.format(busy=0))
    out = _run_beside(tmp_path, psi, stat)
    assert "1 failed, 1 skipped" in out.stdout, out.stdout + out.stderr
    assert "test_idle" in out.stdout and "FAILED" in out.stdout
    assert "the machine was overloaded (a task waited for a CPU" in out.stdout


# /proc/stat's first lines: user nice system idle iowait irq softirq steal guest guest_nice, in clock ticks.
_STAT = "cpu  {busy} 0 0 1000 0 0 0 0 0 0\ncpu0 0 0 0 0 0 0 0 0 0 0\ncpu1 0 0 0 0 0 0 0 0 0 0\n"


def _run_beside(tmp_path: Path, psi: Path, stat: Path) -> subprocess.CompletedProcess[str]:
    """tmp_path's tests under tests/conftest.py, with stand-ins for the kernel's pressure and CPU files."""
    shutil.copy(Path(__file__).with_name("conftest.py"), tmp_path / "conftest.py")
    env = {
        **os.environ,
        "BALLBEAM_TEST_PSI": str(psi),
        "BALLBEAM_TEST_STAT": str(stat),
        "PYTHONPATH": str(Path(__file__).parents[1]),
    }
    env.pop("PYTEST_XDIST_TESTRUNUID", None)
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-rsf", "-p", "no:cacheprovider", "-p", "no:randomly", str(tmp_path)],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120,
    )  # fmt: skip


def test_a_busy_loop_on_each_core_is_seen_though_nothing_waits(tmp_path: Path) -> None:
    """Two busy-loops on two cores make nothing wait (the stall stays 0) until the test's own task wakes and
    queues behind one: the CPU time other programs took says the machine was not the test's. A realtime
    failure in its call, in a fixture's setup (before the test's own clock starts: a module fixture) or in its
    teardown is then a skip naming the load; with the CPUs idle the same failures stay failures."""
    psi = tmp_path / "cpu"
    psi.write_text("some avg10=0.00 avg60=0.00 avg300=0.00 total=0\n")
    stat = tmp_path / "stat"
    stat.write_text(_STAT.format(busy=0))
    # Each test sleeps 0.3 s, then the stand-in says the CPUs were busy for 6 s more (600 clock ticks) since.
    busy = (
        f"p = pathlib.Path({str(stat)!r}); "
        f"p.write_text({_STAT!r}.format(busy=int(p.read_text().split()[1]) + 600))"
    )
    (tmp_path / "test_hogs.py").write_text(
        "import pathlib, time, pytest\n\n"
        f"def _hogs():\n    time.sleep(0.3)\n    {busy}\n\n"
        "@pytest.fixture(scope='module')\n"
        "def served():\n    _hogs()\n    raise AssertionError('the view did not start in time')\n\n"
        "@pytest.fixture\n"
        "def teardown_waits():\n    yield\n    _hogs()\n    raise AssertionError('the view did not stop in time')\n\n"
        "@pytest.mark.realtime\n"
        "def test_call():\n    _hogs()\n    assert False, 'pace missed'\n\n"
        "@pytest.mark.realtime\n"
        "def test_setup(served):\n    pass\n\n"
        "@pytest.mark.realtime\n"
        "def test_teardown(teardown_waits):\n    pass\n"
    )
    out = _run_beside(tmp_path, psi, stat)
    assert "3 skipped" in out.stdout and "failed" not in out.stdout and "error" not in out.stdout, out.stdout
    assert out.stdout.count("other programs kept its 2 CPUs") == 3, out.stdout
    for phase in ("call", "setup", "teardown"):
        assert f"in the {phase} of this test" in out.stdout, out.stdout
    # The same failures on a machine whose CPUs stay idle: failures (the test's own CPU is not counted).
    (tmp_path / "test_hogs.py").write_text((tmp_path / "test_hogs.py").read_text().replace(busy, "pass"))
    stat.write_text(_STAT.format(busy=0))
    out = _run_beside(tmp_path, psi, stat)
    assert "1 failed" in out.stdout and "2 error" in out.stdout and "skipped" not in out.stdout, out.stdout
