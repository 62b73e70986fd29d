"""What several ``ballbeam`` commands share: their option groups and the typed records they are read into
(``options_from``), the parameters (``--params``, ``--set``, ``--calibration``, ``--spread``), the files a
command reads and writes, its progress bar and its exit code. A many-run job's skeleton (its checks, served
clients, writing and interrupts) is ``twin.app.commands.job``.

Each command reads its parsed options once, into its own frozen record (``options_from``); the functions here
take those records or plain values, never the parsed namespace.

Nothing heavy is imported at the top: ``--help`` builds every command's options from here.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, get_type_hints

from twin.app.hosts import HOSTS, host_of
from twin.app.options import MAX_JOB_RUN_S, MAX_RUN_S, count, finite_float, seed
from twin.outputs import writing
from twin.rigs.backends import (
    DEFAULT_PLANT,
    ENGINES,
    backend,
    engine_policy,
    plant_choices,
    plant_help,
    stand_in_refusal,
)

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

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

Record = TypeVar("Record", bound="DataclassInstance")


def options_from(kind: type[Record], args: argparse.Namespace) -> Record:
    """A command's typed record of its options, filled from the parsed ``args`` by field name; a field that is
    itself a record (an option group such as ``ParamsOptions``) is filled the same way. A field the parser did
    not define is a programming error (TypeError), never a silent default."""
    values = vars(args)
    hints = get_type_hints(kind)
    filled: dict[str, Any] = {}
    for field in dataclasses.fields(kind):
        hint = hints[field.name]
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            filled[field.name] = options_from(hint, args)
        elif field.name in values:
            filled[field.name] = values[field.name]
        else:
            raise TypeError(f"{kind.__name__}.{field.name}: the parser defines no option {field.name!r}")
    return kind(**filled)


def option_names(kind: type[DataclassInstance]) -> set[str]:
    """The parsed options a record reads (its groups' too): the ``dest`` of each."""
    hints = get_type_hints(kind)
    names: set[str] = set()
    for field in dataclasses.fields(kind):
        hint = hints[field.name]
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            names |= option_names(hint)
        else:
            names.add(field.name)
    return names


@dataclass(frozen=True)
class ParamsOptions:
    """``--rig-file FILE|PRESET``, ``--params FILE`` and the ``--set`` items (every command)."""

    rig_file: str | None
    params: str | None
    set: list[str] | None


@dataclass(frozen=True)
class SpreadOptions:
    """``--spread FILE`` or ``--calibration DIR``: what a many-run job's rigs are drawn from."""

    spread: str | None
    calibration: str | None


@dataclass(frozen=True)
class ServedOptions:
    """``--serve [HOST:]PORT`` and its waits (sweep, montecarlo, validate)."""

    serve: str | None
    timeout: float | None
    wait_client: float | None


@dataclass(frozen=True)
class OutputOptions:
    """A many-run job's outputs: ``--out DIR``, ``--overwrite`` and ``--json``."""

    out: str | None
    overwrite: bool
    json: bool


def controller_help(firmware: bool = True) -> str:
    """The help of ``--controller``: the registry's names (importing it loads no design code), MODULE:CLASS and
    the other hosts' values (twin.app.hosts), firmware only where the twin runs it (``firmware``)."""
    from controllers import registry

    return CONTROLLER_HELP.format(names=", ".join(registry.NAMES)) + "".join(
        host.help for host in HOSTS.values() if firmware or host.kind != "firmware"
    )


def add_params_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--rig-file",
        metavar="FILE.toml|PRESET",
        help="the rig: a rig description (a TOML file naming its parts and their values) or a preset's name "
        "(thesis, the default; `ballbeam params --rig-file X` lists a rig's parameters)",
    )
    parser.add_argument(
        "--params",
        metavar="FILE",
        help="parameter file (TOML or JSON) overriding the defaults (the rig's, with --rig-file)",
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
        default=None,  # 1, set by resolve_band: given, it is refused where the engine is not screen
        metavar="N",
        help="with --engine screen: the grid steps around each class change that MuJoCo decides (default 1)",
    )


def resolve_engine(
    engine: str | None,
    plant: str,
    default: str,
    *,
    plain: bool = False,
    served: bool = False,
    params: Parameters | None = None,
) -> str:
    """The engine asked for, or the command's default where the job allows it (refused where it does not):
    MuJoCo alone for a ``plain`` job (``sweep --refine``), a ``served`` one, a plant no screening backend
    stands in for, or a rig (``params``) with a part the fast engine has no form for (asked for explicitly:
    refused naming the part)."""
    if engine is None:
        # no screening backend stands in for the plant, or it cannot run this rig's parts
        alone = backend(plant).stand_in is None or stand_in_refusal(plant, params) is not None
        return "mujoco" if plain or served or alone else default
    from twin.parameters import ParameterError

    try:
        policy = engine_policy(engine, plant, params=params)
    except ValueError as exc:
        raise ParameterError(str(exc)) from None
    if policy.screen is not None and served:
        raise ParameterError(
            f"--engine {engine}: a served job's runs are sessions with a client; not with --serve"
        )
    return str(engine)


def resolve_band(band: int | None, engine: str, plant: str) -> int:
    """A grid's ``--band``: it goes with the screen engine only (refused with another); not given, 1."""
    if band is not None and not engine_policy(engine, plant).screened:
        refuse_unused([("--band", band)], f"the band is the screen engine's; this job's engine is {engine}")
    return 1 if band is None else band


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
        "--spread", metavar="FILE", help=f"each parameter's uncertainty (TOML/JSON; docs/validate.md), {use}"
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


def load_params(options: ParamsOptions) -> Parameters:
    from twin.parameters import ParameterError, Parameters
    from twin.parts.description import rig_of

    base = rig_of(options.rig_file) if options.rig_file else Parameters()
    params = Parameters.from_file(options.params, base=base) if options.params else base
    overrides: dict[str, object] = {}
    for item in options.set or ():
        name, sep, text = item.partition("=")
        if not sep or "." not in name:
            raise ParameterError(f"--set {item!r}: expected GROUP.NAME=VALUE, e.g. start.free_run_s=0.02")
        overrides[name.strip()] = _parse_value(text.strip(), item)
    params = params.with_overrides(overrides, origin="--set") if overrides else params
    if "daq.period_s" in overrides and params.period_field != "daq.period_s":
        raise ParameterError(
            f"--set daq.period_s: this rig's board ({params.parts.io_board}) ticks at {params.period_field} "
            f"= {params.period_s!r} s, not at the PCI-1712's daq.period_s: set {params.period_field}"
        )
    return params


def refuse_part_rig(params: Parameters, command: str, instead: str) -> None:
    """Refuse (a ParameterError: exit 2) a rig of other parts than the thesis's for ``command``, whose model is
    the thesis rig's smooth one (calib.identify: its wiper curve, counter and amplifier), naming the parts and
    what to use ``instead``. A rig's log is never read through another board's units."""
    from twin.parameters import ParameterError
    from twin.parts import ROLES, THESIS, is_thesis_rig, rig_parts

    parts = rig_parts(params)
    if is_thesis_rig(parts):
        return
    other = ", ".join(
        f"parts.{role} = {getattr(parts, role).name!r}"
        for role in ROLES
        if getattr(parts, role) is not getattr(THESIS, role)
    )
    raise ParameterError(
        f"{command} predicts with the thesis rig's identification model, not with a rig of other parts ({other}); "
        f"{instead}"
    )


def params_source(options: ParamsOptions) -> str:
    """Where the parameters came from, as typed: ``--rig-file``, ``--params FILE`` and the ``--set`` items."""
    parts = [f"--rig-file {options.rig_file}"] if options.rig_file else []
    parts += [f"--params {options.params}"] if options.params else []
    parts += [f"--set {item}" for item in options.set or ()]
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
    ticks = int(duration_s / params.period_s) + 2
    return ticks * _LOG_BYTES_PER_TICK.get(Path(text).suffix.lower(), 0)


def save_log(log: RunLog, option: str, text: str, path: Path, overwrite: bool) -> None:
    """Write ``log`` to the checked output ``path`` (``option`` as typed ``text``): .csv as CSV, else .mat."""
    from twin.log import save_csv, save_mat

    save = save_csv if path.suffix.lower() == ".csv" else save_mat
    with writing(option, text):
        save(log, path, overwrite=overwrite)


def inputs(
    *,
    params: str | None = None,
    rig_file: str | None = None,
    spread: str | None = None,
    criteria: str | None = None,
    table: str | None = None,
    spec: str | None = None,
    replay: str | None = None,
    logs: Sequence[str] | None = None,
    reference: Sequence[str] | None = None,
    calibration: str | None = None,
    controller: str | None = None,
) -> list[tuple[str, str]]:
    """The files a command reads (the options it has), as (option, path): no output may replace one. A
    calibration folder brings its two files; a user controller its module's file (imported by then)."""
    found: list[tuple[str, str]] = []
    described = rig_file if rig_file and rig_file.lower().endswith(".toml") else None  # a preset is no file
    for option, value in (
        ("--rig-file", described),
        ("--params", params),
        ("--spread", spread),
        ("--criteria", criteria),
        ("TABLE", table),
        ("--spec", spec),
        ("--replay", replay),
    ):
        if value:
            found.append((option, value))
    for log in logs or ():
        found.append(("LOG", log))
    for log in reference or ():
        found.append(("--reference", log))
    if calibration:
        found += [
            ("--calibration", str(Path(calibration) / name)) for name in ("params.toml", "calibration.json")
        ]
    spec_text = str(controller or "")
    image = host_of(spec_text).image(spec_text) if spec_text else None  # its host's file (twin.app.hosts)
    if image is not None:
        found.append(("--controller", str(image)))
    return found


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


def check_overwrite(overwrite: bool, outputs: Sequence[tuple[str, object]]) -> None:
    """``--overwrite`` with none of the command's ``outputs`` (option, value) given replaces nothing: refused."""
    if overwrite and not any(given(value) for _, value in outputs):
        names = " or ".join(option for option, _ in outputs)
        refuse_unused([("--overwrite", True)], f"it replaces an existing {names}: none is given")


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


def params_and_spread(options: ParamsOptions, rigs: SpreadOptions) -> tuple[Parameters, Distribution | None]:
    """The parameters and the Monte Carlo spread: a calibration brings both; else --params/--set and an
    optional --spread file."""
    from twin.app.montecarlo import load_calibration_spread, load_spread
    from twin.parameters import ParameterError

    if rigs.calibration is not None:
        if options.params or options.set:
            raise ParameterError("--calibration brings its own parameters: drop --params/--set")
        return load_calibration_spread(rigs.calibration)
    params = load_params(options)
    return params, load_spread(rigs.spread, params) if rigs.spread is not None else None


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


def write_out(out: str | None, overwrite: bool, write: Callable[..., Any], result: Any) -> None:
    """Write a job's result to ``--out`` (checked before the job), an OSError as one line naming it."""
    if out is not None:
        with writing("--out", out):
            write(result, out, overwrite=overwrite)


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


def compare_params(options: ParamsOptions, calibration: str | None) -> tuple[Parameters, str]:
    """compare's parameters: a calibration folder's params.toml, or --params/--set (the defaults without)."""
    from twin.parameters import ParameterError, Parameters

    if calibration is not None:
        if options.params or options.set:
            raise ParameterError("--calibration brings its own parameters: drop --params/--set")
        path = Path(calibration) / "params.toml"
        if not path.is_file():
            raise ParameterError(
                f"--calibration {calibration}: no params.toml in it (calibrate --out DIR writes one)"
            )
        return Parameters.from_file(path), f"--calibration {calibration}"
    return load_params(options), params_source(options) or "the defaults (thesis values)"


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
        help=f"requirements in signal temporal logic (TOML; docs/requirements.md): {spec_use}",
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
