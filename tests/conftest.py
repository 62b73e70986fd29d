"""Shared fixtures: the default parameters and the analytic reference model; a ``realtime`` test runs alone."""

import fcntl
import os
import tempfile
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


@pytest.fixture(autouse=True)
def _realtime_runs_alone(request: pytest.FixtureRequest) -> Iterator[None]:
    """Under pytest-xdist (the default run: two workers), a test marked ``realtime`` — one that asserts a
    wall-clock pace: commands late or missing, a watchdog, jitter — waits for the other worker's test to end
    and holds it off until it is done; the others share. A turnstile in front of a shared/exclusive lock
    (flock) keeps new shared holders from starving the exclusive one."""
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if run is None:  # one process: nothing else runs
        yield
        return
    base = Path(tempfile.gettempdir()) / f"ballbeam-pytest-{run}"
    alone = request.node.get_closest_marker("realtime") is not None
    with open(f"{base}.turnstile", "a") as gate, open(f"{base}.lock", "a") as lock:
        fcntl.flock(gate, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        fcntl.flock(lock, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        if not alone:
            fcntl.flock(gate, fcntl.LOCK_UN)
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
