"""``ballbeam serve``: the twin as an I/O card on protocol 1 for one session."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from typing import Any

from twin.app.catalogue import one_line
from twin.app.commands.common import (
    LOG_SUFFIXES,
    ParamsOptions,
    add_episode_options,
    add_params_options,
    add_plant_options,
    check_overwrite,
    inputs,
    load_params,
    log_bytes,
    options_from,
    refuse_unused,
    save_log,
)
from twin.app.options import count, finite_float
from twin.outputs import check_outputs
from twin.rigs.backends import backend

HELP = (
    "serve the twin as an I/O card on protocol 1 over UDP or a serial line (docs/protocol.md) for one "
    "session; "
    "prints the session summary and the verdict (exit 0 held, 1 not)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--mode", choices=("lockstep", "realtime"), default="lockstep", help="default lockstep"
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="interface to serve on (default 127.0.0.1: this machine only)"
    )
    parser.add_argument(
        "--port", type=count(0, 65535), default=0, help="UDP port (default 0: a free one, printed)"
    )
    parser.add_argument(
        "--serial",
        metavar="/dev/ttyX",
        help="serve on this serial line (a tty, raw mode, frames after the sync bytes 0xA5 0x5A) instead of UDP",
    )
    parser.add_argument(
        "--baud", type=count(1, 4_000_000), help="the serial line's speed (with --serial; default 115200)"
    )
    parser.add_argument(
        "--x0", type=finite_float(), required=True, metavar="M", help="initial ball position (m)"
    )
    parser.add_argument(
        "--theta0", type=finite_float(), required=True, metavar="RAD", help="initial beam angle (rad)"
    )
    add_episode_options(parser)
    add_plant_options(parser)
    parser.add_argument(
        "--timeout",
        type=finite_float(0, 3600, lo_open=True, unit="s"),
        default=5.0,
        metavar="S",
        help="lock-step: the longest wait for one command before the session ends with STOP 3; also how long "
        "an observer may be silent, at least 1 s, before its place is freed (default 5)",
    )
    parser.add_argument(
        "--watchdog",
        type=count(1, 10_000),
        default=None,  # the server's default (5); given in lock-step, refused: that mode waits instead
        metavar="N",
        help="real time: periods without a command before the output goes to the zero command (default 5)",
    )
    parser.add_argument(
        "--wait-client",
        type=finite_float(0, 86400, lo_open=True, unit="s"),
        metavar="S",
        help="give up when no controlling client says HELLO within S seconds, at most a day (default: wait "
        "until one comes)",
    )
    parser.add_argument("--log", metavar="FILE", help="save the session: .mat or .csv, with the true state")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --log file")
    add_params_options(parser)
    parser.add_argument("--json", action="store_true", help="print the summary and verdict as JSON")


@dataclass(frozen=True)
class Options:
    """``serve``'s options."""

    mode: str
    host: str
    port: int
    serial: str | None
    baud: int | None
    x0: float
    theta0: float
    duration: float
    seed: int
    no_noise: bool
    plant: str
    ideal_sensors: bool
    timeout: float
    watchdog: int | None
    wait_client: float | None
    log: str | None
    overwrite: bool
    json: bool
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from twin.app.commands.common import package_version
    from twin.engine import ControllerError
    from twin.plant import NumericalError
    from twin.serving.server import ServeError, Server, SessionSettings
    from twin.wire import protocol
    from twin.wire.links import DEFAULT_BAUD, LinkError, SerialLink

    if o.serial is not None and (o.host != "127.0.0.1" or o.port != 0):
        print(
            "ballbeam serve: error: --serial replaces --host and --port: give one or the other",
            file=sys.stderr,
        )
        return 2
    if o.baud is not None and o.serial is None:
        print("ballbeam serve: error: --baud is the serial line's speed: it needs --serial", file=sys.stderr)
        return 2
    if o.mode == "lockstep":  # a lock-step session waits for each command (--timeout): no watchdog
        refuse_unused([("--watchdog", o.watchdog)], "the real-time watchdog: it needs --mode realtime")
    check_overwrite(o.overwrite, [("--log", o.log)])
    params = load_params(o.parameters)
    paths = check_outputs(
        [("--log", o.log, LOG_SUFFIXES, log_bytes(o.log, o.duration, params))],
        overwrite=o.overwrite,
        inputs=inputs(params=o.parameters.params, rig_file=o.parameters.rig_file),
    )
    ideal = bool(o.ideal_sensors or backend(o.plant).ideal_converters)
    watchdog: dict[str, Any] = {} if o.watchdog is None else {"watchdog_periods": o.watchdog}
    settings = SessionSettings(
        x0_m=o.x0,
        theta0_rad=o.theta0,
        duration_s=o.duration,
        seed=o.seed,
        noise=not o.no_noise,
        params=params,
        plant=o.plant,
        ideal_sensors=ideal,
        mode=protocol.MODE_REALTIME if o.mode == "realtime" else protocol.MODE_LOCKSTEP,
        timeout_s=o.timeout,
        **watchdog,
        wait_client_s=o.wait_client,
        rig_name=f"ballbeam-twin {package_version()} {o.plant}",
    )
    try:
        if o.serial is not None:
            try:
                link = SerialLink.open(o.serial, o.baud or DEFAULT_BAUD)
            except LinkError as exc:
                raise ServeError(str(exc)) from None
            server = Server(settings, link=link)
        else:
            server = Server(settings, o.host, o.port)
    except ServeError as exc:
        print(f"ballbeam serve: error: {exc}", file=sys.stderr)
        return 2
    with server:
        # The address first (port 0 picks one): with --json stdout is JSON lines, this one and the summary.
        print(json.dumps({"serving_on": server.url}) if o.json else f"serving on {server.url}", flush=True)
        try:
            session = server.serve()
        except ServeError as exc:
            print(f"ballbeam serve: {exc}", file=sys.stderr)
            return 1
        except (ControllerError, NumericalError) as exc:
            print(f"ballbeam serve: {one_line(exc)}", file=sys.stderr)
            return 1
    if o.log is not None and "--log" in paths:
        save_log(session.result.log, "--log", o.log, paths["--log"], o.overwrite)
    summary = {
        "mode": o.mode,
        "x0_m": o.x0,
        "theta0_rad": o.theta0,
        "seed": o.seed,
        "noise": not o.no_noise,
        "plant": o.plant,
        "ideal_sensors": ideal,
        **session.summary(),
        **session.result.verdict.to_json(),
    }
    if o.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:<26} {value}")
    return 0 if session.result.verdict.held else 1
