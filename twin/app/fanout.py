"""Many closed-loop runs fanned out: in this process, in local worker processes, or on a Dask cluster.

A job is a list of starts, each with its own seed (and, for Monte Carlo, its own parameters). It is cut
into chunks (``chunk_runs``: at least ``BATCHES`` of them, of ``MIN_BATCH_RUNS`` … ``MAX_BATCH_RUNS`` runs);
each chunk runs through the batch engine (``twin.rigs.batch.run_batch``) where it lands. Because every run's
numbers depend only on its own start, seed and parameters, the result is the same however the job is chunked
and wherever the chunks run. A run is done when its chunk has come back: progress counts those runs, and an
interrupt (Ctrl-C, or SIGTERM/SIGHUP in the CLI: ``twin.guard``) stops handing out chunks, stops the chunks
running (their runs are lost: at most one chunk per worker) and returns the runs done (``complete`` false).

A served job (``Served``, ``run_served``) runs the same starts, seeds and parameters as sessions of the
twin served on protocol 1, one after the other, to a controller in any language: each record is made from
the twin's true state exactly as in process, so the reports are the same.

Why Dask for more than one machine: it is pip-installable, pure Python, starts a local cluster in a test,
and its futures map one-to-one onto chunks; Ray would bring a much larger runtime for the same use here.
"""

from __future__ import annotations

import gc
import os
import signal
from collections.abc import Generator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from twin.guard import STOP_SIGNALS
from twin.parameters import ParameterError, Parameters

if TYPE_CHECKING:
    from twin.engine import RunResult, Scenario
    from twin.requirements import Requirement
    from twin.serving.server import Server
    from twin.verdict import Verdict

__all__ = [
    "BATCHES",
    "MAX_BATCH_RUNS",
    "MIN_BATCH_RUNS",
    "chunk_runs",
    "Progress",
    "Runs",
    "Served",
    "Stages",
    "run_chunk",
    "run_served",
    "run_starts",
]

# Runs per chunk. A batch pays its per-tick Python once for all its runs, so larger batches cost less CPU per
# run; an interrupt loses the chunks running, and progress moves as chunks come back, so a job is cut into
# at least BATCHES chunks. Measured (CPU seconds per run, ``time.process_time``, 5 s runs of appendix-sf in
# this process): a sweep (512 starts, one rig) 39.5 ms in one batch of 512, 39.7 ms in 256s, 44.1 ms in 128s,
# 47.4 ms in 64s, 47.8 ms in 32s; a Monte Carlo (256 rigs of docs/examples/spread.toml, each its own model)
# 54 ms from 64 to 256 a batch, 58 ms in 32s, 72 ms in 16s. So a job of 2048 runs or more costs what one
# batch does, a smaller one up to ~20 % more; MIN_BATCH_RUNS keeps that bound; MAX_BATCH_RUNS bounds what an
# interrupt loses (256 runs of 15 s: about 40 s of CPU) and a batch's memory (~16 KB a run, ~100 kB with
# each run's log kept for requirements).
BATCHES = 8
MIN_BATCH_RUNS = 32
MAX_BATCH_RUNS = 256
CHUNKS_PER_WORKER = 4  # with local workers: enough chunks that none waits long for the last


def chunk_runs(n: int, workers: int, scheduler: str | None) -> int:
    """Runs per chunk of a job of ``n`` runs: ``n`` / ``BATCHES`` here (more chunks, ``CHUNKS_PER_WORKER``,
    with workers or a cluster), within ``MIN_BATCH_RUNS`` … ``MAX_BATCH_RUNS``, evened out so that the last
    chunk is not a sliver."""
    here = scheduler is None and workers <= 1
    chunks = BATCHES if here else max(BATCHES, CHUNKS_PER_WORKER * (workers if scheduler is None else 8))
    size = min(MAX_BATCH_RUNS, max(MIN_BATCH_RUNS, -(-n // chunks)))
    count = max(1, -(-n // size))
    return max(1, -(-n // count))


class Progress(Protocol):
    """Told ``(runs done, runs in the job)`` as a job advances, and the stage it is in (a job of stages)."""

    def __call__(self, done: int, total: int, stage: str = "") -> None: ...


class Stages:
    """One progress over every run of every stage of a job (validate), so that its ETA is the whole job's.

    ``planned``: each stage's runs, in order, counted before the job starts (a screened stage: every start on
    the fast engine and, at most, every start again on MuJoCo). ``stage(name)`` is that stage's
    ``Progress``: its (done, n) calls are counted after the runs of the stages before it. A stage that runs
    in waves, each counted from 0 (a screening: the fast engine's wave, then MuJoCo's), counts each wave
    after the ones before it, so the job's count never goes back. A stage's size is its plan until it has
    reported more (a grid's corner states, known once it is built); once the next stage starts, it is the
    runs the stage ran."""

    def __init__(self, progress: Progress | None, planned: dict[str, int]) -> None:
        self.progress = progress
        self.planned = dict(planned)
        self.sizes = dict(planned)
        self.ran: dict[str, int] = {}  # per stage started: the runs counted so far

    def stage(self, name: str) -> Progress | None:
        if self.progress is None:
            return None
        progress, names = self.progress, list(self.sizes)
        for earlier in names[: names.index(name)]:  # the stages before it are over: what they ran
            self.sizes[earlier] = self.ran.get(earlier, self.sizes[earlier])
        before = sum(self.sizes[n] for n in names[: names.index(name)])
        label = f"{name} (stage {names.index(name) + 1} of {len(names)})"
        waves = [0, 0]  # the runs of the stage's finished waves; the runs done in the current wave

        def update(done: int, total: int, stage: str = "") -> None:
            if done < waves[1]:  # a new wave, counted from 0
                waves[0] += waves[1]
            waves[1] = done
            self.ran[name] = waves[0] + done
            self.sizes[name] = max(self.planned[name], waves[0] + total)
            progress(before + waves[0] + done, sum(self.sizes.values()), label)

        return update


@dataclass(frozen=True)
class Runs:
    """What every run of a job shares."""

    controller: str  # a registry name or MODULE:CLASS
    params: Parameters
    duration_s: float
    noise: bool
    plant: str
    ideal_sensors: bool
    # Judged by these too: each record gains each requirement's robustness (``twin.requirements``).
    requirements: tuple[Requirement, ...] = ()


@dataclass(frozen=True)
class _Chunk:
    """One piece of work as plain data (picklable, for processes and Dask)."""

    runs: Runs
    x0_m: tuple[float, ...]
    theta0_rad: tuple[float, ...]
    seeds: tuple[int, ...]
    params: tuple[Parameters, ...] | None  # one per run, or None: ``runs.params`` for all
    nthread: int
    scenarios: tuple[Scenario | None, ...] | None = None  # one per run (a flick, a setpoint), or None
    controller_timeout_s: float | None = None  # the watchdog's budget per controller call (twin.guard)


def run_chunk(chunk: _Chunk) -> list[dict[str, Any]]:
    """Run one chunk through the batch engine: per run its start, seed and verdict as JSON values. A
    controller that fails (raises anything, ``SystemExit`` included, stalls past its watchdog budget, or
    returns no command in the DAC range) fails its own run, not the job: the chunk is run again one run at a
    time and that run's record says why (``failed``, ``reason``)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # an idle OpenBLAS thread spins after dlqr
    from twin.engine import ControllerError
    from twin.plant import NumericalError

    runs = range(len(chunk.seeds))
    try:
        return _records(chunk, runs)
    except (ControllerError, NumericalError):
        pass
    out = []
    for i in runs:
        try:
            out += _records(chunk, [i])
        except ControllerError as exc:
            out.append(_failed(chunk, i, str(exc)))
        except NumericalError as exc:  # the simulation failed, not the controller: no physical verdict
            out.append(_numerical_record(chunk.x0_m[i], chunk.theta0_rad[i], chunk.seeds[i], str(exc)))
    return out


def _records(chunk: _Chunk, runs: Sequence[int]) -> list[dict[str, Any]]:
    from twin.app.hosts import catalogue_for
    from twin.rigs.batch import run_batch

    r = chunk.runs
    pick = list(runs)
    results = run_batch(
        catalogue_for(r.controller, r.params, chunk.controller_timeout_s),
        r.controller,
        x0_m=np.array([chunk.x0_m[i] for i in pick]),
        theta0_rad=np.array([chunk.theta0_rad[i] for i in pick]),
        seeds=np.array([chunk.seeds[i] for i in pick], dtype=np.int64),
        duration_s=r.duration_s,
        noise=r.noise,
        params=[chunk.params[i] for i in pick] if chunk.params is not None else r.params,
        plant=r.plant,
        ideal_sensors=r.ideal_sensors,
        nthread=chunk.nthread,
        record=bool(r.requirements),
        controller_timeout_s=chunk.controller_timeout_s,
        scenarios=[chunk.scenarios[i] for i in pick] if chunk.scenarios is not None else None,
    )
    return [
        _record(
            chunk.x0_m[i],
            chunk.theta0_rad[i],
            chunk.seeds[i],
            result.verdict,
            result.firmware,
            _margins(
                r,
                result,
                chunk.params[i] if chunk.params is not None else r.params,
                chunk.scenarios[i] if chunk.scenarios is not None else None,
            ),
        )
        for i, result in zip(pick, results, strict=True)
    ]


def _margins(
    runs: Runs, result: RunResult, params: Parameters, scenario: Scenario | None = None
) -> dict[str, float] | None:
    """Each of the job's requirements' robustness over a run (None: the job has none), about its setpoint."""
    if not runs.requirements:
        return None
    from twin.requirements import margins

    setpoint = scenario.setpoint_m if scenario is not None and scenario.setpoint_m is not None else 0.0
    return margins(runs.requirements, result.log, params, setpoint)


# What a many-run job keeps of a firmware's figures per run (``twin.avr.firmware.AvrFirmware.figures``).
FIRMWARE_RECORD = (
    "update_cycles_max",
    "update_cycles_mean",
    "deadline_margin_s",
    "missed_periods",
    "stack_high_water_bytes",
    "stack_room_bytes",
    "load",
)


def _record(
    x0_m: float,
    theta0_rad: float,
    seed: int,
    verdict: Verdict,
    firmware: dict[str, Any] | None = None,
    requirements: dict[str, float] | None = None,
) -> dict[str, Any]:
    """The record of a run (in process or served): its start, seed and verdict as JSON values, a firmware's
    timing and stack figures (``FIRMWARE_RECORD``) and each requirement's robustness."""
    record = {"x0_m": x0_m, "theta0_rad": theta0_rad, "seed": seed, "failed": False, **verdict.to_json()}
    if firmware is not None:
        record["firmware"] = {name: firmware[name] for name in FIRMWARE_RECORD}
    if requirements is not None:
        record["requirements"] = requirements
    return record


def _failed(chunk: _Chunk, i: int, reason: str) -> dict[str, Any]:
    return _failed_record(chunk.x0_m[i], chunk.theta0_rad[i], chunk.seeds[i], reason)


def _failed_record(x0_m: float, theta0_rad: float, seed: int, reason: str) -> dict[str, Any]:
    """The record of a run whose controller failed: not held, the reason, no figures."""
    from twin.verdict import Verdict

    empty = {f.name: None for f in fields(Verdict)}
    return {
        "x0_m": x0_m,
        "theta0_rad": theta0_rad,
        "seed": seed,
        "failed": True,
        **empty,
        "held": False,
        "ball_lost": False,
        "hit_stops": False,
        "reason": f"the controller failed: {reason}",
    }


def _numerical_record(x0_m: float, theta0_rad: float, seed: int, reason: str) -> dict[str, Any]:
    """The record of a run whose simulation failed (``NumericalError``): no physical verdict, the reason."""
    return {**_failed_record(x0_m, theta0_rad, seed, ""), "numerical": True, "reason": reason}


def _worker_signals() -> None:
    """A worker process ignores Ctrl-C (the terminal sends it to the whole group: the parent decides) and
    dies at SIGTERM (the parent's way to stop a chunk it no longer wants; ``timeout`` signals the group)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_DFL)


def _local(
    chunks: list[tuple[int, _Chunk]], workers: int
) -> Generator[tuple[int, list[dict[str, Any]]], None, None]:
    if workers <= 1:
        for lo, chunk in chunks:
            yield lo, run_chunk(chunk)
        return
    # The workers are forked. An object holding MuJoCo's thread pool (a batch's, a rollout's) that a worker's
    # garbage collection reaches there waits for pool threads the fork did not copy: a worker hung for good in
    # the pool's destructor. So the garbage is collected here, where those threads run, and what lives is
    # frozen out of the workers' collections (gc.freeze: made for fork) while they start.
    gc.collect()
    gc.freeze()
    try:
        pool = ProcessPoolExecutor(workers, initializer=_worker_signals)
        pending: dict[Future, int] = {pool.submit(run_chunk, chunk): lo for lo, chunk in chunks}
    finally:
        gc.unfreeze()
    finished = False
    try:
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                yield pending.pop(future), future.result()
        finished = True
    finally:
        if not finished:  # interrupted (or failed): the chunks still running are not waited for
            # The pool has no public way to stop a running task (Python 3.14's terminate_workers); its
            # futures are left to fail as the pool breaks (cancelling them first trips Python 3.11's pool).
            for process in list(getattr(pool, "_processes", {}).values()):
                process.terminate()
        pool.shutdown(wait=finished)


def _dask(
    chunks: list[tuple[int, _Chunk]], scheduler: str
) -> Generator[tuple[int, list[dict[str, Any]]], None, None]:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ParameterError(
            "--scheduler needs Dask distributed: pip install 'ballbeam-twin[distributed]'"
        ) from None
    try:
        client = Client(scheduler, timeout="20s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise ParameterError(f"--scheduler {scheduler!r}: cannot connect: {exc}") from None
    try:
        futures = {client.submit(run_chunk, chunk, pure=False): lo for lo, chunk in chunks}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:
            client.cancel(list(futures))
    finally:
        client.close()


@dataclass
class Served:
    """A served job: every run is one lock-step session of ``server`` (``twin.serving.server``), in order, to
    whatever controlling client says HELLO; nothing runs a controller here.

    ``first_wait_s``: how long the job's first session waits for a client (None: until one comes);
    ``next_wait_s``: every later session's wait (a client running many sessions reconnects at once; none
    within it ends the job, incomplete). ``timeout_s``: the lock-step wait for each command (a silent client
    fails that run). What the job saw is kept here: the clients' HELLO names and why it stopped early."""

    server: Server
    timeout_s: float = 5.0
    first_wait_s: float | None = None
    next_wait_s: float = 5.0
    clients: list[str] = field(default_factory=list)  # each session's HELLO name, in order
    stopped: str = ""  # no client came: the job ended before its last run

    def client_names(self) -> list[str]:
        return list(dict.fromkeys(self.clients))

    def to_json(self) -> dict[str, Any]:
        """What a served job's report adds: where it was served, the clients, why it stopped early."""
        return {
            "url": self.server.url,
            "clients": self.client_names(),
            "sessions": len(self.clients),
            **({"stopped": self.stopped} if self.stopped else {}),
        }


def run_served(
    runs: Runs,
    starts: np.ndarray,
    seeds: np.ndarray,
    served: Served,
    *,
    params: Sequence[Parameters] | None = None,
    progress: Progress | None = None,
) -> tuple[list[dict[str, Any] | None], bool]:
    """``run_starts`` over the wire: run i is a session with start ``starts[i]``, seed ``seeds[i]`` and its
    parameters, judged from the twin's true state as in process (``Server.serve`` runs the engine's
    closed loop), so its record is the in-process run's when the client computes what the in-process
    controller does. A client that quits or goes silent fails that run with the server's reason; Ctrl-C or
    no client within the wait ends the job with what came back (``complete`` false)."""
    from twin.engine import ControllerError
    from twin.plant import NumericalError
    from twin.serving.server import ServeError, SessionSettings
    from twin.wire import protocol

    n = len(starts)
    results: list[dict[str, Any] | None] = [None] * n
    if progress is not None:
        progress(0, n)
    server = served.server
    for i in range(n):
        if served.stopped:  # an earlier stage (validate) ran out of clients: nothing more is served
            return results, False
        x0, th0, seed = float(starts[i, 0]), float(starts[i, 1]), int(seeds[i])
        settings = SessionSettings(
            x0_m=x0,
            theta0_rad=th0,
            duration_s=runs.duration_s,
            seed=seed,
            noise=runs.noise,
            params=params[i] if params is not None else runs.params,
            plant=runs.plant,
            ideal_sensors=runs.ideal_sensors,
            mode=protocol.MODE_LOCKSTEP,
            timeout_s=served.timeout_s,
            wait_client_s=served.next_wait_s if served.clients else served.first_wait_s,
            rig_name=server.settings.rig_name,
        )
        try:
            session = server.serve(settings)
        except KeyboardInterrupt:
            return results, False
        except ServeError as exc:
            if server.controller_addr is None:  # nobody said HELLO within the wait
                served.stopped = str(exc)
                return results, False
            served.clients.append(server.client_name)
            results[i] = _failed_record(x0, th0, seed, str(exc))
        except ControllerError as exc:
            served.clients.append(server.client_name)
            results[i] = _failed_record(x0, th0, seed, str(exc))
        except NumericalError as exc:  # the simulation failed, not the client: no physical verdict
            served.clients.append(server.client_name)
            results[i] = _numerical_record(x0, th0, seed, str(exc))
        else:
            served.clients.append(session.client)
            if session.stop_reason in (protocol.STOP_DONE, protocol.STOP_BALL_LOST):
                results[i] = _record(
                    x0,
                    th0,
                    seed,
                    session.result.verdict,
                    None,
                    _margins(runs, session.result, settings.params),
                )
            else:  # the client quit or went silent: its run failed, as a failing controller's does
                results[i] = _failed_record(x0, th0, seed, f"{session.client!r}: {session.stop_detail}")
        if progress is not None:
            progress(i + 1, n)
    return results, True


def run_starts(
    runs: Runs,
    starts: np.ndarray,
    seeds: np.ndarray,
    *,
    params: Sequence[Parameters] | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    nthread: int | None = None,
    progress: Progress | None = None,
    serve: Served | None = None,
    scenarios: Sequence[Scenario | None] | None = None,
) -> tuple[list[dict[str, Any] | None], bool]:
    """Every start ((N, 2): x0, θ0) with its seed (and its parameters and scenario, when given): the records in the
    starts' order (None where not run) and whether all ran. ``workers`` local processes (1: here), or a Dask
    ``scheduler`` address; ``nthread``: rollout threads per batch (default: the cores shared by the
    workers). Each controller call's watchdog budget is the process's (``twin.guard.default_timeout_s``,
    the CLI's ``--controller-timeout``), carried to the workers with the chunks. ``serve``: every run a
    session to a client over the wire instead (``run_served``; ``runs.controller`` is then only a name)."""
    from twin.guard import job_runs

    if serve is not None:
        if scenarios is not None:
            raise ParameterError("a served job has no flick or setpoint per run (twin.engine.Scenario)")
        if workers > 1 or scheduler is not None:
            raise ParameterError("a served job runs its sessions here, one after the other: no workers")
    results: list[dict[str, Any] | None] = [None] * len(starts)
    # A signal within raises here: the runs done so far are returned; one that came before: no run starts.
    with job_runs() as stop:
        if stop:
            return results, False
        try:
            if serve is not None:
                return run_served(runs, starts, seeds, serve, params=params, progress=progress)
            return _fan_out(
                runs, starts, seeds, results, params, workers, scheduler, nthread, progress, scenarios
            )
        except KeyboardInterrupt:
            return results, False


def _fan_out(
    runs: Runs,
    starts: np.ndarray,
    seeds: np.ndarray,
    results: list[dict[str, Any] | None],
    params: Sequence[Parameters] | None,
    workers: int,
    scheduler: str | None,
    nthread: int | None,
    progress: Progress | None,
    scenarios: Sequence[Scenario | None] | None,
) -> tuple[list[dict[str, Any] | None], bool]:
    """``run_starts`` here, on workers or on a cluster, each record into ``results`` as its chunk comes back."""
    from twin.guard import default_timeout_s

    timeout_s = default_timeout_s()
    n = len(starts)
    threads = nthread or max(1, (os.cpu_count() or 1) // max(workers, 1))
    size = chunk_runs(n, workers, scheduler)
    chunks = [
        (
            lo,
            _Chunk(
                runs=runs,
                x0_m=tuple(float(v) for v in starts[lo : lo + size, 0]),
                theta0_rad=tuple(float(v) for v in starts[lo : lo + size, 1]),
                seeds=tuple(int(v) for v in seeds[lo : lo + size]),
                params=tuple(params[lo : lo + size]) if params is not None else None,
                nthread=threads,
                scenarios=tuple(scenarios[lo : lo + size]) if scenarios is not None else None,
                controller_timeout_s=timeout_s,
            ),
        )
        for lo in range(0, n, size)
    ]
    source = _dask(chunks, scheduler) if scheduler else _local(chunks, workers)
    if progress is not None:
        progress(0, n)  # the bar (and its clock for the ETA) starts with the job
    done = 0
    try:
        for lo, records in source:
            results[lo : lo + len(records)] = records
            done += len(records)
            if progress is not None:  # whole runs, done and kept: what an interrupt now would keep
                progress(done, n)
    except KeyboardInterrupt:
        source.close()  # stop handing out chunks; the running ones are stopped, not waited for
        return results, False
    return results, all(r is not None for r in results)
