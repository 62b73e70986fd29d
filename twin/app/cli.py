"""The ``ballbeam`` command (application layer: it sees the controllers and hands their catalogue down).

Exit codes: 0 success (for ``run``: the ball was held), 1 a run whose ball was lost or not held, or whose
controller failed, 2 bad input (arguments, parameter files, output paths), each with a one-line message
and no traceback.

Outputs (``--log``, ``--plot``, ``--out``) are checked before any work (twin.outputs): a known extension of
the file written (a link's target), not an existing file unless ``--overwrite``, never an input of the
command, two options never naming the same file, a directory that exists and can be written; an ``--out``
folder never ``.``, ``..``, ``/`` or the home folder, and with ``--overwrite`` only the command's own files in
it are replaced. They are written atomically: a failed write leaves an existing file as it was.

``--help`` imports nothing heavy: it lists the registry's names (``controllers.registry`` loads no design code
until a controller is built); python-control, MuJoCo's runs and the plots are imported by the commands that
use them.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from twin.app.catalogue import WithUserController, construct, one_line, user_controller
from twin.app.options import (
    DEFAULT_REFINE_STEP,
    MAX_JOB_RUN_S,
    MAX_LOCATE,
    MAX_RIGS,
    GridType,
    NumberType,
    count,
    finite_float,
    seed,
    serve_address,
)
from twin.outputs import JobFiles, check_output_folder, check_outputs, writing

if TYPE_CHECKING:
    from twin.app.fanout import Served
    from twin.app.montecarlo import Distribution
    from twin.engine import Catalogue, RunResult
    from twin.interface import Controller
    from twin.log import RunLog
    from twin.parameters import Parameters
    from twin.remote import RemoteRig, RemoteRun
    from twin.verdict import Verdict

CONTROLLER_HELP = (
    "a named controller ({names}) or MODULE:CLASS, your own twin.interface.Controller subclass imported from "
    "MODULE (the current directory is searched first); it is built as CLASS(software=params.software), with "
    "the rig software's calibration, if its constructor has a parameter named 'software', else as CLASS()"
)
# A run keeps every tick of its log in memory (and the log on disk holds them all): one simulated hour is
# 180 000 ticks at 50 Hz.
MAX_RUN_S = 3600.0
MAX_WORKERS = 256  # local processes
# The live view's speed slider (twin.viewer) runs from 0.1 to 4.
SPEED_MIN, SPEED_MAX = 0.1, 4.0
LOG_SUFFIXES = (".mat", ".csv")
PLOT_SUFFIXES = (".png",)
PARAMS_OUT_SUFFIXES = (".toml",)
# Lower bounds of an output's size, to refuse a disk without room before the run: 17 columns a tick, 8 bytes
# each in a .mat, at least 4 characters each in a CSV; a plot takes at least 20 kB.
_LOG_BYTES_PER_TICK = {".mat": 17 * 8, ".csv": 17 * 4}
_PLOT_BYTES = 20_000


def package_version() -> str:
    """The installed package's version, or pyproject.toml's when the package is not installed."""
    from importlib import metadata

    try:
        return metadata.version("ballbeam-twin")
    except metadata.PackageNotFoundError:
        pass
    import tomllib

    try:
        with open(Path(__file__).resolve().parents[2] / "pyproject.toml", "rb") as fh:
            return str(tomllib.load(fh)["project"]["version"])
    except (OSError, KeyError, tomllib.TOMLDecodeError):
        return "unknown"


def _load_params(args: argparse.Namespace) -> Parameters:
    from twin.parameters import ParameterError, Parameters

    params = Parameters.from_file(args.params) if args.params else Parameters()
    overrides: dict[str, object] = {}
    for item in getattr(args, "set", None) or ():
        name, sep, text = item.partition("=")
        if not sep or "." not in name:
            raise ParameterError(f"--set {item!r}: expected GROUP.NAME=VALUE, e.g. start.free_run_s=0.02")
        overrides[name.strip()] = _parse_value(text.strip(), item)
    return params.with_overrides(overrides, origin="--set") if overrides else params


def _params_source(args: argparse.Namespace) -> str:
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


def _cmd_linearize(args: argparse.Namespace) -> int:
    import numpy as np

    from twin.reference import STATE_NAMES, ReferenceModel

    params = _load_params(args)
    if args.source == "reference":
        a, b = ReferenceModel(params).linearize(args.input)
    else:
        from twin.linearize import linearize_mujoco  # imports MuJoCo only when needed

        a, b = linearize_mujoco(params, args.input)
    result = {
        "state": list(STATE_NAMES),
        "input": args.input,
        "source": args.source,
        "A": a.tolist(),
        "B": b.tolist(),
    }
    if args.json:
        print(json.dumps(result))
    else:
        unit = "N·m" if args.input == "torque" else "V"
        print(f"Continuous-time linearization at the origin ({args.source}, input: {args.input} [{unit}])")
        print("state:", ", ".join(STATE_NAMES))
        with np.printoptions(precision=6, suppress=True, linewidth=120):
            print("A =\n", a)
            print("B =\n", b)
            print("eigenvalues of A:", np.linalg.eigvals(a))
    return 0


def _cmd_params(args: argparse.Namespace) -> int:
    from twin.parameters import Parameters

    params = _load_params(args)
    if args.json:
        print(json.dumps(params.to_dict(), indent=2))
    else:
        for row in Parameters.describe():
            group, name = row["name"].split(".")
            value = getattr(getattr(params, group), name)
            print(f"{row['name']:<40} {value!r:>22} {row['unit']:<10} {row['source']}")
    return 0


def _log_bytes(text: str | None, duration_s: float, params: Parameters) -> int:
    """A lower bound of a log's size on disk (0 for a path the checks will refuse anyway)."""
    if not text:
        return 0
    ticks = int(duration_s / params.daq.period_s) + 2
    return ticks * _LOG_BYTES_PER_TICK.get(Path(text).suffix.lower(), 0)


def _apply_setpoint(controller: object, spec: str, setpoint_m: float, params: Parameters) -> None:
    """``--setpoint``: on the track, and only for a controller that declares one (twin.interface.Setpoint)."""
    from twin.interface import Setpoint
    from twin.parameters import ParameterError

    half_m = params.track.half_length_m
    if abs(setpoint_m) > half_m:
        raise ParameterError(f"--setpoint = {setpoint_m!r} m is off the track (|x| ≤ {half_m:g} m)")
    if not isinstance(controller, Setpoint):
        from controllers import registry

        named = ", ".join(name for name, entry in registry.ENTRIES.items() if entry.setpoint)
        raise ParameterError(
            f"--setpoint: {spec} has no ball setpoint (it regulates the ball to its own fixed point); "
            f"named controllers with one: {named} (your own: implement twin.interface.Setpoint)"
        )
    controller.setpoint_m = setpoint_m


def _verdict_about(result: RunResult, params: Parameters, x0_m: float, setpoint_m: float) -> Verdict:
    """The run's verdict judged about the setpoint: ``twin.engine.judge`` on the logged true state. The
    per-tick peak |θ| is not logged; only its maximum enters the verdict, and the run's verdict holds it."""
    import numpy as np

    from twin.engine import judge

    log, first = result.log, result.verdict
    return judge(
        params,
        log.true_time_s,
        log.true_x_m,
        log.true_theta_rad,
        log.motor_volts_v,
        np.array([first.peak_theta_rad]),
        x0_m=x0_m,
        ball_lost_time_s=first.ball_lost_time_s,
        x_ref_m=setpoint_m,
    )


def _cmd_run(args: argparse.Namespace) -> int:
    from controllers import registry
    from twin.engine import ControllerError, run_closed_loop
    from twin.plant import NumericalError

    params = _load_params(args)
    if args.rig is not None:
        return _run_on_remote_rig(args, params)
    if args.sessions != 1 or args.wait_server is not None:
        print(
            "ballbeam run: error: --sessions and --wait-server are a rig's: they need --rig", file=sys.stderr
        )
        return 2
    if args.x0 is None or args.theta0 is None:
        print(
            "ballbeam run: error: --x0 and --theta0 are required (unless --rig: the server's)",
            file=sys.stderr,
        )
        return 2
    user = user_controller(args.controller)
    paths = check_outputs(
        [
            ("--log", args.log, LOG_SUFFIXES, _log_bytes(args.log, args.duration, params)),
            ("--plot", args.plot, PLOT_SUFFIXES, _PLOT_BYTES),
        ],
        overwrite=args.overwrite,
        inputs=_inputs(args),
    )
    controller = (
        registry.make(args.controller, params) if user is None else construct(user, args.controller, params)
    )
    if args.setpoint is not None:
        _apply_setpoint(controller, args.controller, args.setpoint, params)
    pacer = None
    if args.realtime:
        from twin.realtime import WallClockPacer

        pacer = WallClockPacer(params.daq.period_s)
    try:
        result = run_closed_loop(
            controller,
            x0_m=args.x0,
            theta0_rad=args.theta0,
            duration_s=args.duration,
            seed=args.seed,
            noise=not args.no_noise,
            params=params,
            plant=args.plant,
            ideal_sensors=args.ideal_sensors or args.plant == "reference",
            pacer=pacer,
        )
    except ControllerError as exc:
        print(f"ballbeam run: the controller failed: {exc}", file=sys.stderr)
        return 1
    except NumericalError as exc:  # the simulation failed: no physical verdict
        print(f"ballbeam run: {one_line(exc)}", file=sys.stderr)
        return 1
    if args.setpoint is not None:
        result.verdict = _verdict_about(result, params, args.x0, args.setpoint)
    if "--log" in paths:
        _save_log(result.log, "--log", args.log, paths["--log"], args.overwrite)
    if "--plot" in paths:
        from twin.app.plots import plot_run

        with writing("--plot", args.plot):
            plot_run(result, paths["--plot"], overwrite=args.overwrite, software=params.software)
    summary = {
        "controller": args.controller,
        "x0_m": args.x0,
        "theta0_rad": args.theta0,
        "seed": args.seed,
        "noise": not args.no_noise,
        "plant": args.plant,
        "ideal_sensors": bool(args.ideal_sensors or args.plant == "reference"),
        "free_run_s": params.start.free_run_s,
        **({} if args.setpoint is None else {"setpoint_m": args.setpoint}),
        **result.verdict.to_json(),
    }
    if pacer is not None:
        summary["realtime"] = pacer.timing().to_json()
    if args.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:<26} {value}")
    return 0 if result.verdict.held else 1


def _run_on_remote_rig(args: argparse.Namespace, params: Parameters) -> int:
    """``run --rig udp://HOST:PORT`` (or ``serial:///dev/ttyX?baud=N``): the controller through
    ``twin.remote.RemoteRig``. The rig's initial state, duration and noise are the server's; the verdict is
    judged from the measured signals (``ballbeam serve`` prints the true state's). ``--sessions N``: N
    sessions one after the other (0: until the server stops answering HELLO within ``--wait-server``), a
    fresh controller each, built from that session's CONFIG (a served job's runs, ``sweep --serve``)."""
    from twin.links import parse_url
    from twin.remote import RemoteError

    try:
        parse_url(args.rig)
    except ValueError as exc:
        raise ValueError(f"--rig {exc}") from None
    if args.sessions != 1 and args.log is not None:
        raise ValueError(
            "--log keeps one session's log: with --sessions other than 1 the server keeps every run (its "
            "job's report, or serve --log)"
        )
    user = user_controller(args.controller)
    paths = check_outputs(
        [("--log", args.log, LOG_SUFFIXES, _log_bytes(args.log, args.duration, params))],
        overwrite=args.overwrite,
        inputs=_inputs(args),
    )
    many = args.sessions != 1
    wait_s = args.wait_server or 5.0
    done, ok = 0, True
    while args.sessions == 0 or done < args.sessions:
        try:
            rig = _connect(args.rig, f"ballbeam run {args.controller}"[:32], wait_s, retry_refused=many)
        except RemoteError as exc:
            if args.sessions == 0 and done:  # the server has no further session: the job is over
                break
            print(f"ballbeam run: {exc}", file=sys.stderr)
            return 1
        done += 1
        with rig:
            session = _remote_session(args, rig, params, user, many)
        if session is None:
            return 2  # a law on the true state (reported): refused at the first session
        held, run, summary = session
        if run is None:  # the controller failed (reported, STOP sent): the server records that run failed
            if not many:
                return 1
            ok = False
            continue
        ok = ok and held and run.ended == "last sample"
        if "--log" in paths:
            _save_log(run.log, "--log", args.log, paths["--log"], args.overwrite)
        if many:
            summary = {"session": done, **summary}
        if args.json:
            print(json.dumps(summary), flush=True)
        elif many:
            print(
                f"session {done}: held {summary['held']}, ball_lost {summary['ball_lost']}, ticks "
                f"{summary['ticks']}, settling_time_s {summary['settling_time_s']}, ended {summary['ended']}",
                flush=True,
            )
        else:
            for key, value in summary.items():
                print(f"{key:<26} {value}")
    return 0 if ok else 1


def _connect(url: str, client: str, wait_s: float, *, retry_refused: bool) -> RemoteRig:
    """``open_remote`` within ``wait_s``; ``retry_refused``: a refusal (the rig is still another session's,
    e.g. a dead client's waiting out its timeout) is asked again until then."""
    import time

    from twin.remote import Refused, open_remote

    deadline = time.monotonic() + wait_s
    while True:
        try:
            return open_remote(url, client=client, connect_timeout_s=max(deadline - time.monotonic(), 0.2))
        except Refused:
            if not retry_refused or time.monotonic() >= deadline:
                raise
            time.sleep(0.2)


def _remote_session(
    args: argparse.Namespace,
    rig: RemoteRig,
    params: Parameters,
    user: Callable[..., Controller] | None,
    many: bool,
) -> tuple[bool, RemoteRun | None, dict[str, Any]] | None:
    """One session of ``run --rig`` on the open ``rig``: (held, the run or None if the controller failed,
    the summary); None when the controller cannot drive a rig (reported)."""
    from controllers import registry
    from twin.engine import ControllerError
    from twin.interface import Controller
    from twin.remote import RemoteError, run_remote
    from twin.verdict import evaluate_measured

    rig_params = rig.parameters(params)  # the rig's period, DAC and software calibration
    controller = (
        registry.make(args.controller, rig_params)
        if user is None
        else construct(user, args.controller, rig_params)
    )
    if not isinstance(controller, Controller):
        rig.stop()
        print(
            f"ballbeam run: {args.controller} is a law on the true state (simulation only): it cannot drive a rig",
            file=sys.stderr,
        )
        return None
    try:
        run = run_remote(controller, rig)
    except ControllerError as exc:
        rig.stop()
        print(f"ballbeam run: the controller failed: {exc}", file=sys.stderr)
        return False, None, {}
    if many and run.ended == "last sample":
        # Wait for the server's STOP (answering a repeated last sample): the next HELLO then reaches the next
        # session, not this one, which would refuse a second controller.
        try:
            while True:
                rig.read()
        except RemoteError:
            pass
    # A rig has no true state: the run is judged from what it measured, as a recorded log is.
    verdict = evaluate_measured(run.log, rig_params)
    summary = {
        "controller": args.controller,
        "rig": args.rig,
        "rig_identity": rig.config.rig,
        "ticks": int(run.log.timem.size),
        "ended": run.ended,
        "ball_lost": rig.ball_lost,
        "verdict_source": "measured (the rig's volts through its calibration: ballbeam judge)",
        **verdict.to_json(),
        **({} if run.timing is None else {"realtime": run.timing.to_json()}),
    }
    return verdict.held, run, summary


def _cmd_serve(args: argparse.Namespace) -> int:
    from twin import protocol
    from twin.engine import ControllerError
    from twin.links import DEFAULT_BAUD, LinkError, SerialLink
    from twin.plant import NumericalError
    from twin.serve import ServeError, Server, SessionSettings

    if args.serial is not None and (args.host != "127.0.0.1" or args.port != 0):
        print(
            "ballbeam serve: error: --serial replaces --host and --port: give one or the other",
            file=sys.stderr,
        )
        return 2
    if args.baud is not None and args.serial is None:
        print("ballbeam serve: error: --baud is the serial line's speed: it needs --serial", file=sys.stderr)
        return 2
    params = _load_params(args)
    paths = check_outputs(
        [("--log", args.log, LOG_SUFFIXES, _log_bytes(args.log, args.duration, params))],
        overwrite=args.overwrite,
        inputs=_inputs(args),
    )
    ideal = bool(args.ideal_sensors or args.plant == "reference")
    settings = SessionSettings(
        x0_m=args.x0,
        theta0_rad=args.theta0,
        duration_s=args.duration,
        seed=args.seed,
        noise=not args.no_noise,
        params=params,
        plant=args.plant,
        ideal_sensors=ideal,
        mode=protocol.MODE_REALTIME if args.mode == "realtime" else protocol.MODE_LOCKSTEP,
        timeout_s=args.timeout,
        watchdog_periods=args.watchdog,
        wait_client_s=args.wait_client,
        rig_name=f"ballbeam-twin {package_version()} {args.plant}",
    )
    try:
        if args.serial is not None:
            try:
                link = SerialLink.open(args.serial, args.baud or DEFAULT_BAUD)
            except LinkError as exc:
                raise ServeError(str(exc)) from None
            server = Server(settings, link=link)
        else:
            server = Server(settings, args.host, args.port)
    except ServeError as exc:
        print(f"ballbeam serve: error: {exc}", file=sys.stderr)
        return 2
    with server:
        print(f"serving on {server.url}", flush=True)
        try:
            session = server.serve()
        except ServeError as exc:
            print(f"ballbeam serve: {exc}", file=sys.stderr)
            return 1
        except (ControllerError, NumericalError) as exc:
            print(f"ballbeam serve: {one_line(exc)}", file=sys.stderr)
            return 1
    if "--log" in paths:
        _save_log(session.result.log, "--log", args.log, paths["--log"], args.overwrite)
    summary = {
        "mode": args.mode,
        "x0_m": args.x0,
        "theta0_rad": args.theta0,
        "seed": args.seed,
        "noise": not args.no_noise,
        "plant": args.plant,
        "ideal_sensors": ideal,
        **session.summary(),
        **session.result.verdict.to_json(),
    }
    if isinstance(server.link, SerialLink):  # what the serial reader threw away before a frame existed
        summary["serial"] = server.link.counts.to_json()
    if args.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:<26} {value}")
    return 0 if session.result.verdict.held else 1


def _save_log(log: RunLog, option: str, text: str, path: Path, overwrite: bool) -> None:
    """Write ``log`` to the checked output ``path`` (``option`` as typed ``text``): .csv as CSV, else .mat."""
    from twin.log import save_csv, save_mat

    save = save_csv if path.suffix.lower() == ".csv" else save_mat
    with writing(option, text):
        save(log, path, overwrite=overwrite)


def _cmd_judge(args: argparse.Namespace) -> int:
    from calib.logs import read_log
    from twin.verdict import evaluate_measured

    params = _load_params(args)
    log = read_log(args.log)
    verdict = evaluate_measured(log, params, x_ref_m=args.setpoint or 0.0)
    summary = {
        "log": args.log,
        "source": "measured",
        "ticks": log.k,
        **({} if args.setpoint is None else {"setpoint_m": args.setpoint}),
        **verdict.to_json(),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:<26} {value}")
    return 0 if verdict.held else 1


def _cmd_view(args: argparse.Namespace) -> int:
    from controllers import registry
    from twin.app.shadow import view_monitor
    from twin.viewer import ViewerError, serve

    params = _load_params(args)
    if args.no_noise:  # the view's noise switch starts off
        params = params.with_overrides({"ball_sensor.noise_enabled": False})
    user = user_controller(args.controller) if args.controller is not None else None
    catalogue: Catalogue = registry
    if user is not None:
        construct(user, args.controller, params)  # a failing constructor is refused here, not in the view
        catalogue = WithUserController(registry, args.controller, user)
    # With --serve the wire client starts unless --controller names another (both are in the menu).
    controller = args.controller or (None if args.serve is not None else "appendix-clp")
    try:
        stats = serve(
            catalogue,
            monitor=view_monitor(),
            host=args.host,
            port=args.port,
            controller=controller,
            speed=args.speed,
            seed=args.seed,
            duration_s=args.duration,
            params=params,
            plant=args.plant,
            ideal_sensors=args.ideal_sensors or args.plant == "reference",
            allowed_origins=tuple(args.allow_origin or ()),
            params_source=_params_source(args),
            wire=args.serve,
            rig_name=f"ballbeam-twin {package_version()} {args.plant}",
        )
    except ViewerError as exc:
        print(f"ballbeam view: error: {exc}", file=sys.stderr)
        return 2
    if args.duration is not None and stats:
        print(json.dumps(stats))
    return 0


def _inputs(args: argparse.Namespace) -> list[tuple[str, str]]:
    """The files a command reads, as (option, path): no output may replace one. A calibration folder brings
    its two files; a user controller its module's file (imported by then)."""
    found: list[tuple[str, str]] = []
    for option in ("params", "spread", "criteria", "table"):
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
    module_name, colon, _ = str(getattr(args, "controller", "")).partition(":")
    module_file = getattr(sys.modules.get(module_name), "__file__", None) if colon else None
    if module_file:
        found.append(("--controller", module_file))
    return found


def _check_job(args: argparse.Namespace, params: Parameters, outputs: JobFiles) -> None:
    """What every many-run command checks before the work (its numbers are checked by their types): the
    controller (built once: a failing constructor is refused here) and the output folder the job writes
    ``outputs`` into."""
    from twin.app.catalogue import catalogue_for

    if args.serve is None:  # served: the client's controller is none of ours
        catalogue_for(args.controller, params)
    if args.out is not None:
        check_output_folder("--out", args.out, outputs, overwrite=args.overwrite, inputs=_inputs(args))


def _params_and_spread(args: argparse.Namespace) -> tuple[Parameters, Distribution | None]:
    """The parameters and the Monte Carlo spread: a calibration brings both; else --params/--set and an
    optional --spread file."""
    from twin.app.montecarlo import load_calibration_spread, load_spread
    from twin.parameters import ParameterError

    if args.calibration is not None:
        if args.params or args.set:
            raise ParameterError("--calibration brings its own parameters: drop --params/--set")
        return load_calibration_spread(args.calibration)
    params = _load_params(args)
    return params, load_spread(args.spread, params) if args.spread is not None else None


def _check_served(args: argparse.Namespace) -> None:
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
def _served(args: argparse.Namespace, params: Parameters) -> Iterator[Served | None]:
    """With --serve: the job's server (one socket for all its sessions, bound before the work; its URL
    printed first), closed after the job; else None."""
    if args.serve is None:
        yield None
        return
    from twin.app.fanout import Served
    from twin.parameters import ParameterError
    from twin.serve import DEFAULT_TIMEOUT_S, ServeError, Server, SessionSettings

    host, port = _serve_address(args.serve)
    settings = SessionSettings(params=params, rig_name=f"ballbeam-twin {package_version()} {args.command}")
    try:
        server = Server(settings, host, port)
    except ServeError as exc:
        raise ParameterError(f"--serve {args.serve}: {exc}") from None
    timeout_s = args.timeout if args.timeout is not None else DEFAULT_TIMEOUT_S
    with server:
        print(f"serving on {server.url}", flush=True)
        yield Served(
            server,
            timeout_s=timeout_s,
            first_wait_s=args.wait_client,
            next_wait_s=args.wait_client if args.wait_client is not None else timeout_s,
        )


def _job_name(args: argparse.Namespace) -> str:
    """What a job's report calls its controller: --controller, else (served) a placeholder until the
    client has said its name (``_client_name``)."""
    return str(args.controller) if args.controller is not None else "served client"


def _client_name(args: argparse.Namespace, served: Served | None) -> str | None:
    """A served job without --controller: the clients' HELLO names, which the report then carries."""
    if served is None or args.controller is not None:
        return None
    return ", ".join(served.client_names()) or "served client (none came)"


def _served_stopped(served: Served | None, what: str, done: int, total: int) -> int | None:
    """1 with a line on stderr when a served job ended for want of a client; else None."""
    if served is None or not served.stopped:
        return None
    print(
        f"ballbeam {what}: {served.stopped}: the job stopped after {done} of {total} runs (they are kept)",
        file=sys.stderr,
    )
    return 1


def _cmd_sweep(args: argparse.Namespace) -> int:
    from twin.app.sweep import (
        DEFAULT_THETA0,
        DEFAULT_X0,
        MAX_POINTS,
        OUTPUT_FILES,
        SweepSettings,
        parse_range,
        run_sweep,
    )
    from twin.app.sweep_render import write_sweep
    from twin.parameters import ParameterError

    _check_served(args)
    robust = args.rigs is not None or args.spread is not None or args.calibration is not None
    if robust:
        if args.rigs is None or (args.spread is None and args.calibration is None):
            raise ParameterError("a robust map needs --rigs N and one of --spread FILE or --calibration DIR")
        if args.serve is not None:
            raise ParameterError("a robust map runs here or on workers, not as served sessions")
    params, spread = _params_and_spread(args) if robust else (_load_params(args), None)
    settings = SweepSettings(
        controller=_job_name(args),
        x0=parse_range("--x0", args.x0) if args.x0 else DEFAULT_X0,
        theta0=parse_range("--theta0", args.theta0) if args.theta0 else DEFAULT_THETA0,
        duration_s=args.duration,
        noise=not args.no_noise,
        plant=args.plant,
        ideal_sensors=bool(args.ideal_sensors or args.plant == "reference"),
        seed=args.seed,
        refine=args.refine,
        audit=args.audit,
        locate=args.locate,
    )
    if args.audit and not args.refine:
        raise ParameterError("--audit checks a refined map: give --refine too")
    if args.locate and robust:
        raise ParameterError("--locate finds one rig's boundary: not with a robust map (--rigs)")
    points = settings.x0.n * settings.theta0.n
    if points > MAX_POINTS:  # refused before the grid is built (its arrays alone may not fit in memory)
        raise ParameterError(
            f"--x0 {settings.x0.n} × --theta0 {settings.theta0.n} = {points} starts: at most {MAX_POINTS}"
        )
    if robust:
        return _robust_sweep(args, settings, params, spread)
    _check_job(args, params, OUTPUT_FILES)
    with _served(args, params) as served:
        result = run_sweep(
            settings,
            params,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=_progress_bar("sweep"),
            serve=served,
        )
    if (client := _client_name(args, served)) is not None:
        result.settings = settings = replace(settings, controller=client)
    _write_out(args, write_sweep, result)
    report = result.to_json()
    if args.json:
        print(json.dumps(report))
    else:
        summary = report["summary"]
        print(
            f"{settings.controller}: {summary['done']} of {summary['points']} starts: held {summary['held']}, "
            f"not held {summary['not_held']}, lost {summary['lost']} ({result.wall_s:.1f} s)"
        )
        if (ref := result.refinement) is not None:
            audit = ref["audit"]
            print(
                f"refined from a step of {ref['coarse_step']}: {ref['run']} starts run "
                f"({100 * ref['run_fraction']:.1f} %), {ref['inferred']} inferred"
                + (
                    f"; audit: {audit['checked']} inferred starts run, {len(audit['mismatches'])} differ"
                    if audit["checked"]
                    else ""
                )
            )
        if (boundary := result.boundary) is not None:
            print(
                f"boundary: {boundary['edges']} grid edges crossed, each located to 1/{2 ** boundary['bisections']} "
                f"of a grid step ({boundary['run']} more runs)"
            )
        for claim in result.claims:
            print(
                f"claim ({claim['source']}): {claim['statement']}: {claim['verdict']} "
                f"({claim['kept']} of {claim['grid_points_inside']} grid starts keep the ball)"
            )
        if args.out is not None:
            print(f"wrote {Path(args.out) / 'sweep.json'} and {Path(args.out) / 'map.png'}")
    stopped = _served_stopped(served, "sweep", sum(map(bool, result.points)), len(result.points))
    if stopped is not None:
        return stopped
    if not result.complete:
        print("ballbeam sweep: interrupted: the starts done so far are kept", file=sys.stderr)
        return 130
    if result.refinement is not None and (wrong := result.refinement["audit"]["mismatches"]):
        first = wrong[0]
        print(
            f"ballbeam sweep: the refinement's assumption fails: {len(wrong)} audited starts differ from their "
            f"inferred class (the first ({first['x0_m']:g}, {first['theta0_rad']:g}): inferred {first['inferred']}, "
            f"run {first['run']}); run with a smaller --refine step or without it",
            file=sys.stderr,
        )
        return 1
    return _controller_failures(result.points, "sweep")


def _robust_sweep(args: argparse.Namespace, settings: Any, params: Parameters, spread: Any) -> int:
    """``sweep --rigs N --spread|--calibration``: the nominal rig's map, then every start on N drawn rigs."""
    from twin.app.robust import OUTPUT_FILES, run_robust
    from twin.app.robust_render import write_robust
    from twin.app.sweep import run_sweep

    _check_job(args, params, OUTPUT_FILES)
    nominal = run_sweep(
        settings,
        params,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=_progress_bar("nominal map"),
    )
    result = run_robust(
        settings,
        params,
        spread,
        args.rigs,
        level=args.level,
        nominal=nominal.points,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=_progress_bar("robust sweep"),
    )
    _write_out(args, write_robust, result)
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        m = result.summary
        print(
            f"{settings.controller}: {m['starts']} starts on {result.rigs} rigs ({result.runs} runs, "
            f"{result.wall_s:.1f} s): kept by every rig {m['kept_by_every_rig']}, held by every rig "
            f"{m['held_by_every_rig']}, lower bound ≥ {result.level:g}: "
            f"{m['robust']} (the best bound {result.rigs} rigs give: {m['best_possible_lower_bound']:.3f}); the "
            f"nominal rig holds {m['nominal_held']}"
        )
        if args.out is not None:
            print(f"wrote {Path(args.out) / 'robust.json'} and {Path(args.out) / 'robust.png'}")
    if not result.complete:
        print("ballbeam sweep: interrupted: the starts done so far are kept", file=sys.stderr)
        return 130
    return 0


def _cmd_montecarlo(args: argparse.Namespace) -> int:
    from twin.app.montecarlo import OUTPUT_FILES, MonteCarloSettings, run_montecarlo
    from twin.app.montecarlo_render import write_montecarlo
    from twin.parameters import ParameterError
    from twin.physics import check_initial_state

    _check_served(args)
    if (args.spread is None) == (args.calibration is None):
        raise ParameterError(
            "give one of --spread FILE or --calibration DIR (what to perturb, and by how much)"
        )
    base, spread = _params_and_spread(args)
    assert spread is not None
    try:
        check_initial_state(base, args.x0, args.theta0, 0.0, 0.0)
    except ValueError as exc:
        raise ParameterError(f"--x0/--theta0: {exc}") from None
    _check_job(args, base, OUTPUT_FILES)
    settings = MonteCarloSettings(
        controller=_job_name(args),
        n=args.n,
        x0_m=args.x0,
        theta0_rad=args.theta0,
        duration_s=args.duration,
        noise=not args.no_noise,
        plant=args.plant,
        ideal_sensors=bool(args.ideal_sensors or args.plant == "reference"),
        seed=args.seed,
    )
    with _served(args, base) as served:
        result = run_montecarlo(
            settings,
            base,
            spread,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=_progress_bar("montecarlo"),
            serve=served,
        )
    if (client := _client_name(args, served)) is not None:
        result.settings = settings = replace(settings, controller=client)
    _write_out(args, write_montecarlo, result)
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        s = result.summary
        ci = s["success_ci"]
        print(
            f"{settings.controller} from ({args.x0:g} m, {args.theta0:g} rad): held {s['held']} of {s['runs']}"
            + (
                f" ({100 * s['success_rate']:.1f} %, 95 % CI {100 * ci[0]:.1f}–{100 * ci[1]:.1f} %)"
                if ci
                else ""
            )
            + f", lost {s['lost']} ({result.wall_s:.1f} s)"
        )
        for name, dist in (("settling time (s)", s["settling_time_s"]), ("steady x (m)", s["steady_x_m"])):
            if dist:
                print(
                    f"  {name}: p5 {dist['p5']:g}, median {dist['p50']:g}, p95 {dist['p95']:g}, max {dist['max']:g}"
                )
        for run in s["worst"][:3]:
            if run["held"]:
                break
            changed = ", ".join(f"{k} = {v:.6g}" for k, v in run["parameters"].items())
            print(f"  worst: {run['reason']} (seed {run['seed']}): {changed}")
        if args.out is not None:
            print(f"wrote {Path(args.out) / 'montecarlo.json'} and {Path(args.out) / 'distributions.png'}")
    stopped = _served_stopped(served, "montecarlo", sum(map(bool, result.runs)), len(result.runs))
    if stopped is not None:
        return stopped
    if not result.complete:
        print("ballbeam montecarlo: interrupted: the runs done so far are kept", file=sys.stderr)
        return 130
    return _controller_failures(result.runs, "montecarlo")


def _cmd_validate(args: argparse.Namespace) -> int:
    from twin.app.validate import (
        OUTPUT_FILES,
        ValidationCriteria,
        check_criteria_for,
        load_criteria,
        validate,
    )
    from twin.app.validate_render import write_validation
    from twin.parameters import ParameterError

    _check_served(args)
    params, spread = _params_and_spread(args)
    criteria = load_criteria(args.criteria) if args.criteria else ValidationCriteria()
    try:
        check_criteria_for(criteria, params)
    except ParameterError as exc:
        raise ParameterError(f"{args.criteria or 'the default criteria'}: {exc}") from None
    _check_job(args, params, OUTPUT_FILES)
    with _served(args, params) as served:
        report = validate(
            _job_name(args),
            params,
            criteria,
            spread=spread,
            seed=args.seed,
            workers=args.workers,
            progress=_progress_bar("validate"),
            serve=served,
        )
    if (client := _client_name(args, served)) is not None:
        report.controller = client
    _write_out(args, write_validation, report)
    if args.json:
        print(json.dumps(report.to_json()))
    else:
        mark = {True: "pass", False: "FAIL", None: "not run"}
        for check in report.checks:
            print(f"{mark[check.passed]:<8} {check.name}: {check.measured}  [{check.criterion}]")
        print(f"{report.controller}: {'PASS' if report.passed else 'FAIL'} ({report.wall_s:.0f} s)")
        if args.out is not None:
            print(f"wrote {Path(args.out) / 'report.md'}")
    if served is not None and served.stopped:
        print(f"ballbeam validate: {served.stopped}: the checks done so far are reported", file=sys.stderr)
        return 1
    if not report.complete:
        print("ballbeam validate: interrupted: the checks done so far are reported", file=sys.stderr)
        return 130
    return 0 if report.passed else 1


def _write_out(args: argparse.Namespace, write: Callable[..., Any], result: Any) -> None:
    """Write a job's result to ``--out`` (checked before the job), an OSError as one line naming it."""
    if args.out is not None:
        with writing("--out", args.out):
            write(result, args.out, overwrite=args.overwrite)


def _progress_bar(what: str, unit: str = "run") -> Callable[..., None]:
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


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from calib.identify import FITTABLE, calibrate
    from calib.logs import load_rig_log
    from calib.report import OUTPUT_FILES, write_report
    from twin.parameters import ParameterError

    start = _load_params(args)
    fit = [name.strip() for name in args.fit.split(",") if name.strip()]
    unknown = [n for n in fit if n not in FITTABLE]
    if not fit or unknown:
        raise ParameterError(f"--fit {args.fit!r}: choose from {', '.join(FITTABLE)}")
    if args.out is not None:
        check_output_folder("--out", args.out, OUTPUT_FILES, overwrite=args.overwrite, inputs=_inputs(args))
    logs = [load_rig_log(path) for path in args.logs]
    period_s = min(log.period_s for log in logs)
    if args.window < 2 * period_s:  # a window is fitted from its ticks' differences: at least two
        raise ParameterError(
            f"--window = {args.window:g}: at least 2 ticks of the logs' {period_s * 1e3:g} ms period "
            f"({2 * period_s:g} s)"
        )

    # A bar per stage over its evaluation budget: the ETA is an upper bound (a fit stops when it converges).
    progress = None if args.json else _progress_bar("calibrate", unit="evaluation")
    cal = calibrate(logs, fit, start, window_s=args.window, progress=progress)
    _write_out(args, write_report, cal)
    if args.json:
        print(json.dumps(cal.to_json()))
    else:
        for name, v in cal.values.items():
            print(
                f"{name:<36} {v.value:12.6g}  [{v.ci_low:.6g}, {v.ci_high:.6g}]  (start {v.initial:.6g}) {v.unit}"
            )
        print(f"converged: {cal.converged} ({cal.message}); {cal.wall_s:.1f} s")
        for warning in cal.warnings:
            print(f"warning: {warning}")
        if args.out is not None:
            print(f"wrote {Path(args.out) / 'params.toml'}, calibration.json, report.md")
    # A fit that did not converge, or whose residuals or information say it cannot be trusted (model
    # mismatch, weak excitation), exits 1: its files are written for inspection, its message is on stderr.
    for problem in cal.problems:
        print(f"calibrate: {problem}", file=sys.stderr)
    return 0 if cal.trustworthy else 1


def _compare_params(args: argparse.Namespace) -> tuple[Parameters, str]:
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
    return _load_params(args), _params_source(args) or "the defaults (thesis values)"


def _hardware_controller(spec: str, params: Parameters) -> Callable[[], Controller]:
    """A factory of fresh hardware controllers named by ``spec`` (one per replayed log); a law on the true state
    or a failing constructor is refused here, before the work."""
    from controllers import registry
    from twin.parameters import ParameterError

    user = user_controller(spec)
    if user is None:
        if registry.simulation_only(spec):
            raise ParameterError(
                f"--controller {spec}: a law on the true state (simulation only); a log is replayed with a "
                "hardware controller (raw volts in, DAC volts out)"
            )

        def named() -> Controller:
            from twin.interface import Controller

            made = registry.make(spec, params)
            if not isinstance(made, Controller):  # the registry's flag says so; the type checker cannot
                raise ParameterError(f"--controller {spec}: not a hardware controller")
            return made

        return named
    construct(user, spec, params)

    def own() -> Controller:
        return construct(user, spec, params)

    return own


def _cmd_shadow(args: argparse.Namespace) -> int:
    """``ballbeam shadow --rig udp://HOST:PORT``: observe, predict each window, test for drift."""
    import contextlib
    import math
    from dataclasses import asdict

    from calib.shadow import Cusum, Shadow, WindowScore
    from twin.app.shadow import REFERENCE_CONTROLLER, load_reference, logs_band, reference_band, watch
    from twin.outputs import atomic_output
    from twin.parameters import ParameterError
    from twin.remote import RemoteError, open_observer

    if args.reference and args.reference_controller:
        raise ParameterError("--reference-controller runs the twin's reference: not with --reference logs")
    base, source = _compare_params(args)
    reference = args.reference_controller or REFERENCE_CONTROLLER
    factory = None if args.reference else _hardware_controller(reference, base)
    paths = check_outputs(
        [("--log", args.log, (".jsonl", ".json"), 1 << 20)], overwrite=args.overwrite, inputs=_inputs(args)
    )
    reference_logs = load_reference(args.reference) if args.reference else None
    try:
        observer = open_observer(args.rig, client="ballbeam shadow", timeout_s=args.idle)
    except RemoteError as exc:
        print(f"ballbeam shadow: {exc}", file=sys.stderr)
        return 1
    with observer:
        params = observer.parameters(base)  # the rig's period, DAC range and software calibration
        # The samples queue in the observer meanwhile: none is lost while the band is measured.
        band = logs_band(reference_logs, params) if reference_logs else None
        if band is None:
            assert factory is not None
            band = reference_band(params, _hardware_controller(reference, params), name=reference)
        default = Cusum()
        test = Cusum(
            k=default.k if args.cusum_k is None else args.cusum_k,
            h=default.h if args.cusum_h is None else args.cusum_h,
        )
        shadow = Shadow(params, band, test)
        p_hour = test.false_alarm_probability(band, int(round(3600.0 / shadow.window_s)))
        head = {
            "rig": observer.url,
            "parameters": source,
            "band": band.to_json(),
            "cusum": test.to_json(),
            "false_alarm_probability_per_hour": p_hour,
        }
        if not args.json:
            print(f"shadow of {observer.url}: parameters {source}")
            print(
                f"band: {band.windows} windows of {band.source}; median error ball "
                f"{1e3 * math.exp(band.mean['ball']):.3g} mm, angle {1e3 * math.exp(band.mean['angle']):.3g} mrad"
            )
            print(
                f"drift test: CUSUM k = {test.k:g}, h = {test.h:g} (band sd) per channel; false alarms: "
                f"{test.run_length_normal():.3g} windows on average for normal scores, probability "
                f"{p_hour:.2%} per hour of windows by resampling the band"
            )
        out = (
            atomic_output(paths["--log"], overwrite=args.overwrite)
            if "--log" in paths
            else contextlib.nullcontext(None)
        )
        with out as fh:

            def line(record: dict[str, object]) -> None:
                if fh is not None:
                    fh.write((json.dumps(record) + "\n").encode("utf-8"))

            line({"shadow": head})

            def on_window(w: WindowScore) -> None:
                line({"session": shadow.session, **w.to_json()})
                for a in w.alarms:
                    print(
                        f"DRIFT ALARM at {a.time_s:.2f} s (session {shadow.session}, window {a.window}): the "
                        f"{a.channel} prediction error {w.rms[a.channel] / math.exp(band.mean[a.channel]):.1f} × "
                        f"the band's median, CUSUM {a.cusum:.1f} > {test.h:g}",
                        flush=True,
                    )
                if not args.quiet and not args.json and not w.skipped:
                    print(
                        f"{w.end_s:8.2f} s  ball {1e3 * w.rms['ball']:7.3f} mm z {w.z['ball']:+5.2f}  angle "
                        f"{1e3 * w.rms['angle']:7.3f} mrad z {w.z['angle']:+5.2f}  cusum "
                        f"{w.cusum['ball']:4.1f} {w.cusum['angle']:4.1f}",
                        flush=True,
                    )

            def on_session(n: int, stop: str) -> None:
                line({"session_end": n, "stop": stop})
                if not args.json:
                    print(f"session {n} ended: {stop}", flush=True)

            result = watch(
                observer,
                shadow,
                sessions=args.sessions,
                idle_timeout_s=args.idle,
                on_window=on_window,
                on_session=on_session,
            )
            summary = {
                **shadow.summary(),
                "sessions": result.sessions,
                "ended": result.ended,
                "wall_s": round(result.wall_s, 2),
                "observer": asdict(observer.counts),
            }
            line({"summary": summary})
    if args.json:
        print(json.dumps({**head, "summary": summary}))
    else:
        print(
            f"{result.ended}; {shadow.scored} windows scored, {shadow.skipped} not; "
            + (
                f"{len(shadow.alarms)} drift alarm(s), the first at {shadow.alarms[0].time_s:.2f} s"
                if shadow.alarms
                else "no drift alarm"
            )
        )
        if "--log" in paths:
            print(f"wrote {paths['--log']}")
    lost = result.sessions == 0 or result.ended.startswith("the rig went silent")
    return 1 if shadow.alarmed or lost else 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from calib.compare import OUTPUT_FILES, Criterion, compare
    from calib.compare_render import write_comparison
    from calib.logs import read_log, rig_log
    from twin.engine import ControllerError
    from twin.parameters import ParameterError
    from twin.plant import NumericalError

    params, source = _compare_params(args)
    criterion = Criterion(min_fit_percent=args.min_fit, max_floor_ratio=args.max_floor_ratio)
    factory = None if args.controller is None else _hardware_controller(args.controller, params)
    check_output_folder("--out", args.out, OUTPUT_FILES, overwrite=args.overwrite, inputs=_inputs(args))
    logs = [(path, read_log(path)) for path in args.logs]
    rigs = [rig_log(log, path) for path, log in logs]  # every log checked before the work
    period_s = min(r.period_s for r in rigs)
    if args.window < 2 * period_s:
        raise ParameterError(
            f"--window = {args.window:g}: at least 2 ticks of the logs' {period_s * 1e3:g} ms period "
            f"({2 * period_s:g} s)"
        )
    if not period_s <= args.horizon <= args.window:
        raise ParameterError(
            f"--horizon = {args.horizon:g}: from one tick ({period_s:g} s) to the window ({args.window:g} s)"
        )
    bar = _progress_bar("compare", unit="step")
    try:
        result = compare(
            logs,
            params,
            params_source=source,
            controller=factory,
            controller_name=args.controller or "",
            window_s=args.window,
            horizon_s=args.horizon,
            criterion=criterion,
            seed=args.seed,
            progress=bar,
        )
    except ControllerError as exc:
        print(f"ballbeam compare: the controller failed: {exc}", file=sys.stderr)
        return 1
    except NumericalError as exc:
        print(f"ballbeam compare: {one_line(exc)}", file=sys.stderr)
        return 1
    _write_out(args, write_comparison, result)
    if args.json:
        print(json.dumps(result.to_json()))
        return 0 if result.passed else 1
    wp = result.windowed
    print(
        f"{wp.n_windows} windows of {wp.window_s:g} s; each window predicted {wp.horizon_s:g} s ahead from the "
        "previous window's fitted end state (scored), and fitted to itself (shown apart)"
    )
    for lw in wp.logs:
        for d in lw.dropped:
            print(f"warning: {lw.path}: the window from {d.start_s:.2f} s left out ({d.reason}): not scored")
    for c in ("ball", "angle"):
        pred, fitted = wp.predicted[c], wp.fitted[c]
        unit, scale = ("mm", 1e3) if c == "ball" else ("mrad", 1e3)
        print(
            f"{c:<6} predicted fit {pred.fit_percent:7.2f} %  RMS {scale * pred.rms:.3g} {unit} "
            f"= {pred.floor_ratio:.1f} × floor {scale * pred.floor:.3g} {unit}  "
            f"whiteness {pred.outside}/{len(pred.acf) - 1} lags outside  (fitted {fitted.fit_percent:.2f} %)"
        )
    for cl in result.closed_loop:
        tracked = ", ".join(
            f"{c} until {'the end' if t is None else f'{t:.2f} s'}" for c, t in cl.tracked_s.items()
        )
        print(f"closed loop {cl.path} ({cl.controller}): tracks the log: {tracked}")
        print(
            f"  verdict  log: {cl.verdict_log.reason}; twin: {cl.verdict_twin.reason} (measured), "
            f"{cl.verdict_twin_true.reason} (true state); agree: {'yes' if cl.verdicts_agree else 'no'}"
        )
    crit = result.criterion
    if result.passed:
        print(
            f"conforms: fit ≥ {crit.min_fit_percent:g} % and RMS ≤ {crit.max_floor_ratio:g} × floor on both channels"
        )
    else:
        print(f"does not conform: {'; '.join(result.failures)}")
    print(f"wrote {Path(args.out) / 'report.md'}, comparison.json and the figures")
    return 0 if result.passed else 1


def _cmd_calibrate_static(args: argparse.Namespace) -> int:
    from calib.static import calibrate, load_table
    from calib.static_render import render_lines, render_toml
    from twin.outputs import atomic_output

    params = _load_params(args)
    paths = check_outputs(
        [("--out", args.out, PARAMS_OUT_SUFFIXES, 0)], overwrite=args.overwrite, inputs=_inputs(args)
    )
    result = calibrate(load_table(args.table), params)
    print(json.dumps(result.to_json(), indent=2) if args.json else "\n".join(render_lines(result)))
    if "--out" in paths:
        with writing("--out", args.out), atomic_output(paths["--out"], overwrite=args.overwrite) as fh:
            fh.write(render_toml(result).encode("utf-8"))
    return 0


def _cmd_experiment(args: argparse.Namespace) -> int:
    from calib.experiments import EXPERIMENTS, run_experiment
    from twin.parameters import ParameterError

    params = _load_params(args)
    if args.name not in EXPERIMENTS:
        raise ParameterError(f"unknown experiment {args.name!r}; known: {', '.join(EXPERIMENTS)}")
    out = check_outputs(
        [("--out", args.out, LOG_SUFFIXES, _log_bytes(args.out, args.duration, params))],
        overwrite=args.overwrite,
        inputs=_inputs(args),
    )["--out"]
    result = run_experiment(args.name, params, duration_s=args.duration, seed=args.seed)
    _save_log(result.log, "--out", args.out, out, args.overwrite)
    print(
        f"{args.name}: {args.duration:g} s, {result.log.k} ticks, ball lost: {result.verdict.ball_lost}; "
        f"wrote {args.out}"
    )
    return 0 if not result.verdict.ball_lost else 1


class _HelpFormatter(argparse.HelpFormatter):
    """Help text wrapped at spaces only: a controller name such as thesis-clp-continuous stays whole."""

    def _split_lines(self, text: str, width: int) -> list[str]:
        import textwrap

        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)


class _Parser(argparse.ArgumentParser):
    """An argparse parser whose usage errors are one line (exit 2), naming the bad argument."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _HelpFormatter)  # subcommands' parsers too
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        # "argument --x0: --x0 '…': …" (a type that names its option) → "--x0 '…': …"
        message = re.sub(r"^argument (--[\w-]+): \1 ", r"\1 ", message)
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _VersionAction(argparse.Action):
    """``--version``: read the version only when asked (importlib.metadata is not free)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        print(f"ballbeam {package_version()}")
        parser.exit()


def _add_params_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--params", metavar="FILE", help="parameter file (TOML or JSON) overriding the defaults"
    )
    parser.add_argument(
        "--set",
        action="append",
        metavar="GROUP.NAME=VALUE",
        help="override one parameter, e.g. --set start.free_run_s=0 (repeatable; applied after --params)",
    )


def _add_plant_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--plant",
        choices=("twin", "reference"),
        default="twin",
        help="the MuJoCo twin (default) or the analytic reference model (always with ideal sensors)",
    )
    parser.add_argument(
        "--ideal-sensors",
        action="store_true",
        help="ideal converters: exact x and θ in the volts the software expects, exact DAC (no quantization, "
        "wiper curve, RC filter or noise)",
    )


def _mc_max_runs() -> float:
    from twin.app.montecarlo import MAX_RUNS

    return MAX_RUNS


def _sweep_max_points() -> float:
    from twin.app.sweep import MAX_POINTS

    return MAX_POINTS


# The numeric options shared by several commands (their types check them when parsed: see twin.app.options).
_JOB_RUN_S = finite_float(
    0, MAX_JOB_RUN_S, lo_open=True, unit="s", why="each run of a many-run job; its verdict is kept"
)
_WORKERS = count(1, MAX_WORKERS, unit="local processes")


_SERVED_CONTROLLER = (
    "; required unless --serve, where it only names what the client runs (never built here; the region "
    "claims about that name are then judged) and the report names the client from its HELLO without it"
)


def _add_spread_options(parser: argparse.ArgumentParser, use: str) -> None:
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


def _add_served_options(parser: argparse.ArgumentParser) -> None:
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


def _add_episode_options(parser: argparse.ArgumentParser) -> None:
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


def build_parser() -> argparse.ArgumentParser:
    from controllers import registry  # its names only: importing it loads no design code

    controller_help = CONTROLLER_HELP.format(names=", ".join(registry.NAMES))
    parser = _Parser(prog="ballbeam", description="Digital twin of the two-wire ball-and-beam rig.")
    parser.add_argument("--version", action=_VersionAction, help="print the version and exit")
    sub = parser.add_subparsers(dest="command", required=True)

    lin = sub.add_parser("linearize", help="continuous-time A, B at the origin")
    lin.add_argument("--input", choices=("torque", "voltage"), default="torque")
    lin.add_argument(
        "--source",
        choices=("twin", "reference"),
        default="twin",
        help="the MuJoCo twin (reduced to its 4 slow modes) or the analytic reference model",
    )
    _add_params_options(lin)
    lin.add_argument("--json", action="store_true", help="print JSON")
    lin.set_defaults(func=_cmd_linearize)

    run = sub.add_parser(
        "run",
        help="run a controller in closed loop and report the verdict (exit 0 held, 1 lost or not held)",
    )
    run.add_argument("--controller", required=True, metavar="NAME|MODULE:CLASS", help=controller_help)
    run.add_argument(
        "--x0", type=finite_float(), metavar="M", help="initial ball position (m; required unless --rig)"
    )
    run.add_argument(
        "--theta0", type=finite_float(), metavar="RAD", help="initial beam angle (rad; required unless --rig)"
    )
    run.add_argument(
        "--rig",
        metavar="URL",
        help="udp://HOST:PORT or serial:///dev/ttyX?baud=N: run on a rig served over protocol 1 (ballbeam "
        "serve, or firmware speaking docs/protocol.md); "
        "its state and duration are the server's; the verdict is judged from the measured signals",
    )
    _add_episode_options(run)
    run.add_argument(
        "--sessions",
        type=count(0, 10_000_000),
        default=1,
        metavar="N",
        help="with --rig: N sessions one after the other, each with a fresh controller and its verdict printed "
        "(0: until the server answers no HELLO within --wait-server: a served job's every run, sweep --serve); "
        "exit 0 only if every session held (default 1)",
    )
    run.add_argument(
        "--wait-server",
        type=finite_float(0, 3600, lo_open=True, unit="s"),
        metavar="S",
        help="with --rig: how long HELLO is repeated before the server counts as gone (default 5)",
    )
    run.add_argument(
        "--setpoint",
        type=finite_float(unit="m"),
        metavar="M",
        help="ball setpoint (m, on the track) for a controller that has one (twin.interface.Setpoint); the "
        "verdict is then judged about it",
    )
    run.add_argument(
        "--realtime",
        action="store_true",
        help="pace the ticks to the wall clock (one every daq.period_s, as on the rig) and report the tick "
        "jitter (p50/p99/max) and overruns",
    )
    _add_plant_options(run)
    run.add_argument(
        "--log",
        metavar="FILE",
        help="save the run: .mat (thesis data_file format) or .csv (written atomically)",
    )
    run.add_argument("--plot", metavar="FILE.png", help="save a PNG of the run")
    run.add_argument("--overwrite", action="store_true", help="replace existing --log/--plot files")
    _add_params_options(run)
    run.add_argument("--json", action="store_true", help="print the verdict as JSON")
    run.set_defaults(func=_cmd_run)

    srv = sub.add_parser(
        "serve",
        help="serve the twin as an I/O card on protocol 1 over UDP or a serial line (docs/protocol.md) for one "
        "session; "
        "prints the session summary and the verdict (exit 0 held, 1 not)",
    )
    srv.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep", help="default lockstep")
    srv.add_argument(
        "--host", default="127.0.0.1", help="interface to serve on (default 127.0.0.1: this machine only)"
    )
    srv.add_argument(
        "--port", type=count(0, 65535), default=0, help="UDP port (default 0: a free one, printed)"
    )
    srv.add_argument(
        "--serial",
        metavar="/dev/ttyX",
        help="serve on this serial line (a tty, raw mode, frames after the sync bytes 0xA5 0x5A) instead of UDP",
    )
    srv.add_argument(
        "--baud", type=count(1, 4_000_000), help="the serial line's speed (with --serial; default 115200)"
    )
    srv.add_argument(
        "--x0", type=finite_float(), required=True, metavar="M", help="initial ball position (m)"
    )
    srv.add_argument(
        "--theta0", type=finite_float(), required=True, metavar="RAD", help="initial beam angle (rad)"
    )
    _add_episode_options(srv)
    _add_plant_options(srv)
    srv.add_argument(
        "--timeout",
        type=finite_float(0, 3600, lo_open=True, unit="s"),
        default=5.0,
        metavar="S",
        help="lock-step: the longest wait for one command before the session ends with STOP 3 (default 5)",
    )
    srv.add_argument(
        "--watchdog",
        type=count(1, 10_000),
        default=5,
        metavar="N",
        help="real time: periods without a command before the output goes to the zero command (default 5)",
    )
    srv.add_argument(
        "--wait-client",
        type=finite_float(0, lo_open=True, unit="s"),
        metavar="S",
        help="give up when no controlling client says HELLO within S seconds (default: wait)",
    )
    srv.add_argument("--log", metavar="FILE", help="save the session: .mat or .csv, with the true state")
    srv.add_argument("--overwrite", action="store_true", help="replace an existing --log file")
    _add_params_options(srv)
    srv.add_argument("--json", action="store_true", help="print the summary and verdict as JSON")
    srv.set_defaults(func=_cmd_serve)

    shd = sub.add_parser(
        "shadow",
        help="watch a rig on the wire (never writing to it): each window predicted by the twin, a drift "
        "alarm when the prediction error leaves its band (exit 0 no alarm, 1 alarm or rig lost, 2 bad input)",
    )
    shd.add_argument(
        "--rig",
        required=True,
        metavar="udp://HOST:PORT",
        help="the rig (ballbeam serve, or firmware) to observe",
    )
    shd.add_argument(
        "--calibration",
        metavar="DIR",
        help="the parameters of a calibration (its params.toml; not with --params)",
    )
    shd.add_argument(
        "--reference",
        nargs="+",
        metavar="LOG",
        help="the band from these logs of the rig when it was known good (e.g. its calibration's logs); "
        "default: the twin's own runs at the parameters",
    )
    shd.add_argument(
        "--reference-controller",
        default=None,
        metavar="NAME|MODULE:CLASS",
        help="the hardware controller of the twin's reference runs (default appendix-sf; not with --reference)",
    )
    shd.add_argument(
        "--sessions",
        type=count(0, 10_000_000),
        default=1,
        metavar="N",
        help="watch N sessions (0: until no session follows within --idle; default 1)",
    )
    shd.add_argument(
        "--idle",
        type=finite_float(0, lo_open=True, unit="s"),
        default=5.0,
        metavar="S",
        help="the rig counts as gone after this long without a frame (default 5)",
    )
    shd.add_argument(
        "--cusum-k",
        type=finite_float(0, unit="sd"),
        default=None,
        metavar="K",
        help="the CUSUM's reference value in band sd (default 1: half the 2-sd shift it detects fastest)",
    )
    shd.add_argument(
        "--cusum-h",
        type=finite_float(0, lo_open=True, unit="sd"),
        default=None,
        metavar="H",
        help="the CUSUM's alarm threshold in band sd (default 7: see the README for its false-alarm rate)",
    )
    shd.add_argument(
        "--log", metavar="FILE.jsonl", help="write every window and alarm as JSON lines (atomically)"
    )
    shd.add_argument("--overwrite", action="store_true", help="replace an existing --log file")
    shd.add_argument("--quiet", action="store_true", help="print only the band, the alarms and the summary")
    shd.add_argument("--json", action="store_true", help="print the summary as JSON")
    _add_params_options(shd)
    shd.set_defaults(func=_cmd_shadow)

    jdg = sub.add_parser(
        "judge",
        help="the verdict of a recorded log (a rig's data_file.mat or CSV) from its measured signals only "
        "(exit 0 held, 1 lost or not held, 2 bad input)",
    )
    jdg.add_argument("log", metavar="LOG.mat|LOG.csv", help="the log: timem, datam1, datam2, aout are read")
    jdg.add_argument(
        "--setpoint", type=finite_float(unit="m"), metavar="M", help="judge the ball about this position (m)"
    )
    _add_params_options(jdg)
    jdg.add_argument("--json", action="store_true", help="print the verdict as JSON")
    jdg.set_defaults(func=_cmd_judge)

    sweep = sub.add_parser(
        "sweep",
        help="region of attraction: a grid of initial states, a map (PNG) and the verdict of every start (JSON)",
    )
    sweep.add_argument("--controller", metavar="NAME|MODULE:CLASS", help=controller_help + _SERVED_CONTROLLER)
    sweep.add_argument(
        "--x0",
        type=GridType("--x0", max_n=_sweep_max_points),
        metavar="LO:HI:N",
        help="initial ball positions (default -0.32:0.32:41, the chapter 7 range)",
    )
    sweep.add_argument(
        "--theta0",
        type=GridType("--theta0", max_n=_sweep_max_points),
        metavar="LO:HI:N",
        help="initial beam angles (default -0.7:0.7:41, the chapter 7 range)",
    )
    sweep.add_argument(
        "--duration", type=_JOB_RUN_S, default=10.0, metavar="S", help="seconds per run (default 10)"
    )
    sweep.add_argument(
        "--seed", type=seed(), default=0, help="base seed; each start's seed follows from it and its index"
    )
    sweep.add_argument("--no-noise", action="store_true", help="switch the ball sensor's contact noise off")
    _add_plant_options(sweep)
    _add_params_options(sweep)
    sweep.add_argument(
        "--workers", type=_WORKERS, default=1, help="local processes (default 1: this process)"
    )
    sweep.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a Dask distributed scheduler, e.g. tcp://10.0.0.5:8786, to fan the grid out to "
        "(pip install 'ballbeam-twin[distributed]'); results equal the local run's",
    )
    sweep.add_argument(
        "--refine",
        type=count(2, 1024),
        nargs="?",
        const=DEFAULT_REFINE_STEP,
        default=0,
        metavar="STEP",
        help=f"boundary refinement: run a coarse grid (every STEP-th start, default {DEFAULT_REFINE_STEP}), "
        "bisect its lines where their classes change, then follow each boundary start by start; the other "
        "starts take the class of the run starts around them (assumed: every boundary crosses a coarse line "
        "between coarse starts of different classes)",
    )
    sweep.add_argument(
        "--audit",
        type=count(0, 100_000),
        default=0,
        metavar="N",
        help="with --refine: also run N inferred starts, at random, and report any that differ",
    )
    sweep.add_argument(
        "--locate",
        type=count(0, MAX_LOCATE),
        default=0,
        metavar="K",
        help="bisect every grid edge the boundary crosses K times (off-grid starts, seeded), locating each "
        "crossing to 1/2^K of a grid step: K more runs per crossed edge; in sweep.json's 'boundary' and on "
        "the map",
    )
    _add_spread_options(sweep, "for the robust map's rigs (with --rigs N)")
    sweep.add_argument(
        "--rigs",
        type=count(1, MAX_RIGS),
        metavar="N",
        help="robust map: every start on N rigs drawn from --spread or --calibration (the same N everywhere); "
        "per start the rigs that hold it and an exact lower bound; writes DIR/robust.json and DIR/robust.png",
    )
    sweep.add_argument(
        "--level",
        type=finite_float(0.0, 1.0),
        default=0.95,
        help="robust map: the share of rigs a start must be held by, as a 95 %% lower bound (default 0.95)",
    )
    _add_served_options(sweep)
    sweep.add_argument("--out", metavar="DIR", help="write DIR/sweep.json and DIR/map.png")
    sweep.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    sweep.add_argument("--json", action="store_true", help="print the whole result as JSON")
    sweep.set_defaults(func=_cmd_sweep)

    mc = sub.add_parser(
        "montecarlo",
        help="robustness: one start over many perturbed rigs and noise seeds; success rate with its interval",
    )
    mc.add_argument("--controller", metavar="NAME|MODULE:CLASS", help=controller_help + _SERVED_CONTROLLER)
    mc.add_argument("--n", type=count(1, _mc_max_runs), default=200, help="runs (default 200)")
    _add_spread_options(mc, "for the perturbed rigs")
    mc.add_argument(
        "--x0", type=finite_float(), default=-0.2, metavar="M", help="initial ball position (default -0.2)"
    )
    mc.add_argument(
        "--theta0", type=finite_float(), default=0.3, metavar="RAD", help="initial beam angle (default 0.3)"
    )
    mc.add_argument(
        "--duration", type=_JOB_RUN_S, default=15.0, metavar="S", help="seconds per run (default 15)"
    )
    mc.add_argument("--seed", type=seed(), default=0, help="seed of the samples and of every run's noise")
    mc.add_argument("--no-noise", action="store_true", help="switch the ball sensor's contact noise off")
    _add_plant_options(mc)
    _add_params_options(mc)
    mc.add_argument("--workers", type=_WORKERS, default=1, help="local processes (default 1: this process)")
    mc.add_argument(
        "--scheduler", metavar="ADDRESS", help="a Dask distributed scheduler to fan the runs out to"
    )
    _add_served_options(mc)
    mc.add_argument("--out", metavar="DIR", help="write DIR/montecarlo.json and DIR/distributions.png")
    mc.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    mc.add_argument("--json", action="store_true", help="print the whole result as JSON")
    mc.set_defaults(func=_cmd_montecarlo)

    val = sub.add_parser(
        "validate",
        help="the standard battery before hardware: nominal starts, region, sensitivities, saturation, "
        "Monte Carlo; one report, exit 0 pass / 1 fail",
    )
    val.add_argument("--controller", metavar="NAME|MODULE:CLASS", help=controller_help + _SERVED_CONTROLLER)
    _add_spread_options(val, "for the robust-region and Monte Carlo checks")
    val.add_argument("--criteria", metavar="FILE", help="TOML overriding the pass criteria (see the report)")
    val.add_argument("--seed", type=seed(), default=0, help="base seed of every run's noise")
    _add_params_options(val)
    val.add_argument("--workers", type=_WORKERS, default=1, help="local processes (default 1: this process)")
    _add_served_options(val)
    val.add_argument("--out", metavar="DIR", help="write DIR/report.md, DIR/validation.json, DIR/region.png")
    val.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    val.add_argument("--json", action="store_true", help="print the report as JSON")
    val.set_defaults(func=_cmd_validate)

    view = sub.add_parser("view", help="live 3D view of the twin in the browser (viser)")
    view.add_argument(
        "--allow-origin",
        action="append",
        metavar="ORIGIN",
        help="also accept browser connections from this origin, e.g. http://lab-pc:8080 (repeatable; "
        "by default only the page's own origin may drive the twin)",
    )
    view.add_argument(
        "--host", default="127.0.0.1", help="interface to serve on (default 127.0.0.1: this machine only)"
    )
    view.add_argument(
        "--port", type=count(1, 65535), default=8080, help="port (default 8080); a taken port is an error"
    )
    view.add_argument(
        "--controller",
        metavar="NAME|MODULE:CLASS",
        help=f"the controller to start with (default appendix-clp; with --serve the wire client): {controller_help}",
    )
    view.add_argument(
        "--serve",
        type=serve_address,
        metavar="[HOST:]PORT",
        help="serve the twin on protocol 1 over UDP there (host 127.0.0.1 unless given; port 0: a free one) "
        "to a controller in any language, e.g. examples/c/bb_sf udp 127.0.0.1 PORT: the menu's wire client, "
        "in real time (docs/protocol.md)",
    )
    view.add_argument(
        "--speed",
        type=finite_float(
            SPEED_MIN,
            SPEED_MAX,
            unit="simulated seconds per wall second",
            why="the range of its speed slider",
        ),
        default=1.0,
        help=f"simulated seconds per wall second, {SPEED_MIN:g}…{SPEED_MAX:g} (default 1.0)",
    )
    view.add_argument("--seed", type=seed(), default=0, help="seed of the sensor noise (default 0)")
    view.add_argument(
        "--no-noise", action="store_true", help="start with the ball sensor's contact noise off (the switch)"
    )
    view.add_argument(
        "--duration",
        type=finite_float(0, lo_open=True, unit="s"),
        metavar="S",
        help="stop after S wall-clock seconds (headless runs)",
    )
    _add_plant_options(view)
    _add_params_options(view)
    view.set_defaults(func=_cmd_view)

    cal = sub.add_parser(
        "calibrate",
        help="fit the twin's parameters to logs recorded on a rig (exit 0 converged and adequate; 1 not "
        "converged, model mismatch or weak excitation; 2 a log refused)",
    )
    cal.add_argument("logs", nargs="+", metavar="LOG", help="data_file.mat or .csv logs of the same rig")
    cal.add_argument(
        "--fit",
        required=True,
        metavar="NAME,NAME,…",
        help="parameters to fit, e.g. motor.resistance_ohm,beam.inertia_pivot_kgm2 (see README)",
    )
    cal.add_argument("--out", metavar="DIR", help="write params.toml, calibration.json and report.md here")
    cal.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    cal.add_argument(
        "--window",
        type=finite_float(0, unit="s"),  # its minimum, 2 ticks, follows from the logs' period
        default=1.0,
        metavar="S",
        help="window length (default 1 s; at least 2 ticks of the logs)",
    )
    cal.add_argument("--json", action="store_true", help="print calibration.json")
    _add_params_options(cal)
    cal.set_defaults(func=_cmd_calibrate)

    cmp_ = sub.add_parser(
        "compare",
        help="the twin's prediction of recorded logs: windowed prediction and, with --controller, the closed loop "
        "from the first block; report, figures, JSON (exit 0 conforms, 1 not, 2 bad input)",
    )
    cmp_.add_argument(
        "logs", nargs="+", metavar="LOG", help="data_file.mat or .csv logs (rig, run, serve, experiment)"
    )
    cmp_.add_argument(
        "--out", required=True, metavar="DIR", help="write report.md, comparison.json and PNGs here"
    )
    cmp_.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    cmp_.add_argument(
        "--calibration",
        metavar="DIR",
        help="the parameters of a calibration (its params.toml; not with --params)",
    )
    cmp_.add_argument(
        "--controller",
        metavar="NAME|MODULE:CLASS",
        help="the hardware controller that ran: the twin then runs it from each log's first block. "
        + controller_help,
    )
    cmp_.add_argument(
        "--window",
        type=finite_float(0, unit="s"),  # its minimum, 2 ticks, follows from the logs' period
        default=1.0,
        metavar="S",
        help="window whose fitted state starts the next prediction (default 1 s, as calibrate)",
    )
    cmp_.add_argument(
        "--horizon",
        type=finite_float(0, lo_open=True, unit="s"),
        default=0.5,
        metavar="S",
        help="seconds predicted and scored from each window's start (default 0.5: two e-folding times of the "
        "open-loop plant's unstable pole, 3.8 /s)",
    )
    cmp_.add_argument(
        "--min-fit",
        type=finite_float(hi=100.0, unit="%"),
        default=90.0,
        metavar="PCT",
        help="conformance: the prediction's fit %% on each channel at least this (default 90)",
    )
    cmp_.add_argument(
        "--max-floor-ratio",
        type=finite_float(0, lo_open=True),
        default=20.0,
        metavar="K",
        help="conformance: the prediction's residual RMS at most K × the channel's noise floor (default 20)",
    )
    cmp_.add_argument("--seed", type=seed(), default=0, help="seed of the closed-loop twin's sensor noise")
    cmp_.add_argument("--json", action="store_true", help="print comparison.json")
    _add_params_options(cmp_)
    cmp_.set_defaults(func=_cmd_compare)

    stat = sub.add_parser("calibrate-static", help="fit a sensor's static curve from a measured table (CSV)")
    stat.add_argument(
        "table", metavar="TABLE.csv", help="columns position_m,volts_v (ball) or di,volts_v (angle)"
    )
    stat.add_argument("--out", metavar="FILE.toml", help="write the fitted parameters as a parameter file")
    stat.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    stat.add_argument("--json", action="store_true", help="print JSON")
    _add_params_options(stat)
    stat.set_defaults(func=_cmd_calibrate_static)

    exp = sub.add_parser("experiment", help="run an identification experiment on the twin and save its log")
    exp.add_argument("name", metavar="NAME", help="square (recommended), dither or sweep")
    exp.add_argument("--out", required=True, metavar="LOG.mat", help="the log: .mat (thesis format) or .csv")
    exp.add_argument(
        "--duration",
        type=finite_float(5, MAX_RUN_S, unit="s", why="the log keeps every tick in memory"),
        default=60.0,
        metavar="S",
        help=f"seconds, 5…{MAX_RUN_S:g} (default 60)",
    )
    exp.add_argument("--seed", type=seed(), default=0, help="seed of the dither and the sensor noise")
    exp.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    _add_params_options(exp)
    exp.set_defaults(func=_cmd_experiment)

    par = sub.add_parser("params", help="list every parameter with its unit and source")
    _add_params_options(par)
    par.add_argument("--json", action="store_true", help="print JSON")
    par.set_defaults(func=_cmd_params)
    for command in (run, sweep, mc, val, view, cmp_):
        _add_controller_timeout(command)
    return parser


def _add_controller_timeout(command: argparse.ArgumentParser) -> None:
    from twin.guard import FIRST_CALL_BUDGET_S, MIN_UPDATE_BUDGET_S, UPDATE_BUDGET_PERIODS

    command.add_argument(
        "--controller-timeout",
        type=float,
        metavar="SECONDS",
        help=f"fail a controller whose update does not return within SECONDS (default: "
        f"{UPDATE_BUDGET_PERIODS} control periods, at least {MIN_UPDATE_BUDGET_S:g} s; its import, "
        f"construction and start get at least {FIRST_CALL_BUDGET_S:g} s); inf: no watchdog (a debugger)",
    )


def _controller_failures(records: Sequence[dict[str, Any] | None], what: str) -> int:
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


def _option_strings(parser: argparse.ArgumentParser) -> tuple[set[str], set[str]]:
    """The options (of the parser and its subcommands) that take a number, and all options."""
    numeric: set[str] = set()
    every: set[str] = set()
    parsers = [parser]
    while parsers:
        for action in parsers.pop()._actions:
            every.update(action.option_strings)
            if action.option_strings and isinstance(action.type, (NumberType, GridType)):
                numeric.update(action.option_strings)
            if isinstance(action, argparse._SubParsersAction):
                parsers.extend(action.choices.values())
    return numeric, every


def _is_number(text: str) -> bool:
    """A number, or a range of numbers ``LO:HI:N``."""
    try:
        for part in text.split(":"):
            float(part)
    except ValueError:
        return False
    return True


def join_negative_numbers(argv: Sequence[str], parser: argparse.ArgumentParser) -> list[str]:
    """``--x0 -1e-2`` → ``--x0=-1e-2`` for the options that take a number.

    argparse reads a token that starts with '-' as an option unless it looks like ``-1`` or ``-.5``, so
    ``-1e-2`` or ``-inf`` after a numeric option would be refused; joined with '=' it is the option's value.
    An unambiguous prefix (``--th -0.3``) counts; nothing after ``--`` is touched."""
    numeric, every = _option_strings(parser)
    args = list(argv)
    out: list[str] = []
    i = 0
    while i < len(args):
        token = args[i]
        if token == "--":
            out.extend(args[i:])
            break
        if (
            token.startswith("--")
            and "=" not in token
            and i + 1 < len(args)
            and args[i + 1].startswith("-")
            and _is_number(args[i + 1])
            and (token in numeric or (token not in every and any(n.startswith(token) for n in numeric)))
        ):
            out.append(f"{token}={args[i + 1]}")
            i += 2
            continue
        out.append(token)
        i += 1
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(join_negative_numbers(sys.argv[1:] if argv is None else argv, parser))
    except SystemExit as exc:  # --help, --version, or a usage error already reported on one line
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    from twin.guard import (
        check_timeout_s,
        default_timeout_s,
        install_interrupt_handler,
        set_default_timeout_s,
    )

    install_interrupt_handler()  # the user's Ctrl-C told apart from a controller's KeyboardInterrupt
    previous_timeout_s = default_timeout_s()
    try:
        set_default_timeout_s(
            check_timeout_s(getattr(args, "controller_timeout", None), "--controller-timeout")
        )
        return int(args.func(args))
    except BrokenPipeError:  # output piped into e.g. head
        return 0
    except SystemExit as exc:  # not ours (the controllers' calls are guarded): never a silent success
        print(f"ballbeam: error: unexpected SystemExit({exc.code!r})", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # Ctrl-C outside the long jobs (which keep what they did and return 130)
        print("ballbeam: interrupted", file=sys.stderr)
        return 130
    except (ValueError, OSError) as exc:  # bad input, or an output that cannot be written: no traceback
        print(f"ballbeam: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except FloatingPointError as exc:  # twin.plant.NumericalError: the simulation failed, not the input
        print(f"ballbeam: {one_line(exc)}", file=sys.stderr)
        return 1
    finally:
        set_default_timeout_s(previous_timeout_s)  # the caller's own default (main called in-process)


if __name__ == "__main__":
    sys.exit(main())
