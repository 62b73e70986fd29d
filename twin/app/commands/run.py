"""``ballbeam run``: a controller in closed loop on the twin, or on a rig over the wire (``--rig``)."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.app.catalogue import one_line
from twin.app.commands.common import (
    LOG_SUFFIXES,
    ParamsOptions,
    add_controller_timeout,
    add_episode_options,
    add_params_options,
    add_plant_options,
    check_flick,
    check_overwrite,
    controller_help,
    inputs,
    load_params,
    log_bytes,
    options_from,
    refuse_unused,
    save_log,
)
from twin.app.options import count, finite_float
from twin.outputs import check_outputs, writing
from twin.rigs.backends import DEFAULT_PLANT, backend

if TYPE_CHECKING:
    from twin.app.replay import Replay
    from twin.engine import RunResult
    from twin.parameters import Parameters
    from twin.realtime import WallClockPacer
    from twin.requirements import Requirement
    from twin.verdict import Verdict

PLOT_SUFFIXES = (".png",)
_PLOT_BYTES = 20_000  # a lower bound of a plot's size, to refuse a disk without room before the run

HELP = "run a controller in closed loop and report the verdict (exit 0 held, 1 lost or not held)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--controller",
        metavar="NAME|MODULE:CLASS|avr:FILE.elf",
        help=controller_help() + " (required unless --replay)",
    )
    parser.add_argument(
        "--replay",
        metavar="FILE",
        help="repeat a run bit for bit: falsify --out's falsify.json (its counterexample, else its least robust "
        "run) or certify's certify.json (its failing run): controller, engine, start, seed, noise, duration, "
        "parameters and requirements from the file; the summary says whether each robustness is the one the "
        "file states. A file naming your own code (MODULE:CLASS, avr:, fmu:) runs it only when you name it "
        "with --controller or pass --trust-replay-controller, and only if its SHA-256 is the file's",
    )
    parser.add_argument(
        "--trust-replay-controller",
        action="store_true",
        help="with --replay: run the MODULE:CLASS, firmware image or FMU the file names without naming it with "
        "--controller (that code runs here: use it for files you made; stderr says what runs)",
    )
    parser.add_argument(
        "--x0", type=finite_float(), metavar="M", help="initial ball position (m; required unless --rig)"
    )
    parser.add_argument(
        "--theta0", type=finite_float(), metavar="RAD", help="initial beam angle (rad; required unless --rig)"
    )
    parser.add_argument(
        "--rig",
        metavar="URL",
        help="udp://HOST:PORT or serial:///dev/ttyX?baud=N: run on a rig served over protocol 1 (ballbeam "
        "serve, or firmware speaking docs/protocol.md); "
        "its state and duration are the server's; the verdict is judged from the measured signals",
    )
    add_episode_options(parser)
    parser.set_defaults(duration=None, seed=None)  # 15 s and seed 0 unless --replay brings its own
    parser.add_argument(
        "--sessions",
        type=count(0, 10_000_000),
        default=1,
        metavar="N",
        help="with --rig: N sessions one after the other, each with a fresh controller and its verdict printed "
        "(0: until the server answers no HELLO within --wait-server: a served job's every run, sweep --serve); "
        "exit 0 only if every session held (default 1)",
    )
    parser.add_argument(
        "--wait-server",
        type=finite_float(0, 3600, lo_open=True, unit="s"),
        metavar="S",
        help="with --rig: how long HELLO is repeated before the server counts as gone (default 5)",
    )
    parser.add_argument(
        "--wait-sample",
        type=finite_float(0, 3600, lo_open=True, unit="s"),
        metavar="S",
        help="with --rig: the longest wait for the next SAMPLE (silence, or a sample repeated because our "
        "commands do not reach the server) before the server counts as gone (default 5)",
    )
    parser.add_argument(
        "--wait-start",
        type=finite_float(0, 86400, lo_open=True, unit="s"),
        metavar="S",
        help="with --rig: how long a held session may wait to start once we acknowledged its held sample (a "
        "live view waits for its browser) (default: as long as the server holds it)",
    )
    parser.add_argument(
        "--spec",
        metavar="FILE",
        help='requirements in signal temporal logic (TOML [requirements] name = "formula"; '
        "docs/requirements.md): each one's robustness in the summary; exit 1 when one is violated",
    )
    parser.add_argument(
        "--setpoint",
        type=finite_float(unit="m"),
        metavar="M",
        help="ball setpoint (m, on the track) for a controller that has one (twin.interface.Setpoint); the "
        "verdict is then judged about it",
    )
    parser.add_argument(
        "--flick-time",
        type=finite_float(0, unit="s"),
        metavar="S",
        help="flick the ball this long after release (at the next tick boundary), as the live view's Flick",
    )
    parser.add_argument(
        "--flick-speed",
        type=finite_float(unit="m/s"),
        default=None,
        metavar="M/S",
        help="the flick's kick along the beam (m/s; with --flick-time)",
    )
    parser.add_argument(
        "--realtime",
        action="store_true",
        help="pace the ticks to the wall clock (one every daq.period_s, as on the rig) and report the tick "
        "jitter (p50/p99/max) and overruns",
    )
    add_plant_options(parser)
    parser.add_argument(
        "--log",
        metavar="FILE",
        help="save the run: .mat (thesis data_file format) or .csv (written atomically)",
    )
    parser.add_argument("--plot", metavar="FILE.png", help="save a PNG of the run")
    parser.add_argument("--overwrite", action="store_true", help="replace existing --log/--plot files")
    add_params_options(parser)
    parser.add_argument("--json", action="store_true", help="print the verdict as JSON")
    add_controller_timeout(parser)


@dataclass(frozen=True)
class Options:
    """``run``'s options."""

    controller: str | None
    replay: str | None
    trust_replay_controller: bool
    x0: float | None
    theta0: float | None
    rig: str | None
    duration: float | None
    seed: int | None
    no_noise: bool
    sessions: int
    wait_server: float | None
    wait_sample: float | None
    wait_start: float | None
    spec: str | None
    setpoint: float | None
    flick_time: float | None
    flick_speed: float | None
    realtime: bool
    plant: str
    ideal_sensors: bool
    log: str | None
    plot: str | None
    overwrite: bool
    json: bool
    controller_timeout: float | None
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    replay, o = _replayed(o)
    _check_options(o, replay)
    if replay is None:
        if o.controller is None:
            print("ballbeam run: error: --controller is required (unless --replay)", file=sys.stderr)
            return 2
        o = replace(
            o, duration=15.0 if o.duration is None else o.duration, seed=0 if o.seed is None else o.seed
        )
    params = replay.params if replay is not None else load_params(o.parameters)
    requirements = replay.requirements if replay is not None else None
    if o.spec is not None:
        from twin.requirements import load_requirements

        if o.rig is not None:
            raise ValueError("--spec judges the twin's true state: not with --rig (a rig's measured signals)")
        requirements = load_requirements(o.spec)
    _check_timing(o, requirements, params)
    if o.rig is not None:
        return _run_on_remote_rig(o, params)
    rig_only = (o.wait_server, o.wait_sample, o.wait_start)
    if o.sessions != 1 or any(wait is not None for wait in rig_only):
        print(
            "ballbeam run: error: --sessions, --wait-server, --wait-sample and --wait-start are a rig's: they "
            "need --rig",
            file=sys.stderr,
        )
        return 2
    if o.x0 is None or o.theta0 is None:
        print(
            "ballbeam run: error: --x0 and --theta0 are required (unless --rig: the server's)",
            file=sys.stderr,
        )
        return 2
    # With --json, stdout carries the summary alone: what the controller prints (at import, in its
    # constructor or its ticks) goes to stderr.
    out = sys.stdout
    with contextlib.redirect_stdout(sys.stderr) if o.json else contextlib.nullcontext():
        outcome = _run_in_process(o, params)
    if isinstance(outcome, int):
        return outcome
    result, paths, pacer = outcome
    if o.setpoint is not None:
        result.verdict = _verdict_about(result, params, o.x0, o.setpoint)
    if o.log is not None and "--log" in paths:
        save_log(result.log, "--log", o.log, paths["--log"], o.overwrite)
    if o.plot is not None and "--plot" in paths:
        from twin.app.plots import plot_run

        with writing("--plot", o.plot):
            plot_run(result, paths["--plot"], overwrite=o.overwrite, software=params.software)
    summary = {
        "controller": o.controller,
        "x0_m": o.x0,
        "theta0_rad": o.theta0,
        "seed": o.seed,
        "noise": not o.no_noise,
        "plant": o.plant,
        "ideal_sensors": _ideal_sensors(o),
        "free_run_s": params.start.free_run_s,
        **({} if o.setpoint is None else {"setpoint_m": o.setpoint}),
        **result.verdict.to_json(),
    }
    if result.firmware is not None:
        from twin.avr.firmware import stuck_output

        summary["firmware"] = result.firmware
        stuck = None if result.verdict.held else stuck_output(result.firmware, params.period_s)
        if stuck:
            summary["firmware_warning"] = stuck
            print(f"ballbeam run: {stuck}", file=sys.stderr)
    if pacer is not None:
        summary.update(_realtime_summary(pacer))
    from twin.plant import through_stops  # the physics' own module: loaded once a run has run

    warning = through_stops(result.verdict.peak_theta_rad, params)
    if warning:
        summary["warning"] = warning
        print(f"ballbeam run: warning: {warning}", file=sys.stderr)
    held = result.verdict.held
    if requirements is not None:
        from twin.requirements import margins, violated

        values = margins(requirements, result.log, params, o.setpoint or 0.0)
        summary["requirements"] = values
        if replay is not None:
            summary["replayed"] = {
                "file": replay.source,
                "robustness_stated": replay.robustness,
                "same": values == replay.robustness,
            }
            if values != replay.robustness:
                print(f"ballbeam run: the robustness differs from {replay.source}'s", file=sys.stderr)
        bad = violated(values)
        held = held and not bad
        if bad:
            print(f"ballbeam run: requirements violated: {', '.join(bad)}", file=sys.stderr)
    if o.json:
        print(json.dumps(summary), file=out)
    else:
        for key, value in summary.items():
            print(f"{key:<26} {value}")
    return 0 if held else 1


def _realtime_summary(pacer: WallClockPacer) -> dict[str, object]:
    """The paced run's timing, and a warning (also on stderr) when it did not keep real time."""
    from twin.realtime import overrun_warning

    timing = pacer.timing()
    late = overrun_warning(timing)
    if late is None:
        return {"realtime": timing.to_json()}
    print(f"ballbeam run: warning: {late}", file=sys.stderr)
    return {"realtime": timing.to_json(), "realtime_warning": late}


def _check_options(o: Options, replay: Replay | None) -> None:
    """Options this run would not use are refused, not ignored: those a run on ``--rig`` leaves to the server,
    ``--overwrite`` with nothing to write, a flick without its time or kick, after the run or beyond the live
    view's Flick range."""
    if o.rig is not None:
        refuse_unused(_set_by_the_rig(o), "with --rig the server sets the run and its rig: drop it")
    check_overwrite(o.overwrite, [("--log", o.log), ("--plot", o.plot)])
    if replay is None and o.rig is None:
        duration = 15.0 if o.duration is None else o.duration
        flick = [None if v is None else (v, v) for v in (o.flick_time, o.flick_speed)]
        check_flick(flick[0], flick[1], duration)


def _check_timing(o: Options, requirements: tuple[Requirement, ...] | None, params: Parameters) -> None:
    """The requirements' time bounds against this run's duration and period (``check_timing``)."""
    if requirements is not None:
        from twin.requirements import check_timing

        where = o.spec if o.spec is not None else f"{o.replay}: requirements"
        assert o.duration is not None  # the default's, or the replay's
        check_timing(requirements, where, params.period_s, o.duration)


def _set_by_the_rig(o: Options) -> list[tuple[str, object]]:
    """The options of a run here that a run on ``--rig`` does not use (the server's start, duration, noise,
    plant and pacing; a flick, setpoint or plot of the run here)."""
    return [
        ("--x0", o.x0),
        ("--theta0", o.theta0),
        ("--duration", o.duration),
        ("--seed", o.seed),
        ("--no-noise", o.no_noise),
        ("--plant", None if o.plant == DEFAULT_PLANT else o.plant),
        ("--ideal-sensors", o.ideal_sensors),
        ("--realtime", o.realtime),
        ("--setpoint", o.setpoint),
        ("--flick-time", o.flick_time),
        ("--flick-speed", o.flick_speed),
        ("--plot", o.plot),
    ]


def _replayed(o: Options) -> tuple[Replay | None, Options]:
    """``--replay FILE``: the run it names and the options with its values (options the file sets are refused;
    its controller only as ``replay_controller`` allows); (None, the options) without ``--replay``."""
    from twin.app.replay import load_replay, refuse_given, replay_controller
    from twin.parameters import ParameterError

    if o.replay is None:
        if o.trust_replay_controller:
            raise ParameterError("--trust-replay-controller goes with --replay FILE")
        return None, o

    refuse_given(
        [
            ("--x0", o.x0),
            ("--theta0", o.theta0),
            ("--duration", o.duration),
            ("--seed", o.seed),
            ("--no-noise", o.no_noise),
            ("--rig-file", o.parameters.rig_file),
            ("--params", o.parameters.params),
            ("--set", o.parameters.set),
            ("--spec", o.spec),
            ("--rig", o.rig),
            ("--setpoint", o.setpoint),
            ("--flick-time", o.flick_time),
            ("--flick-speed", o.flick_speed),
            ("--plant", None if o.plant == DEFAULT_PLANT else o.plant),
            ("--ideal-sensors", o.ideal_sensors),
        ]
    )
    replay = load_replay(o.replay)
    replay_controller(replay, o.controller, o.trust_replay_controller, "ballbeam run")
    flick_time, flick_speed = replay.flick if replay.flick is not None else (None, None)
    replayed = replace(
        o,
        plant=replay.plant,
        ideal_sensors=replay.ideal_sensors,
        controller=replay.controller,
        x0=replay.x0_m,
        theta0=replay.theta0_rad,
        seed=replay.seed,
        no_noise=not replay.noise,
        duration=replay.duration_s,
        setpoint=replay.setpoint_m,
        flick_time=flick_time,
        flick_speed=flick_speed,
    )
    return replay, replayed


def _ideal_sensors(o: Options) -> bool:
    """``--ideal-sensors``, always with ``--plant reference``; a replay's as its file states (the fast engine's
    runs: the reference plant under the twin's sensor chain)."""
    if o.replay is not None:
        return bool(o.ideal_sensors)
    return bool(o.ideal_sensors or backend(o.plant).ideal_converters)


def _run_in_process(
    o: Options, params: Parameters
) -> int | tuple[RunResult, dict[str, Path], WallClockPacer | None]:
    """The controller built and run on the twin: (the result, the checked output paths, the pacer), or the
    exit code of a failure (reported)."""
    from twin.app.hosts import build
    from twin.engine import ControllerError, Scenario
    from twin.plant import NumericalError
    from twin.realtime import WallClockPacer
    from twin.rigs.sim import run_closed_loop

    # run_command checked these or set them (its defaults, or the replay's)
    assert o.controller is not None and o.x0 is not None and o.theta0 is not None
    assert o.duration is not None and o.seed is not None
    paths = check_outputs(
        [
            ("--log", o.log, LOG_SUFFIXES, log_bytes(o.log, o.duration, params)),
            ("--plot", o.plot, PLOT_SUFFIXES, _PLOT_BYTES),
        ],
        overwrite=o.overwrite,
        inputs=inputs(
            params=o.parameters.params,
            rig_file=o.parameters.rig_file,
            spec=o.spec,
            replay=o.replay,
            controller=o.controller,
        ),
    )
    controller = build(o.controller, params)
    if o.setpoint is not None:
        _apply_setpoint(controller, o.controller, o.setpoint, params)
    pacer = WallClockPacer(params.period_s) if o.realtime else None
    try:
        result = run_closed_loop(
            controller,
            x0_m=o.x0,
            theta0_rad=o.theta0,
            duration_s=o.duration,
            seed=o.seed,
            noise=not o.no_noise,
            params=params,
            plant=o.plant,
            ideal_sensors=_ideal_sensors(o),
            pacer=pacer,
            scenario=None if o.flick_time is None else Scenario(o.flick_time, o.flick_speed or 0.0),
        )
    except ControllerError as exc:
        print(f"ballbeam run: the controller failed: {exc}", file=sys.stderr)
        return 1
    except NumericalError as exc:  # the simulation failed: no physical verdict
        print(f"ballbeam run: {one_line(exc)}", file=sys.stderr)
        return 1
    return result, paths, pacer


def _apply_setpoint(controller: object, spec: str, setpoint_m: float, params: Parameters) -> None:
    """``--setpoint``: on the track, and only for a controller that declares one (twin.interface.Setpoint)."""
    from twin.interface import Setpoint
    from twin.parameters import ParameterError
    from twin.physics import check_on_track

    check_on_track(params, "--setpoint", setpoint_m)
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
    from twin.verdict import Trace

    log, first = result.log, result.verdict
    return judge(
        params,
        Trace(
            log.true_time_s,
            log.true_x_m,
            log.true_theta_rad,
            log.motor_volts_v,
            np.array([first.peak_theta_rad]),
        ),
        x0_m=x0_m,
        ball_lost_time_s=first.ball_lost_time_s,
        x_ref_m=setpoint_m,
    )


def _run_on_remote_rig(o: Options, params: Parameters) -> int:
    """``run --rig udp://HOST:PORT`` (or ``serial:///dev/ttyX?baud=N``): the controller through
    ``twin.rigs.remote.RemoteRig`` (``twin.rigs.session``). The rig's initial state, duration and noise are the
    server's; the verdict is judged from the measured signals (``ballbeam serve`` prints the true state's).
    ``--sessions N``: N sessions one after the other (0: until the server stops answering HELLO within
    ``--wait-server``), a fresh controller each, built from that session's CONFIG (a served job's runs,
    ``sweep --serve``)."""
    from twin.app.hosts import host_of
    from twin.rigs.session import Waits, run_on_remote_rig
    from twin.wire.links import parse_url

    assert o.rig is not None and o.controller is not None and o.duration is not None  # run_command's
    try:
        parse_url(o.rig)
    except ValueError as exc:
        raise ValueError(f"--rig {exc}") from None
    host = host_of(o.controller)
    if host.kind == "firmware":  # refused before the other options are read (its row's message)
        host.wire(o.controller)
    if o.sessions != 1 and o.log is not None:
        raise ValueError(
            "--log keeps one session's log: with --sessions other than 1 the server keeps every run (its "
            "job's report, or serve --log)"
        )
    make_controller = host.wire(o.controller)  # its host's row (twin.app.hosts): checked once here
    paths = check_outputs(
        [("--log", o.log, LOG_SUFFIXES, log_bytes(o.log, o.duration, params))],
        overwrite=o.overwrite,
        inputs=inputs(
            params=o.parameters.params,
            rig_file=o.parameters.rig_file,
            spec=o.spec,
            replay=o.replay,
            controller=o.controller,
        ),
    )
    many = o.sessions != 1

    def on_run(done: int, run: RunResult, summary: dict[str, Any]) -> None:
        if o.log is not None and "--log" in paths:
            save_log(run.log, "--log", o.log, paths["--log"], o.overwrite)
        if many:
            summary = {"session": done, **summary}
        if o.json:
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

    return run_on_remote_rig(
        o.rig,
        params,
        make_controller,
        name=o.controller,
        sessions=o.sessions,
        wait_s=o.wait_server or 5.0,
        on_run=on_run,
        waits=Waits(o.wait_sample or 5.0, o.wait_start),
    )
