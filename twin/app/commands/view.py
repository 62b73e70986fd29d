"""``ballbeam view``: the live 3D view of the twin in the browser."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from twin.app.commands.common import (
    ParamsOptions,
    add_controller_timeout,
    add_params_options,
    add_plant_options,
    controller_help,
    load_params,
    options_from,
    params_source,
)
from twin.app.hosts import catalogue_for
from twin.app.options import count, finite_float, seed, serve_address
from twin.rigs.backends import DEFAULT_PLANT, backend

if TYPE_CHECKING:
    from twin.engine import Catalogue

# The live view's speed slider (twin.viewer) runs from 0.1 to 4.
SPEED_MIN, SPEED_MAX = 0.1, 4.0

HELP = "live 3D view of the twin in the browser (viser)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--allow-origin",
        action="append",
        metavar="ORIGIN",
        help="also accept browser connections from this origin, e.g. http://lab-pc:8080 (repeatable; "
        "by default only the page's own origin may drive the twin)",
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="interface to serve on (default 127.0.0.1: this machine only)"
    )
    parser.add_argument(
        "--port", type=count(1, 65535), default=8080, help="port (default 8080); a taken port is an error"
    )
    parser.add_argument(
        "--controller",
        metavar="NAME|MODULE:CLASS|avr:FILE.elf",
        help=f"the controller to start with (default appendix-clp; with --serve the wire client): {controller_help()}",
    )
    parser.add_argument(
        "--serve",
        type=serve_address,
        metavar="[HOST:]PORT",
        help="serve the twin on protocol 1 over UDP there (host 127.0.0.1 unless given; port 0: a free one) "
        "to a controller in any language, e.g. examples/c/bb_sf udp 127.0.0.1 PORT: the menu's wire client, "
        "in real time (docs/protocol.md)",
    )
    parser.add_argument(
        "--wire-timeout",
        type=finite_float(0, 3600, lo_open=True, unit="s"),
        metavar="S",
        help="with --serve: how long the wire client's answer is awaited (its acknowledgement, a command) before "
        "its session ends with STOP 3 and a new one waits for a client (default 5)",
    )
    parser.add_argument(
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
    parser.add_argument("--seed", type=seed(), default=None, help="seed of the sensor noise (default 0)")
    parser.add_argument(
        "--replay",
        metavar="FILE",
        help="open a run to repeat (falsify.json's counterexample, certify.json's failing run): its controller, "
        "engine, start, seed, noise and parameters; Reset repeats it. A file naming your own code (MODULE:CLASS, "
        "avr:, fmu:) runs it only when you name it with --controller or pass --trust-replay-controller, and "
        "only if its SHA-256 is the file's",
    )
    parser.add_argument(
        "--trust-replay-controller",
        action="store_true",
        help="with --replay: run the MODULE:CLASS, firmware image or FMU the file names without naming it with "
        "--controller (that code runs here: use it for files you made; stderr says what runs)",
    )
    parser.add_argument(
        "--no-noise", action="store_true", help="start with the ball sensor's contact noise off (the switch)"
    )
    parser.add_argument(
        "--duration",
        type=finite_float(0, lo_open=True, unit="s"),
        metavar="S",
        help=(
            "stop after S wall-clock seconds and print the pace as JSON (the run still starts when the first "
            "browser connects)"
        ),
    )
    add_plant_options(parser)
    add_params_options(parser)
    add_controller_timeout(parser)


@dataclass(frozen=True)
class Options:
    """``view``'s options."""

    allow_origin: list[str] | None
    host: str
    port: int
    controller: str | None
    serve: tuple[str, int] | None
    wire_timeout: float | None
    speed: float
    seed: int | None
    replay: str | None
    trust_replay_controller: bool
    no_noise: bool
    duration: float | None
    plant: str
    ideal_sensors: bool
    controller_timeout: float | None
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from controllers import registry
    from twin.app.commands.common import package_version
    from twin.app.shadow import view_monitor
    from twin.viewer import ViewerError, serve

    initial = None
    ideal_sensors = o.ideal_sensors or backend(o.plant).ideal_converters
    if o.wire_timeout is not None and o.serve is None:
        print("ballbeam view: error: --wire-timeout is the wire client's: it needs --serve", file=sys.stderr)
        return 2
    if o.trust_replay_controller and o.replay is None:
        print("ballbeam view: error: --trust-replay-controller goes with --replay FILE", file=sys.stderr)
        return 2
    if o.replay is not None:
        from twin.app.replay import load_replay, refuse_given, replay_controller

        refuse_given(
            [
                ("--seed", o.seed),
                ("--rig-file", o.parameters.rig_file),
                ("--rig-file", o.parameters.rig_file),
                ("--params", o.parameters.params),
                ("--set", o.parameters.set),
                ("--no-noise", o.no_noise),
                ("--plant", None if o.plant == DEFAULT_PLANT else o.plant),
                ("--ideal-sensors", o.ideal_sensors),
            ]
        )
        replay = load_replay(o.replay)
        replay_controller(replay, o.controller, o.trust_replay_controller, "ballbeam view")
        params = replay.params
        # the engine the run was made on
        o = replace(
            o, controller=replay.controller, seed=replay.seed, no_noise=not replay.noise, plant=replay.plant
        )
        ideal_sensors = replay.ideal_sensors
        initial = (replay.x0_m, replay.theta0_rad)
    else:
        params = load_params(o.parameters)
    seed = 0 if o.seed is None else o.seed
    if o.no_noise:  # the view's noise switch starts off
        params = params.with_overrides({"ball_sensor.noise_enabled": False})
    # a failing constructor or a bad image is refused here, not in the view
    catalogue: Catalogue = registry if o.controller is None else catalogue_for(o.controller, params)
    # With --serve the wire client starts unless --controller names another (both are in the menu).
    controller = o.controller or (None if o.serve is not None else "appendix-clp")
    try:
        stats = serve(
            catalogue,
            monitor=view_monitor(),
            host=o.host,
            port=o.port,
            controller=controller,
            speed=o.speed,
            seed=seed,
            duration_s=o.duration,
            params=params,
            plant=o.plant,
            ideal_sensors=ideal_sensors,
            allowed_origins=tuple(o.allow_origin or ()),
            params_source=params_source(o.parameters),
            wire=o.serve,
            wire_timeout_s=5.0 if o.wire_timeout is None else o.wire_timeout,
            rig_name=f"ballbeam-twin {package_version()} {o.plant}",
            initial=initial,
        )
    except ViewerError as exc:
        print(f"ballbeam view: error: {exc}", file=sys.stderr)
        return 2
    if o.duration is not None and stats:
        print(json.dumps(stats))
    return 0
