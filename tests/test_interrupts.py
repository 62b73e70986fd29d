"""Ctrl-C, SIGTERM (``kill``, ``timeout``) and SIGHUP end a long job alike: the runs finished are written,
the output says the job was interrupted, the exit code is 128 + the signal (130, 143, 129), and progress
counts whole runs done (what an interrupt keeps), not fractions of a batch.

The command-line tests start the real CLI in a subprocess, wait until its progress bar shows runs done (no
fixed sleep), send the signal and read what it wrote."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from twin.app import fanout
from twin.app.fanout import Runs, Stages, chunk_runs, run_starts
from twin.app.sweep import point_seeds
from twin.parameters import Parameters

ROOT = Path(__file__).resolve().parent.parent
SPREAD = ROOT / "docs" / "examples" / "spread.toml"
RUNS = Runs("appendix-sf", Parameters(), 1.0, True, "twin", False)
VERDICT = {"held", "ball_lost", "seed", "x0_m", "theta0_rad", "settling_time_s", "steady_x_m", "failed"}


class Cli:
    """``python -m twin.app.cli ARGS`` with its stderr read as it comes (the progress bar)."""

    def __init__(self, *args: str, cwd: Path) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "twin.app.cli", *args],
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            # SIGINT at its default, as in a terminal (a background job of a shell may inherit it ignored).
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        self.err = self.out = b""
        self._readers = [
            threading.Thread(target=self._read, args=(name,), daemon=True) for name in ("out", "err")
        ]
        for reader in self._readers:
            reader.start()

    def _read(self, name: str) -> None:
        pipe = self.proc.stdout if name == "out" else self.proc.stderr
        assert pipe is not None
        while chunk := os.read(pipe.fileno(), 4096):
            setattr(self, name, getattr(self, name) + chunk)

    def wait_for(self, pattern: str, timeout_s: float = 600.0) -> re.Match[str]:
        """The first match of ``pattern`` in stderr; fails if the process ends or the time runs out first."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            found = re.search(pattern, self.err.decode(errors="replace"))
            if found:
                return found
            if self.proc.poll() is not None:
                time.sleep(0.2)
                pytest.fail(f"ended ({self.proc.returncode}) before {pattern!r}: {self.err.decode()[-2000:]}")
            time.sleep(0.05)
        self.proc.kill()
        pytest.fail(f"no {pattern!r} within {timeout_s} s: {self.err.decode()[-2000:]}")

    def finish(self, timeout_s: float = 300.0) -> tuple[int, str, str]:
        """The exit code, stdout and stderr once the process has ended."""
        try:
            self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            raise
        for reader in self._readers:
            reader.join(10)
        return self.proc.returncode, self.out.decode(), self.err.decode()


def _runs_done(cli: Cli, total: int) -> int:
    """Wait until the bar shows some runs done (but not all) and return how many."""
    return int(cli.wait_for(rf"\b([1-9]\d*)/{total}\b").group(1))


def _children(pid: int) -> list[int]:
    """The live processes whose parent is ``pid`` (the fan-out's workers)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                out.append(int(entry.name))
    return out


# --- progress counts whole runs done -------------------------------------------------------------------
@pytest.mark.quick
def test_jobs_are_cut_so_an_interrupt_keeps_most_of_them() -> None:
    """At least BATCHES chunks of MIN_BATCH_RUNS … MAX_BATCH_RUNS runs, evened out: a 500-run job
    at one worker is 8 batches of 63 (it was one batch of 500: an interrupt kept nothing)."""
    assert chunk_runs(500, 1, None) == 63
    assert chunk_runs(20, 1, None) == 20  # a small job: one batch
    assert chunk_runs(40, 1, None) == 20  # two of at least MIN_BATCH_RUNS / 2
    assert chunk_runs(100_000, 1, None) == fanout.MAX_BATCH_RUNS
    for n in (1, 7, 17, 100, 500, 1681, 5000):
        for workers, scheduler in ((1, None), (2, None), (1, "tcp://x")):
            size = chunk_runs(n, workers, scheduler)
            assert 1 <= size <= fanout.MAX_BATCH_RUNS
            if n >= fanout.BATCHES * fanout.MIN_BATCH_RUNS:  # an interrupt loses at most an eighth
                assert -(-n // size) >= fanout.BATCHES


def test_progress_counts_the_runs_an_interrupt_keeps(monkeypatch: pytest.MonkeyPatch) -> None:
    """Progress is told whole runs at chunk ends only (the runs done and kept); interrupted in its third
    chunk, the job keeps exactly the runs the progress last showed, each a whole record."""
    n = 100  # four batches of 25
    starts = np.column_stack([np.linspace(-0.2, 0.2, n), np.zeros(n)])
    seeds = point_seeds(5, n)
    calls: list[tuple[int, int]] = []
    size = chunk_runs(n, 1, None)
    real = fanout.run_chunk
    chunks: list[object] = []

    def third_interrupted(chunk: fanout._Chunk) -> list[dict[str, object]]:
        chunks.append(chunk)
        if len(chunks) == 3:
            raise KeyboardInterrupt
        return real(chunk)

    monkeypatch.setattr(fanout, "run_chunk", third_interrupted)
    records, complete = run_starts(RUNS, starts, seeds, progress=lambda d, t, s="": calls.append((d, t)))
    assert not complete
    assert calls == [(0, n), (size, n), (2 * size, n)]  # whole runs, never a fraction of a batch
    kept = [r for r in records if r is not None]
    assert len(kept) == calls[-1][0] == 2 * size
    assert all(VERDICT <= set(r) and r["held"] in (True, False) for r in kept)


@pytest.mark.quick
def test_a_stage_of_waves_counts_on_instead_of_starting_again() -> None:
    """A screened stage reports each wave from 0 (the fast engine's, then MuJoCo's): the job's count goes on
    from the waves before, so the bar is never reset and its ETA stays the whole job's."""
    calls: list[tuple[int, int, str]] = []
    # The region planned at its most: 9 starts on the fast engine, and all 9 again on MuJoCo.
    stages = Stages(lambda d, t, s="": calls.append((d, t, s)), {"nominal": 2, "region": 18, "mc": 3})
    nominal, region, mc = stages.stage("nominal"), stages.stage("region"), None
    assert nominal is not None and region is not None
    nominal(0, 2)
    nominal(2, 2)
    region(0, 9)
    region(9, 9)  # the fast wave
    region(0, 4)  # MuJoCo's wave near the class changes
    region(4, 4)
    mc = stages.stage("mc")
    assert mc is not None
    mc(0, 3)
    mc(3, 3)
    done = [d for d, _, _ in calls]
    assert done == sorted(done) and done[-1] == calls[-1][1] == 2 + 9 + 4 + 3
    assert {t for _, t, s in calls if s.startswith(("nominal", "region"))} == {2 + 18 + 3}  # counted up front
    assert calls[-2][:2] == (15, 18)  # then what the region ran, once it is over


# --- the command line ----------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize(
    ("signum", "code", "name"), [(signal.SIGINT, 130, "Ctrl-C"), (signal.SIGTERM, 143, "SIGTERM")]
)
def test_an_interrupted_monte_carlo_writes_the_runs_done(
    tmp_path: Path, signum: int, code: int, name: str
) -> None:
    """A one-batch job's case, at one worker: 256 runs (8 batches of 32) interrupted after a batch or more."""
    out = tmp_path / "mc"
    cli = Cli(
        "montecarlo", "--controller", "appendix-sf", "--spread", str(SPREAD), "--n", "256",
        "--duration", "3", "--out", str(out), cwd=tmp_path,
    )  # fmt: skip
    shown = _runs_done(cli, 256)
    cli.proc.send_signal(signum)
    rc, stdout, err = cli.finish()
    assert rc == code, err[-2000:]
    data = json.loads((out / "montecarlo.json").read_text())
    assert data["complete"] is False and data["settings"]["n"] == 256
    kept = data["runs"]
    assert shown <= len(kept) < 256 and len(kept) % 32 == 0
    assert all(VERDICT <= set(r) and "parameters" in r for r in kept)  # each a real record
    assert data["summary"]["runs"] == len(kept)
    assert (out / "distributions.png").is_file()
    assert f"held {data['summary']['held']} of {len(kept)}" in stdout
    assert f"ballbeam montecarlo: interrupted ({name}) after {len(kept)} of 256 runs" in err
    assert "Traceback" not in err


@pytest.mark.slow
def test_sigterm_stops_the_workers_and_keeps_what_came_back(tmp_path: Path) -> None:
    """With --workers 2, SIGTERM to the parent alone: the running chunks are stopped (no worker is left),
    the chunks that came back are written, exit 143."""
    out = tmp_path / "sweep"
    cli = Cli(
        "sweep", "--controller", "appendix-sf", "--x0", "-0.3:0.3:13", "--theta0", "-0.5:0.5:11",
        "--duration", "4", "--workers", "2", "--out", str(out), cwd=tmp_path,
    )  # fmt: skip
    total = int(cli.wait_for(r"\b0/(\d+)\b").group(1))
    _runs_done(cli, total)
    assert _children(cli.proc.pid)  # the pool's workers
    cli.proc.send_signal(signal.SIGTERM)
    rc, _, err = cli.finish()
    assert rc == 143, err[-2000:]
    assert not _children(cli.proc.pid)
    data = json.loads((out / "sweep.json").read_text())
    done = [p for p in data["points"] if p]
    assert data["complete"] is False and 0 < len(done) < len(data["points"])
    assert all(VERDICT <= set(p) for p in done)
    assert "ballbeam sweep: interrupted (SIGTERM)" in err and "Traceback" not in err


@pytest.mark.slow
def test_an_interrupted_validation_keeps_its_finished_stages(tmp_path: Path) -> None:
    """SIGTERM in the third stage: the report says interrupted and holds the first two stages' checks and the
    runs the interrupted stage finished."""
    criteria = tmp_path / "criteria.toml"
    criteria.write_text(
        # 36 sensitivity runs (two batches of 18), long enough that the signal comes within the second
        "nominal_seeds = 1\nduration_s = 8.0\nregion_x0 = [-0.2, 0.2, 3]\nregion_theta0 = [-0.3, 0.3, 3]\n"
        "region_duration_s = 4.0\nzeroing_counts = 1\n"
        "latencies_s = [0.0, 0.002, 0.004, 0.006, 0.008, 0.010, 0.012, 0.015]\n"
        "free_runs_s = [0.0, 0.005, 0.01, 0.015, 0.02, 0.025, 0.03, 0.04]\n"
    )
    out = tmp_path / "v"
    cli = Cli(
        "validate", "--controller", "appendix-sf", "--criteria", str(criteria), "--engine", "mujoco",
        "--out", str(out), cwd=tmp_path,
    )  # fmt: skip
    # 6 nominal runs, 10 of the region (9 and its corner state), then the sensitivity's first batch of 18.
    cli.wait_for(r"sensitivity \(stage 3 of 5\)[^\r\n]*?\b34/52\b")
    cli.proc.send_signal(signal.SIGTERM)
    rc, _, err = cli.finish()
    assert rc == 143, err[-2000:]
    data = json.loads((out / "validation.json").read_text())
    assert data["complete"] is False and data["passed"] is False
    names = [c["name"] for c in data["checks"]]
    assert names[:3] == ["nominal", "saturation", "region"]
    partial = [c for c in data["checks"] if c["name"] == "sensitivity"]
    assert len(partial) == 1 and partial[0]["passed"] is None
    assert partial[0]["rows"] and all(VERDICT <= set(r) for r in partial[0]["rows"])
    assert partial[0]["measured"] == "interrupted after 18 of 36 runs (kept in the rows)"
    assert "interrupted" in (out / "report.md").read_text()
    assert "ballbeam validate: interrupted (SIGTERM)" in err and "Traceback" not in err


@pytest.mark.quick
def test_a_signal_between_a_jobs_runs_stops_its_next_runs() -> None:
    """In the CLI, once a job has started its runs, a first SIGTERM outside them does not raise where the
    job's code is (judging, writing: its results would be lost) but stops its next runs; a second raises."""
    from twin import guard

    guard.install_interrupt_handler(terminate=True)
    try:
        with guard.job_runs() as stop:
            assert not stop
        os.kill(os.getpid(), signal.SIGTERM)  # between runs: held
        assert guard.pending_interrupt() and guard.interrupt_exit_code() == 143
        assert guard.interrupt_name() == "SIGTERM"
        with guard.job_runs() as stop:
            assert stop  # the next runs do not start
        assert not guard.pending_interrupt()  # it stopped them: the job reports it
        with pytest.raises(guard.Interrupted):
            os.kill(os.getpid(), signal.SIGTERM)  # a second one: at once
            time.sleep(1)
    finally:
        guard.command_ended()
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_a_sigterm_while_a_finished_job_writes_keeps_its_outputs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The signal comes after the last run, as the outputs are written (``validate --spread`` killed at 98 %
    wrote nothing): the files are written whole, and the exit code still says SIGTERM."""
    from twin.app import montecarlo_render
    from twin.app.cli import main

    real = montecarlo_render.write_montecarlo

    def killed_while_writing(*args: object, **kwargs: object) -> None:
        os.kill(os.getpid(), signal.SIGTERM)
        real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(montecarlo_render, "write_montecarlo", killed_while_writing)
    out = tmp_path / "mc"
    argv = [
        "montecarlo",
        "--controller",
        "appendix-sf",
        "--spread",
        str(SPREAD),
        "--n",
        "4",
        "--duration",
        "1",
    ]
    assert main([*argv, "--out", str(out)]) == 143
    err = capsys.readouterr().err
    assert "ballbeam: interrupted (SIGTERM) after its runs: the outputs are complete" in err
    data = json.loads((out / "montecarlo.json").read_text())
    assert data["complete"] is True and len(data["runs"]) == 4
    assert (out / "distributions.png").is_file()
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # main put it back
