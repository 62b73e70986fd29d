"""``ballbeam serve``: the twin as an I/O card on protocol 1 for one session."""

from __future__ import annotations

import argparse
import json
import sys

from twin.app.catalogue import one_line
from twin.app.commands.common import (
    LOG_SUFFIXES,
    add_episode_options,
    add_params_options,
    add_plant_options,
    check_overwrite,
    inputs,
    load_params,
    log_bytes,
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


def run(args: argparse.Namespace) -> int:
    from twin.app.commands.common import package_version
    from twin.engine import ControllerError
    from twin.plant import NumericalError
    from twin.serving.server import ServeError, Server, SessionSettings
    from twin.wire import protocol
    from twin.wire.links import DEFAULT_BAUD, LinkError, SerialLink

    if args.serial is not None and (args.host != "127.0.0.1" or args.port != 0):
        print(
            "ballbeam serve: error: --serial replaces --host and --port: give one or the other",
            file=sys.stderr,
        )
        return 2
    if args.baud is not None and args.serial is None:
        print("ballbeam serve: error: --baud is the serial line's speed: it needs --serial", file=sys.stderr)
        return 2
    if args.mode == "lockstep":  # a lock-step session waits for each command (--timeout): no watchdog
        refuse_unused([("--watchdog", args.watchdog)], "the real-time watchdog: it needs --mode realtime")
    check_overwrite(args, "--log")
    params = load_params(args)
    paths = check_outputs(
        [("--log", args.log, LOG_SUFFIXES, log_bytes(args.log, args.duration, params))],
        overwrite=args.overwrite,
        inputs=inputs(args),
    )
    ideal = bool(args.ideal_sensors or backend(args.plant).ideal_converters)
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
        **({} if args.watchdog is None else {"watchdog_periods": args.watchdog}),
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
        # The address first (port 0 picks one): with --json stdout is JSON lines, this one and the summary.
        print(json.dumps({"serving_on": server.url}) if args.json else f"serving on {server.url}", flush=True)
        try:
            session = server.serve()
        except ServeError as exc:
            print(f"ballbeam serve: {exc}", file=sys.stderr)
            return 1
        except (ControllerError, NumericalError) as exc:
            print(f"ballbeam serve: {one_line(exc)}", file=sys.stderr)
            return 1
    if "--log" in paths:
        save_log(session.result.log, "--log", args.log, paths["--log"], args.overwrite)
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
    if args.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:<26} {value}")
    return 0 if session.result.verdict.held else 1
