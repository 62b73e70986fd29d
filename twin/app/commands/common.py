"""What several ``ballbeam`` commands share: their option groups, the parameters (``--params``, ``--set``,
``--calibration``, ``--spread``), the files a command reads and writes, a many-run job's served clients
(``--serve``), its progress bar and its exit code.

Nothing heavy is imported at the top: ``--help`` builds every command's options from here.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.app.hosts import HOSTS, host_of
from twin.app.options import MAX_JOB_RUN_S, MAX_RUN_S, count, finite_float, seed
from twin.outputs import JobFiles, check_output_folder, writing
from twin.rigs.backends import DEFAULT_PLANT, ENGINES, backend, engine_policy, plant_choices, plant_help

if TYPE_CHECKING:
    from twin.app.fanout import Served
    from twin.app.montecarlo import Distribution
    from twin.interface import Controller
    from twin.log import RunLog
    from twin.parameters import Parameters

CONTROLLER_HELP = (
    "a named controller ({names}) or MODULE:CLASS, your own twin.interface.Controller subclass imported from "
    "MODULE (the current directory is searched first); it is built as CLASS(software=params.software), with "
    "the rig software's calibration, if its constructor has a parameter named 'software', else as CLASS()"
)
SERVED_CONTROLLER = (
    "; required unless --serve, where it only names what the client runs (never built here; the region "
    "claims about that name are then judged) and the report names the client from its HELLO without it"
)
MAX_WORKERS = 256  # local processes
LOG_SUFFIXES = (".mat", ".csv")
# Lower bounds of a log's size, to refuse a disk without room before the run: 17 columns a tick, 8 bytes
# each in a .mat, at least 4 characters each in a CSV.
_LOG_BYTES_PER_TICK = {".mat": 17 * 8, ".csv": 17 * 4}

# The numeric options shared by several commands (their types check them when parsed: see twin.app.options).
JOB_RUN_S = finite_float(
    0, MAX_JOB_RUN_S, lo_open=True, unit="s", why="each run of a many-run job; its verdict is kept"
)
WORKERS = count(1, MAX_WORKERS, unit="local processes")


def controller_help(firmware: bool = True) -> str:
    """The help of ``--controller``: the registry's names (importing it loads no design code), MODULE:CLASS and
    the other hosts' values (twin.app.hosts), firmware only where the twin runs it (``firmware``)."""
    from controllers import registry

    return CONTROLLER_HELP.format(names=", ".join(registry.NAMES)) + "".join(
        host.help for host in HOSTS.values() if firmware or host.kind != "firmware"
    )


def add_params_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--params", metavar="FILE", help="parameter file (TOML or JSON) overriding the defaults"
    )
    parser.add_argument(
        "--set",
        action="append",
        metavar="GROUP.NAME=VALUE",
        help="override one parameter, e.g. --set start.free_run_s=0 (repeatable; applied after --params)",
    )


def add_plant_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--plant",
        choices=plant_choices(),
        default=DEFAULT_PLANT,
        help=f"the physics backend (twin.rigs.backends): {plant_help()}",
    )
    parser.add_argument(
        "--ideal-sensors",
        action="store_true",
        help="ideal converters: exact x and θ in the volts the software expects, exact DAC (no quantization, "
        "wiper curve, RC filter or noise)",
    )


def add_engine_options(
    parser: argparse.ArgumentParser, default: str, *, near: str = "near a class change", grid: bool = True
) -> None:
    """``--engine screen|fast|mujoco`` and, for a grid, ``--band N`` (twin.app.screening); ``near``: what MuJoCo
    re-runs when it confirms."""
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default=None,
        help="who decides each run: 'screen' (the fast engine, the reference plant compiled under the twin's "
        f"sensor chain, runs everything; MuJoCo re-runs every run {near} and an audit sample, and any "
        "disagreement in the audit fails the command), 'fast' (the fast engine alone, labelled so) or "
        f"'mujoco' (MuJoCo alone); default {default}"
        + (" (mujoco with --refine, --serve or --plant reference)" if default != "mujoco" else ""),
    )
    if not grid:
        return
    parser.add_argument(
        "--band",
        type=count(1, 64),
        default=None,  # 1, set by resolve_engine: given, it is refused where the engine is not screen
        metavar="N",
        help="with --engine screen: the grid steps around each class change that MuJoCo decides (default 1)",
    )


def resolve_engine(args: argparse.Namespace, default: str) -> str:
    """The engine asked for, or the command's default where the job allows it (refused where it does not).
    A grid's ``--band`` goes with the screen engine only (refused with another); not given, it is set to 1."""
    engine = _engine(args, default)
    if hasattr(args, "band"):
        if args.band is not None and not engine_policy(engine, args.plant).screened:
            refuse_unused(
                [("--band", args.band)], f"the band is the screen engine's; this job's engine is {engine}"
            )
        args.band = 1 if args.band is None else args.band
    return engine


def _engine(args: argparse.Namespace, default: str) -> str:
    engine = args.engine
    if engine is None:
        alone = backend(args.plant).stand_in is None  # no screening backend stands in for the plant
        plain = getattr(args, "refine", 0) or getattr(args, "serve", None) is not None or alone
        return "mujoco" if plain else default
    from twin.parameters import ParameterError

    try:
        policy = engine_policy(engine, args.plant)
    except ValueError as exc:
        raise ParameterError(str(exc)) from None
    if policy.screen is not None and getattr(args, "serve", None) is not None:
        raise ParameterError(
            f"--engine {engine}: a served job's runs are sessions with a client; not with --serve"
        )
    return str(engine)


def screen_summary(screen: dict[str, Any]) -> str:
    """A screened job's line: what each engine decided, the band's disagreements and the audit."""
    audit = screen["audit"]
    return (
        f"the fast engine ran {screen['fast_runs']}, MuJoCo decided {screen['mujoco_runs']} "
        f"({100 * screen['mujoco_fraction']:.1f} %; confirmed: {screen['confirmed']}, "
        f"{len(screen['band_disagreements'])} of them classed otherwise by the fast engine; audit "
        f"{audit['checked']}, {len(audit['mismatches'])} differ)"
    )


def screen_audit_failure(command: str, wrong: list[dict[str, Any]]) -> str:
    first = wrong[0]
    where = (
        f"map {first['map']}, grid start ({first['i']}, {first['j']})"
        if "map" in first
        else f"run {first['run']}"
    )
    return (
        f"ballbeam {command}: the screening's audit found {len(wrong)} run(s) decided by the fast engine "
        f"alone that MuJoCo classes otherwise (the first: {where}: fast {first['fast']}, MuJoCo "
        f"{first['mujoco']}); run with a wider --band or --engine mujoco"
    )


def add_spread_options(parser: argparse.ArgumentParser, use: str) -> None:
    """``--spread FILE`` or ``--calibration DIR`` (one of them): what rigs are drawn from, for ``use``."""
    what = parser.add_mutually_exclusive_group()
    what.add_argument(
        "--spread", metavar="FILE", help=f"each parameter's uncertainty (TOML/JSON; see the README), {use}"
    )
    what.add_argument(
        "--calibration",
        metavar="DIR",
        help=f"a calibration's values, uncertainties and correlations (calibrate --out), {use}",
    )


def add_served_options(parser: argparse.ArgumentParser) -> None:
    """A many-run job served over the wire to a controller in any language (sweep, montecarlo, validate)."""
    parser.add_argument(
        "--serve",
        metavar="[HOST:]PORT",
        help="serve every run as one lock-step session of protocol 1 over UDP (docs/protocol.md), in order, "
        "to the controlling client that connects (e.g. examples/c/bb_sf udp HOST PORT --sessions 0, or "
        "ballbeam run --rig udp://HOST:PORT --sessions 0) instead of running a controller here; HOST "
        "defaults to 127.0.0.1 (this machine only), PORT 0 picks a free one (printed)",
    )
    parser.add_argument(
        "--timeout",
        type=finite_float(0, 3600, lo_open=True, unit="s"),
        metavar="S",
        help="with --serve: the longest wait for one command; a silent client fails that run (default 5)",
    )
    parser.add_argument(
        "--wait-client",
        type=finite_float(0, lo_open=True, unit="s"),
        metavar="S",
        help="with --serve: how long each session waits for a client to say HELLO (default: the first "
        "until one comes, every later one --timeout); none within it ends the job with the runs done",
    )


def add_episode_options(parser: argparse.ArgumentParser) -> None:
    """How long one episode of the rig runs and its noise (run and serve)."""
    parser.add_argument(
        "--duration",
        type=finite_float(0, MAX_RUN_S, lo_open=True, unit="s", why="the log keeps every tick in memory"),
        default=15.0,
        metavar="S",
        help=f"simulated seconds after release (default 15, at most {MAX_RUN_S:g}: the log keeps every tick)",
    )
    parser.add_argument("--seed", type=seed(), default=0, help="seed of the sensor noise (default 0)")
    parser.add_argument("--no-noise", action="store_true", help="switch the ball sensor's contact noise off")


def add_controller_timeout(command: argparse.ArgumentParser) -> None:
    from twin.guard import FIRST_CALL_BUDGET_S, MIN_UPDATE_BUDGET_S, UPDATE_BUDGET_PERIODS

    command.add_argument(
        "--controller-timeout",
        type=float,
        metavar="SECONDS",
        help=f"fail a controller whose update does not return within SECONDS (default: "
        f"{UPDATE_BUDGET_PERIODS} control periods, at least {MIN_UPDATE_BUDGET_S:g} s; its import, "
        f"construction and start get at least {FIRST_CALL_BUDGET_S:g} s); inf: no watchdog (a debugger)",
    )


def load_params(args: argparse.Namespace) -> Parameters:
    from twin.parameters import ParameterError, Parameters

    params = Parameters.from_file(args.params) if args.params else Parameters()
    overrides: dict[str, object] = {}
    for item in getattr(args, "set", None) or ():
        name, sep, text = item.partition("=")
        if not sep or "." not in name:
            raise ParameterError(f"--set {item!r}: expected GROUP.NAME=VALUE, e.g. start.free_run_s=0.02")
        overrides[name.strip()] = _parse_value(text.strip(), item)
    return params.with_overrides(overrides, origin="--set") if overrides else params


def params_source(args: argparse.Namespace) -> str:
    """Where the parameters came from, as typed: ``--params FILE`` and the ``--set`` items."""
    parts = [f"--params {args.params}"] if args.params else []
    parts += [f"--set {item}" for item in getattr(args, "set", None) or ()]
    return " ".join(parts)


def _parse_value(text: str, item: str) -> object:
    """A --set value: true/false, a number, or a JSON list of numbers."""
    from twin.parameters import ParameterError

    if text in ("true", "false"):
        return text == "true"
    shown = text if len(text) <= 40 else text[:37] + "..."
    try:
        value = json.loads(text)
    except (json.JSONDecodeError, RecursionError, ValueError):  # ValueError: an integer of > 4300 digits
        raise ParameterError(
            f"--set {item[:60]!r}: {shown!r} is not a number, true/false or a list of numbers"
        ) from None
    ok = isinstance(value, (int, float)) or (
        isinstance(value, list)
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    )
    if not ok:
        raise ParameterError(
            f"--set {item[:60]!r}: {shown!r} is not a number, true/false or a list of numbers"
        )
    return value


def log_bytes(text: str | None, duration_s: float, params: Parameters) -> int:
    """A lower bound of a log's size on disk (0 for a path the checks will refuse anyway)."""
    if not text:
        return 0
    ticks = int(duration_s / params.daq.period_s) + 2
    return ticks * _LOG_BYTES_PER_TICK.get(Path(text).suffix.lower(), 0)


def save_log(log: RunLog, option: str, text: str, path: Path, overwrite: bool) -> None:
    """Write ``log`` to the checked output ``path`` (``option`` as typed ``text``): .csv as CSV, else .mat."""
    from twin.log import save_csv, save_mat

    save = save_csv if path.suffix.lower() == ".csv" else save_mat
    with writing(option, text):
        save(log, path, overwrite=overwrite)


def inputs(args: argparse.Namespace) -> list[tuple[str, str]]:
    """The files a command reads, as (option, path): no output may replace one. A calibration folder brings
    its two files; a user controller its module's file (imported by then)."""
    found: list[tuple[str, str]] = []
    for option in ("params", "spread", "criteria", "table", "spec", "replay"):
        value = getattr(args, option, None)
        if value:
            found.append((f"--{option}" if option != "table" else "TABLE", value))
    for log in getattr(args, "logs", None) or ():
        found.append(("LOG", log))
    for log in getattr(args, "reference", None) or ():
        found.append(("--reference", log))
    calibration = getattr(args, "calibration", None)
    if calibration:
        found += [
            ("--calibration", str(Path(calibration) / name)) for name in ("params.toml", "calibration.json")
        ]
    spec = str(getattr(args, "controller", ""))
    image = host_of(spec).image(spec) if spec else None  # its host's file (twin.app.hosts)
    if image is not None:
        found.append(("--controller", str(image)))
    return found


def check_job(args: argparse.Namespace, params: Parameters, outputs: JobFiles) -> None:
    """What every many-run command checks before the work (its numbers are checked by their types): the
    controller (built once: a failing constructor is refused here) and the output folder the job writes
    ``outputs`` into."""
    from twin.app.hosts import catalogue_for

    if args.serve is None:  # served: the client's controller is none of ours
        catalogue_for(args.controller, params)
    check_overwrite(args, "--out")
    if getattr(args, "scheduler", None) is not None:  # the scheduler's workers run the job, not local ones
        refuse_unused(
            [("--workers", args.workers if args.workers > 1 else None)],
            f"--scheduler {args.scheduler} fans the runs out to its own workers: drop one",
        )
    if args.out is not None:
        check_output_folder("--out", args.out, outputs, overwrite=args.overwrite, inputs=inputs(args))


def given(value: object) -> bool:
    """An option given on the command line: its value neither None (not given) nor False (a flag not set)."""
    return value is not None and value is not False


def refuse_unused(options: Sequence[tuple[str, object]], why: str) -> None:
    """Refuse (a ParameterError: exit 2) the first of ``options`` (option, value) given: the job would not use
    it, ``why`` says when it would. An option is applied or refused, never ignored."""
    from twin.parameters import ParameterError

    for option, value in options:
        if given(value):
            raise ParameterError(f"{option}{_shown(value)}: {why}")


def _shown(value: object) -> str:
    """An option's value as typed, after its name: nothing for a flag, ``A:B`` for a range (``A`` for one)."""
    if value is True:
        return ""
    if isinstance(value, tuple):
        text = ":".join(dict.fromkeys(f"{v:g}" for v in value))
    elif isinstance(value, float):
        text = f"{value:g}"
    else:
        text = str(value)
    return f" {text[:60]}"


def check_overwrite(args: argparse.Namespace, *outputs: str) -> None:
    """``--overwrite`` with none of the command's ``outputs`` (option names) given replaces nothing: refused."""
    named = [getattr(args, option[2:].replace("-", "_"), None) for option in outputs]
    if getattr(args, "overwrite", False) and not any(given(value) for value in named):
        refuse_unused(
            [("--overwrite", True)], f"it replaces an existing {' or '.join(outputs)}: none is given"
        )


def check_flick(
    times: tuple[float, float] | None, speeds: tuple[float, float] | None, duration_s: float
) -> None:
    """``--flick-time`` and ``--flick-speed`` (a value each, or a range ``(A, B)`` searched): both or neither,
    the time before the run ends, a kick within the live view's Flick range in size (its sign is the
    direction); a range searched (it may cross 0) within its top in size and not below its bottom whole."""
    from twin.parameters import ParameterError

    if times is None and speeds is None:
        return
    if times is None or speeds is None:
        option, value = ("--flick-time", times) if speeds is None else ("--flick-speed", speeds)
        other = "--flick-speed (the kick)" if speeds is None else "--flick-time (when)"
        refuse_unused([(option, value)], f"a flick needs {other} too")
        return
    # The Flick control's range has one home, the view's (a heavy import: only for a flick).
    from twin.viewer.common import FLICK

    if times[1] >= duration_s:
        raise ParameterError(
            f"--flick-time{_shown(times)}: at or after the run's end ({duration_s:g} s after release); flick "
            "within it"
        )
    sizes = (abs(speeds[0]), abs(speeds[1]))
    smallest = min(sizes) if speeds[0] == speeds[1] else max(sizes)
    if max(sizes) > FLICK.high or smallest < FLICK.low:
        raise ParameterError(
            f"--flick-speed{_shown(speeds)}: a kick of {FLICK.low:g}…{FLICK.high:g} {FLICK.unit} either way "
            "(the live view's Flick; the sign is the direction)"
        )


def params_and_spread(args: argparse.Namespace) -> tuple[Parameters, Distribution | None]:
    """The parameters and the Monte Carlo spread: a calibration brings both; else --params/--set and an
    optional --spread file."""
    from twin.app.montecarlo import load_calibration_spread, load_spread
    from twin.parameters import ParameterError

    if args.calibration is not None:
        if args.params or args.set:
            raise ParameterError("--calibration brings its own parameters: drop --params/--set")
        return load_calibration_spread(args.calibration)
    params = load_params(args)
    return params, load_spread(args.spread, params) if args.spread is not None else None


def check_served(args: argparse.Namespace) -> None:
    """The options of a many-run job that go with --serve or without it (a ParameterError: exit 2)."""
    from twin.parameters import ParameterError

    if args.serve is None:
        if args.controller is None:
            raise ParameterError("--controller is required (unless --serve: the client's controller)")
        for option, value in (("--timeout", args.timeout), ("--wait-client", args.wait_client)):
            if value is not None:
                raise ParameterError(f"{option} is a served job's wait: it needs --serve")
        return
    _serve_address(args.serve)
    if getattr(args, "workers", 1) > 1 or getattr(args, "scheduler", None) is not None:
        raise ParameterError(
            "--serve runs every session here, one after the other on one socket: drop --workers/--scheduler"
        )
    if getattr(args, "controller_timeout", None) is not None:
        raise ParameterError("--controller-timeout: with --serve the client's budget is --timeout")


def _serve_address(text: str) -> tuple[str, int]:
    """--serve's ``[HOST:]PORT`` (a bare port: 127.0.0.1, this machine only)."""
    from twin.parameters import ParameterError

    host, colon, port_text = text.rpartition(":")
    host = host.strip("[]") if colon else "127.0.0.1"  # [::1]:PORT
    port = int(port_text) if port_text.isdigit() else -1
    if not 0 <= port <= 65535 or not host:
        raise ParameterError(f"--serve {text!r}: expected [HOST:]PORT, a UDP port 0…65535 (0: a free one)")
    return host, port


@contextmanager
def serving(args: argparse.Namespace, params: Parameters) -> Iterator[Served | None]:
    """With --serve: the job's server (one socket for all its sessions, bound before the work; its URL
    printed first), closed after the job; else None."""
    if args.serve is None:
        yield None
        return
    from twin.app.fanout import Served
    from twin.parameters import ParameterError
    from twin.serving.server import DEFAULT_TIMEOUT_S, ServeError, Server, SessionSettings

    host, port = _serve_address(args.serve)
    settings = SessionSettings(params=params, rig_name=f"ballbeam-twin {package_version()} {args.command}")
    try:
        server = Server(settings, host, port)
    except ServeError as exc:
        raise ParameterError(f"--serve {args.serve}: {exc}") from None
    timeout_s = args.timeout if args.timeout is not None else DEFAULT_TIMEOUT_S
    with server:
        # The address first; with --json stdout is JSON lines (this one, then the job's summary).
        address = (
            json.dumps({"serving_on": server.url})
            if getattr(args, "json", False)
            else f"serving on {server.url}"
        )
        print(address, flush=True)
        yield Served(
            server,
            timeout_s=timeout_s,
            first_wait_s=args.wait_client,
            next_wait_s=args.wait_client if args.wait_client is not None else timeout_s,
        )


def job_name(args: argparse.Namespace) -> str:
    """What a job's report calls its controller: --controller, else (served) a placeholder until the
    client has said its name (``client_name``)."""
    return str(args.controller) if args.controller is not None else "served client"


def client_name(args: argparse.Namespace, served: Served | None) -> str | None:
    """A served job without --controller: the clients' HELLO names, which the report then carries."""
    if served is None or args.controller is not None:
        return None
    return ", ".join(served.client_names()) or "served client (none came)"


def served_stopped(served: Served | None, what: str, done: int, total: int) -> int | None:
    """1 with a line on stderr when a served job ended for want of a client; else None."""
    if served is None or not served.stopped:
        return None
    print(
        f"ballbeam {what}: {served.stopped}: the job stopped after {done} of {total} runs (they are kept)",
        file=sys.stderr,
    )
    return 1


def controller_failures(records: Sequence[dict[str, Any] | None], what: str) -> int:
    """0, or 1 with a line on stderr when a job's controller failed in some of its runs (a failed run is
    not a verdict: the exit code says so)."""
    failed = [r for r in records if r and r.get("failed")]
    if not failed:
        return 0
    print(
        f"ballbeam {what}: the controller failed in {len(failed)} of {len(records)} runs; the first: "
        f"{str(failed[0].get('reason', '')).removeprefix('the controller failed: ')}",
        file=sys.stderr,
    )
    return 1


def write_out(args: argparse.Namespace, write: Callable[..., Any], result: Any) -> None:
    """Write a job's result to ``--out`` (checked before the job), an OSError as one line naming it."""
    if args.out is not None:
        with writing("--out", args.out):
            write(result, args.out, overwrite=args.overwrite)


def progress_bar(what: str, unit: str = "run") -> Callable[..., None]:
    """A progress bar with ETA on stderr (tqdm), advanced by ``(done, total[, stage])`` calls (a
    ``fanout.Progress``). A job of stages (validate) reports over all its runs, the stage in the label, so
    that the ETA is the whole job's; a count that goes back starts a new bar."""
    from tqdm import tqdm

    bar: list[Any] = []

    def update(done: int, total: int, stage: str = "") -> None:
        label = f"{what}: {stage}" if stage else what
        if not bar or done < bar[0].n:
            if bar:
                bar.pop().close()
            bar.append(tqdm(total=total, desc=label, unit=unit, file=sys.stderr, dynamic_ncols=True))
        b = bar[0]
        if b.total != total:  # a stage's size corrected once it is known
            b.total = total
        if b.desc != label:
            b.set_description_str(label, refresh=False)
        if done > b.n:
            b.update(done - b.n)
        if done >= total:
            b.close()

    return update


def compare_params(args: argparse.Namespace) -> tuple[Parameters, str]:
    """compare's parameters: a calibration folder's params.toml, or --params/--set (the defaults without)."""
    from twin.parameters import ParameterError, Parameters

    if args.calibration is not None:
        if args.params or args.set:
            raise ParameterError("--calibration brings its own parameters: drop --params/--set")
        path = Path(args.calibration) / "params.toml"
        if not path.is_file():
            raise ParameterError(
                f"--calibration {args.calibration}: no params.toml in it (calibrate --out DIR writes one)"
            )
        return Parameters.from_file(path), f"--calibration {args.calibration}"
    return load_params(args), params_source(args) or "the defaults (thesis values)"


def hardware_controller(spec: str, params: Parameters) -> Callable[[], Controller]:
    """A factory of fresh hardware controllers named by ``spec`` (one per replayed log); a law on the true state,
    a firmware image or a failing constructor is refused here, before the work (its host's row,
    twin.app.hosts)."""
    return host_of(spec).log_replay(spec, params)


def package_version() -> str:
    """The installed package's version, or pyproject.toml's when the package is not installed."""
    from importlib import metadata

    try:
        return metadata.version("ballbeam-twin")
    except metadata.PackageNotFoundError:
        pass
    import tomllib

    try:
        with open(Path(__file__).resolve().parents[3] / "pyproject.toml", "rb") as fh:
            return str(tomllib.load(fh)["project"]["version"])
    except (OSError, KeyError, tomllib.TOMLDecodeError):
        return "unknown"


def add_requirements_job(parser: argparse.ArgumentParser, spec_use: str, spread_use: str) -> None:
    """What a job judged by requirements takes (falsify, certify): the controller, the requirements file and the
    rigs (``--spread``/``--calibration``)."""
    parser.add_argument(
        "--controller", required=True, metavar="NAME|MODULE:CLASS|avr:FILE.elf", help=controller_help()
    )
    parser.add_argument(
        "--spec",
        required=True,
        metavar="FILE",
        help=f"requirements in signal temporal logic (TOML; README: Requirements and counterexamples): {spec_use}",
    )
    add_spread_options(parser, spread_use)


def add_job_outputs(parser: argparse.ArgumentParser, files: str) -> None:
    """Where a many-run job runs (--workers, --scheduler) and what it writes (--out DIR: ``files``, --overwrite,
    --json)."""
    parser.add_argument(
        "--workers", type=WORKERS, default=1, help="local processes (default 1: this process)"
    )
    parser.add_argument(
        "--scheduler", metavar="ADDRESS", help="a Dask distributed scheduler to fan the runs out to"
    )
    parser.add_argument("--out", metavar="DIR", help=f"write {files}")
    parser.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    parser.add_argument("--json", action="store_true", help="print the whole result as JSON")


def check_start_box(params: Parameters, x0_m: tuple[float, float], theta0_rad: tuple[float, float]) -> None:
    """Every corner of a box of starts on the track and within the stops (a ParameterError naming the options)."""
    from twin.parameters import ParameterError
    from twin.physics import check_initial_state

    for x in x0_m:
        for theta in theta0_rad:
            try:
                check_initial_state(params, x, theta, 0.0, 0.0)
            except ValueError as exc:
                raise ParameterError(f"--x0/--theta0: {exc}") from None


def interrupted(command: str, what: str, out: str | None = None, name: str = "") -> int:
    """Say that ``command`` was interrupted (Ctrl-C, SIGTERM, SIGHUP) and what it kept (``what``; ``out``/``name``:
    the file it is kept in), on stderr; the exit code, 128 + the signal."""
    from twin.guard import interrupt_exit_code, interrupt_name

    kept = f" in {Path(out) / name}" if out is not None and name else ""
    print(f"ballbeam {command}: interrupted ({interrupt_name()}){what}{kept}", file=sys.stderr)
    return interrupt_exit_code()
