"""Served jobs (``sweep``/``montecarlo``/``validate --serve``, ``twin.app.fanout.run_served``): every run one
lock-step session of protocol 1 to a client that runs many sessions (``run --rig … --sessions``, ``bb_sf
--sessions``). The records come from the twin's true state as in process, so with a client computing what
the in-process controller computes they are the in-process job's, bit for bit (compared as JSON text:
``repr`` of every float, so -0.0 and the last bit count)."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_checks import refused

from controllers import registry
from controllers.thesis_numbers import HARDWARE_STARTS
from twin.app.fanout import Runs, Served, run_starts
from twin.app.montecarlo import MonteCarloSettings, load_spread, run_montecarlo
from twin.app.sweep import Grid, SweepSettings, point_seeds, run_sweep
from twin.engine import run_on_rig
from twin.parameters import Parameters
from twin.rigs.remote import RemoteError
from twin.rigs.session import connect as _connect
from twin.serving.server import Server, SessionSettings

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
CLI = [sys.executable, "-m", "twin.app.cli"]
SMALL = SweepSettings("appendix-sf", x0=Grid(-0.2, 0.2, 3), theta0=Grid(-0.3, 0.3, 3), duration_s=2.0)


def same(a: Any, b: Any) -> bool:
    """Equal as JSON text: every float by its repr (its bits, up to NaN's payload)."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def python_client(
    port: int, *, sessions: int = 0, die_in: int = 0, die_after: int = 20, wait_s: float = 2.0
) -> dict[str, Any]:
    """appendix-sf sessions on ``port`` as ``run --rig --sessions N`` runs them (0: until no server answers
    HELLO within ``wait_s``); ``die_in`` (1-based): in that session stop answering after ``die_after``
    updates and drop the socket (no STOP), then carry on with a new one. Returns what it saw."""
    seen: dict[str, Any] = {"sessions": 0, "ended": []}
    while sessions == 0 or seen["sessions"] < sessions:
        try:
            rig = _connect(f"udp://127.0.0.1:{port}", "py appendix-sf", wait_s, retry_refused=True)
        except RemoteError:
            break
        seen["sessions"] += 1
        with rig:
            controller = registry.make("appendix-sf", rig.parameters())
            if seen["sessions"] == die_in:
                controller.start(rig.read())
                for _ in range(die_after):
                    rig.write(controller.update(rig.read()))
                seen["ended"].append("died")
                # no answer and no STOP: the server hears nothing more; the client starts again at once and is
                # refused until the dead session has timed out, asking again as run --rig --sessions does
                continue
            run = run_on_rig(controller, rig)
            seen["ended"].append(run.ended)
            try:  # the server's STOP, so that the next HELLO meets the next session
                while True:
                    rig.read()
            except RemoteError:
                pass
    return seen


@contextmanager
def client_thread(port: int, **kw: Any) -> Iterator[dict[str, Any]]:
    box: dict[str, Any] = {}

    def target() -> None:
        box.update(python_client(port, **kw))

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    try:
        yield box
    finally:
        thread.join(60.0)
        assert not thread.is_alive(), "the client hung"


def served(**kw: Any) -> Served:
    return Served(Server(SessionSettings(), log=lambda _: None), **{"next_wait_s": 3.0, **kw})


def test_a_served_sweep_equals_the_in_process_sweep_bit_for_bit() -> None:
    t0 = time.perf_counter()
    ref = run_sweep(SMALL)
    in_process_s = time.perf_counter() - t0
    job = served()
    with job.server, client_thread(job.server.port) as client:
        t0 = time.perf_counter()
        got = run_sweep(SMALL, serve=job)
        served_s = time.perf_counter() - t0
    print(f"3×3 grid + 1 corner, 2 s runs: in process {in_process_s:.2f} s, served {served_s:.2f} s")
    assert got.complete and len(got.points) == 9 and len(got.corners) == 1
    assert same(got.points, ref.points) and same(got.corners, ref.corners) and same(got.claims, ref.claims)
    assert not any(p["failed"] for p in got.points)
    # the report is the in-process one plus where it was served and who came
    assert {k: v for k, v in got.to_json().items() if k != "served"} == ref.to_json()
    assert got.served == {"url": job.server.url, "clients": ["py appendix-sf"], "sessions": 10}
    assert client["sessions"] == 10 and client["ended"] == ["last sample"] * 10


SPREAD = """
[motor]
resistance_ohm = { low = 9.35, high = 10.14 }
[beam]
inertia_pivot_kgm2 = { low = 3.5e-3, high = 4.5e-3 }
[ball_sensor]
rc_capacitance_f = { low = 17.6e-6, high = 26.4e-6 }
"""


def test_a_served_montecarlo_equals_the_in_process_one_bit_for_bit(tmp_path: Path) -> None:
    path = tmp_path / "spread.toml"
    path.write_text(SPREAD)
    p = Parameters()
    spread = load_spread(path, p)
    settings = MonteCarloSettings("appendix-sf", 4, duration_s=3.0, seed=7)
    ref = run_montecarlo(settings, p, spread)
    job = served()
    with job.server, client_thread(job.server.port):
        got = run_montecarlo(settings, p, spread, serve=job)
    assert got.complete and same(got.runs, ref.runs) and same(got.summary, ref.summary)
    # the parameters differ run to run (the server's rig, not the client's: CONFIG carries no physics)
    assert len({r["parameters"]["motor.resistance_ohm"] for r in got.runs}) == 4


def test_a_client_that_dies_mid_job_fails_its_run_and_the_job_goes_on() -> None:
    """Session 2's client stops answering (as a crashed one): after --timeout that run is recorded
    failed with the server's reason; the client's next connection runs the rest, equal to in process."""
    settings = SweepSettings("sf-by-wire", x0=Grid(-0.1, 0.1, 3), theta0=Grid(0.1, 0.1, 1), duration_s=2.0)
    in_process = SweepSettings("appendix-sf", settings.x0, settings.theta0, duration_s=2.0)
    ref = run_sweep(in_process).points
    job = served(timeout_s=0.5)
    with job.server, client_thread(job.server.port, die_in=2) as client:
        got = run_sweep(settings, serve=job)
    assert got.complete and client["ended"] == ["last sample", "died", "last sample"]
    assert same(got.points[0], ref[0]) and same(got.points[2], ref[2])
    dead = got.points[1]
    assert dead["failed"] and not dead["held"] and dead["settling_time_s"] is None
    assert dead["reason"] == "the controller failed: 'py appendix-sf': no COMMAND 21 within 0.5 s (--timeout)"
    assert (dead["x0_m"], dead["theta0_rad"], dead["seed"]) == (ref[1]["x0_m"], 0.1, ref[1]["seed"])


@pytest.mark.realtime
def test_no_client_within_the_wait_ends_the_job_with_the_runs_done() -> None:
    """A client that leaves after one session: the next session waits ``next_wait_s`` and the job ends
    there, incomplete, the first run kept and why it stopped said."""
    runs = Runs("appendix-sf", Parameters(), 1.0, True, "twin", False)
    starts = np.array([[0.1, 0.0], [0.0, 0.1], [-0.1, 0.0]])
    job = served(next_wait_s=0.3)
    with job.server, client_thread(job.server.port, sessions=1):
        t0 = time.perf_counter()
        records, complete = run_starts(runs, starts, point_seeds(0, 3), serve=job)
        waited = time.perf_counter() - t0
    ref, _ = run_starts(runs, starts[:1], point_seeds(0, 1))
    assert not complete and same(records[:1], ref) and records[1:] == [None, None] and waited < 5.0
    assert job.stopped == f"no controlling client said HELLO to {job.server.url} within 0.3 s (--wait-client)"
    # a later stage of the same job (validate) serves nothing more
    assert run_starts(runs, starts, point_seeds(0, 3), serve=job) == ([None, None, None], False)


# --- the command line -------------------------------------------------------------------------------------


def _served_cli(job: list[str], client: list[str], timeout_s: float = 240.0) -> tuple[str, str, int, str]:
    """``ballbeam JOB --serve 0`` and, once it prints its URL, the client ``CLIENT URL…``: the job's stdout
    after its first line, its stderr and exit code, the client's stdout."""
    server = subprocess.Popen(
        [*CLI, *job, "--serve", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV
    )
    assert server.stdout is not None
    first = server.stdout.readline().strip()
    # --json: stdout is JSON lines, the address first; else the text line
    url = json.loads(first)["serving_on"] if "--json" in job else first.removeprefix("serving on ")
    assert url.startswith("udp://127.0.0.1:") and " " not in url, first
    host, port = url.removeprefix("udp://").split(":")
    argv = [a.replace("{url}", url).replace("{host}", host).replace("{port}", port) for a in client]
    try:
        run = subprocess.run(argv, capture_output=True, text=True, env=ENV, timeout=timeout_s)
        out, err = server.communicate(timeout=timeout_s)
    finally:
        server.kill()
    assert run.returncode in (0, 1), run.stderr
    return out, err, server.returncode, run.stdout + run.stderr


QUICK_TOML = """
nominal_seeds = 1
duration_s = 2.0
region_x0 = [-0.2, 0.2, 2]
region_theta0 = [-0.3, 0.3, 2]
region_duration_s = 2.0
zeroing_counts = 1
latencies_s = [0.0]
free_runs_s = [0.04]
montecarlo_runs = 3
robust_rigs = 3
min_success_lower_bound = 0.1
"""


def test_validate_served_to_run_rig_sessions_gives_the_in_process_report(tmp_path: Path) -> None:
    criteria, spread = tmp_path / "criteria.toml", tmp_path / "spread.toml"
    criteria.write_text(QUICK_TOML)
    spread.write_text(SPREAD)
    common = ["validate", "--criteria", str(criteria), "--spread", str(spread)]
    ref = subprocess.run(
        # MuJoCo alone, as a served job runs (a session is a client's run on the twin)
        [
            *CLI,
            *common,
            "--controller",
            "appendix-sf",
            "--engine",
            "mujoco",
            "--out",
            str(tmp_path / "ref"),
            "--json",
        ],
        capture_output=True,
        text=True,
        env=ENV,
        timeout=240,
    )
    assert ref.returncode in (0, 1), ref.stderr
    out, err, code, client = _served_cli(
        [*common, "--out", str(tmp_path / "served"), "--json"],
        [*CLI, "run", "--rig", "{url}", "--controller", "appendix-sf", "--sessions", "0", "--json"],
    )
    assert code == ref.returncode, err
    theirs, ours = json.loads(ref.stdout), json.loads(out)
    assert same(ours["checks"], theirs["checks"]) and ours["passed"] == theirs["passed"]
    assert ours["controller"] == "ballbeam run appendix-sf"  # the client's HELLO: no --controller given
    # nominal, region (no claim: no corner), sensitivity (4 cases × 2), robust region (4 starts × 3 rigs), Monte
    # Carlo
    runs = 6 + 4 + 8 + 12 + 3
    assert ours["served"]["sessions"] == runs and ours["served"]["clients"] == ["ballbeam run appendix-sf"]
    sessions = [json.loads(line) for line in client.splitlines() if line.startswith("{")]
    assert [s["session"] for s in sessions] == list(range(1, runs + 1))
    assert all(s["ended"] == "last sample" for s in sessions)
    report = (tmp_path / "served" / "report.md").read_text()
    assert "ballbeam run appendix-sf" in report


# --- the C client -------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bb_sf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from test_c_controller import build_bb_sf  # examples/c built as that test builds it

    return build_bb_sf(tmp_path_factory.mktemp("c"))


@pytest.mark.parametrize("sessions", ["4", "0"])
def test_bb_sf_sessions_run_a_served_job_of_the_hardware_starts_as_the_python_port(
    bb_sf: Path, sessions: str
) -> None:
    """The four chapter 6 hardware starts (10 s, seed per start) served as one job to ``bb_sf --sessions``:
    every run held, every record the in-process appendix-sf job's, bit for bit; exit 0."""
    starts = np.array(list(HARDWARE_STARTS.values()), dtype=float)
    seeds = point_seeds(0, len(starts))
    runs = Runs("appendix-sf", Parameters(), 10.0, True, "twin", False)
    ref, _ = run_starts(runs, starts, seeds)
    job = served()
    with job.server:
        client = subprocess.Popen(
            [str(bb_sf), "udp", "127.0.0.1", str(job.server.port), "--sessions", sessions, "--timeout", "2"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        got, complete = run_starts(runs, starts, seeds, serve=job)
        _, err = client.communicate(timeout=60)
    assert client.returncode == 0, err
    assert complete and all(r and r["held"] for r in got), got
    assert same(got, ref)
    assert job.client_names() == ["bb_sf appendix-sf (C99)"] and len(job.clients) == 4
    assert err.count("stopped by the server: done") == 4
    assert err.strip().splitlines()[-1] == "bb_sf: 4 sessions, each as the server said"


@pytest.mark.quick
def test_bb_sf_sessions_usage(bb_sf: Path) -> None:
    proc = subprocess.run(
        [str(bb_sf), "pipe", "--sessions", "-1"], capture_output=True, text=True, timeout=10
    )
    assert proc.returncode == 2
    assert proc.stderr.splitlines()[0] == "bb_sf: --sessions -1: a whole number >= 0 (0: until none comes)"


# --- refusals ------------------------------------------------------------------------------------------------


@pytest.mark.quick
@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["sweep", "--serve", "0", "--workers", "2"], ["--serve runs every session here", "--workers"]),
        (["montecarlo", "--serve", "0", "--scheduler", "tcp://x:1", "--spread", "s"], ["--scheduler"]),
        (["sweep", "--serve", "70000"], ["--serve '70000'", "port 0…65535"]),
        (["validate", "--serve", "localhost:"], ["--serve 'localhost:'", "[HOST:]PORT"]),
        (["sweep", "--serve", "0", "--controller-timeout", "1"], ["--controller-timeout", "--timeout"]),
        (["sweep"], ["--controller is required (unless --serve"]),
        (["sweep", "--controller", "appendix-sf", "--timeout", "1"], ["--timeout", "needs --serve"]),
        (
            ["validate", "--controller", "appendix-sf", "--wait-client", "1"],
            ["--wait-client", "needs --serve"],
        ),
        (
            ["run", "--controller", "appendix-sf", "--x0", "0", "--theta0", "0", "--sessions", "2"],
            ["need --rig"],
        ),
        (
            [
                "run",
                "--controller",
                "appendix-sf",
                "--rig",
                "udp://127.0.0.1:9",
                "--sessions",
                "0",
                "--log",
                "a.csv",
            ],
            ["--log keeps one session's log"],
        ),
    ],
)
def test_served_job_refusals(capsys: pytest.CaptureFixture[str], argv: list[str], needles: list[str]) -> None:
    refused(capsys, argv, *needles)


def test_a_port_in_use_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        refused(capsys, ["sweep", "--serve", str(port), "--x0", "0", "--theta0", "0"], f"--serve {port}")


def test_run_rig_sessions_n_runs_n_and_a_job_without_a_client_stops(tmp_path: Path) -> None:
    """``run --rig … --sessions 2`` against a served job of 3 runs: two sessions, their measured verdicts
    printed; the job's third session waits for nobody (after the first, a session waits --timeout without
    --wait-client) and the job stops, exit 1, the two runs kept in its JSON."""
    out_dir = tmp_path / "out"
    job = ["sweep", "--x0", "-0.1:0.1:3", "--theta0", "0", "--duration", "1", "--timeout", "1"]
    out, err, code, client = _served_cli(
        [*job, "--out", str(out_dir)],
        [*CLI, "run", "--rig", "{url}", "--controller", "appendix-sf", "--sessions", "2"],
    )
    assert (
        code == 1 and "within 1 s (--wait-client): the job stopped after 2 of 3 runs (they are kept)" in err
    ), err
    lines = [line for line in client.splitlines() if line.startswith("session ")]
    assert [line.split(":")[0] for line in lines] == ["session 1", "session 2"], client
    assert all("ended last sample" in line for line in lines)
    result = json.loads((out_dir / "sweep.json").read_text())
    assert not result["complete"] and result["summary"]["done"] == 2
    assert result["settings"]["controller"] == "ballbeam run appendix-sf"
    assert result["served"]["stopped"].startswith("no controlling client said HELLO")


@pytest.mark.slow
@pytest.mark.study  # ~2 min of 302 sessions: the default run serves a small validation to run --rig instead
def test_the_default_validation_served_to_bb_sf_gives_the_in_process_report(bb_sf: Path) -> None:
    """The whole default battery (no spread: 18 nominal, 255 + 1 region, 28 sensitivity runs) served to the C
    client: every check, with its rows, the in-process appendix-sf validation's."""
    from twin.app.validate import validate

    t0 = time.perf_counter()
    ref = validate("appendix-sf", Parameters())
    in_process_s = time.perf_counter() - t0
    job = served()
    with job.server:
        client = subprocess.Popen(
            [str(bb_sf), "udp", "127.0.0.1", str(job.server.port), "--sessions", "0", "--timeout", "2"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        t0 = time.perf_counter()
        got = validate("appendix-sf", Parameters(), serve=job)
        served_s = time.perf_counter() - t0
        client.communicate(timeout=60)
    print(f"default validation: in process {in_process_s:.1f} s, served to bb_sf {served_s:.1f} s")
    assert got.complete and len(job.clients) == 18 + 256 + 28
    assert same([asdict(c) for c in got.checks], [asdict(c) for c in ref.checks])
    assert got.passed == ref.passed


def _connect_to_a_silent_address() -> float:
    """``twin.rigs.session.connect`` to an address where nobody answers HELLO: the seconds it took to fail with
    a message naming the URL."""
    import socket
    import time

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:  # bound, never answers
        silent.bind(("127.0.0.1", 0))
        url = f"udp://127.0.0.1:{silent.getsockname()[1]}"
        t0 = time.monotonic()
        with pytest.raises(RemoteError, match=url.replace(".", r"\.")):
            _connect(url, "quick", 0.4, retry_refused=True)
        return time.monotonic() - t0


@pytest.mark.quick
def test_connecting_to_a_silent_address_fails_naming_it() -> None:
    """Nobody answers HELLO at the address, so connect fails with a message naming the URL (in time: below)."""
    _connect_to_a_silent_address()


@pytest.mark.realtime
def test_connecting_to_a_silent_address_fails_in_time() -> None:
    """... within its wait (0.4 s): never a hang. A wall-clock bound, so a realtime test."""
    assert _connect_to_a_silent_address() < 3.0
