"""``ballbeam shadow``: watch a rig on the wire, predict each window with the twin, test for drift."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.app.commands.common import (
    ParamsOptions,
    add_params_options,
    check_overwrite,
    compare_params,
    hardware_controller,
    inputs,
    options_from,
    progress_bar,
    refuse_part_rig,
    refuse_unused,
)
from twin.app.options import count, finite_float
from twin.outputs import check_outputs

if TYPE_CHECKING:
    from calib.shadow import Band, Shadow
    from twin.app.shadow import WatchResult
    from twin.parameters import Parameters
    from twin.serving.observer import Observer

HELP = (
    "watch a rig on the wire (never writing to it): each window predicted by the twin, a drift "
    "alarm when the prediction error leaves its band (exit 0 no alarm, 1 alarm or rig lost, 2 bad input)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--rig",
        required=True,
        metavar="udp://HOST:PORT",
        help="the rig (ballbeam serve, or firmware) to observe",
    )
    parser.add_argument(
        "--calibration",
        metavar="DIR",
        help="the parameters of a calibration (its params.toml; not with --params)",
    )
    parser.add_argument(
        "--reference",
        nargs="+",
        metavar="LOG",
        help="the band from these logs of the rig when it was known good (e.g. its calibration's logs); "
        "default: the twin's own runs at the parameters",
    )
    parser.add_argument(
        "--reference-controller",
        default=None,
        metavar="NAME|MODULE:CLASS",
        help="the hardware controller of the twin's reference runs (default appendix-sf; not with --reference)",
    )
    parser.add_argument(
        "--sessions",
        type=count(0, 10_000_000),
        default=1,
        metavar="N",
        help="watch N sessions (0: until no session follows within --idle; default 1)",
    )
    parser.add_argument(
        "--idle",
        type=finite_float(0, lo_open=True, unit="s"),
        default=5.0,
        metavar="S",
        help="the rig counts as gone after this long without a frame (default 5)",
    )
    parser.add_argument(
        "--start-wait",
        type=finite_float(0, lo_open=True, unit="s"),
        default=600.0,
        metavar="S",
        help="how long a session the shadow joined waits for its controller's first sample (default 600; "
        "--idle applies once the session runs)",
    )
    parser.add_argument(
        "--cusum-k",
        type=finite_float(0, unit="sd"),
        default=None,
        metavar="K",
        help="the CUSUM's reference value in band sd (default 1: half the 2-sd shift it detects fastest)",
    )
    parser.add_argument(
        "--cusum-h",
        type=finite_float(0, lo_open=True, unit="sd"),
        default=None,
        metavar="H",
        help="the CUSUM's alarm threshold in band sd (default 7: docs/watch.md gives its false-alarm rate)",
    )
    parser.add_argument(
        "--log", metavar="FILE.jsonl", help="write every window and alarm as JSON lines (atomically)"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --log file")
    parser.add_argument(
        "--quiet", action="store_true", help="print only the band, the alarms and the summary"
    )
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_params_options(parser)


@dataclass(frozen=True)
class Options:
    """``shadow``'s options."""

    rig: str
    calibration: str | None
    reference: list[str] | None
    reference_controller: str | None
    sessions: int
    idle: float
    start_wait: float
    cusum_k: float | None
    cusum_h: float | None
    log: str | None
    overwrite: bool
    quiet: bool
    json: bool
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    """``ballbeam shadow --rig udp://HOST:PORT``: observe, predict each window, test for drift."""
    from twin.app.shadow import REFERENCE_CONTROLLER, load_reference, logs_band, reference_band
    from twin.parameters import ParameterError
    from twin.rigs.remote import RemoteError
    from twin.serving.observer import open_observer

    if o.reference and o.reference_controller:
        raise ParameterError("--reference-controller runs the twin's reference: not with --reference logs")
    check_overwrite(o.overwrite, [("--log", o.log)])
    if o.json:  # JSON prints the summary alone: there is nothing for --quiet to leave out
        refuse_unused([("--quiet", o.quiet)], "--json prints the summary alone: drop one")
    base, source = compare_params(o.parameters, o.calibration)
    refuse_part_rig(base, "shadow", "watch it in the live view (ballbeam view --rig-file) instead")
    reference = o.reference_controller or REFERENCE_CONTROLLER
    factory = None if o.reference else hardware_controller(reference, base)
    paths = check_outputs(
        [("--log", o.log, (".jsonl", ".json"), 1 << 20)],
        overwrite=o.overwrite,
        inputs=inputs(
            params=o.parameters.params,
            rig_file=o.parameters.rig_file,
            reference=o.reference,
            calibration=o.calibration,
        ),
    )
    reference_logs = load_reference(o.reference) if o.reference else None
    try:
        observer = open_observer(o.rig, client="ballbeam shadow", timeout_s=o.idle)
    except RemoteError as exc:
        print(f"ballbeam shadow: {exc}", file=sys.stderr)
        return 1
    with observer:
        params = observer.parameters(base)  # the rig's period, DAC range and software calibration
        if not o.json:
            print(
                f"shadow of {observer.url}: parameters {source}; measuring the band (progress on stderr), "
                "the session's samples queued meanwhile",
                flush=True,
            )
        # The samples queue in the observer meanwhile: none is lost while the band is measured.
        bar = progress_bar("shadow: measuring the band", unit="tick")
        if reference_logs:
            band = logs_band(reference_logs, params, progress=bar)
        else:
            assert factory is not None
            band = reference_band(
                params, hardware_controller(reference, params), name=reference, progress=bar
            )
        shadow, head = _start(o, observer.url, params, band, source)
        if not o.json:
            print(
                f"watching {observer.url}: start the rig's controller now if it has not started (a session "
                f"waits up to {o.start_wait:g} s for it, --start-wait)",
                flush=True,
            )
        result, summary = _watch(o, observer, shadow, head, paths.get("--log"))
    if o.json:
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


def _start(
    o: Options, url: str, params: Parameters, band: Band, source: str
) -> tuple[Shadow, dict[str, Any]]:
    """The shadow of the rig at ``url`` on ``band`` with its drift test (``--cusum-k``, ``--cusum-h``), and
    the head of its report (printed unless ``--json``)."""
    import math

    from calib.shadow import Cusum, Shadow

    default = Cusum()
    test = Cusum(
        k=default.k if o.cusum_k is None else o.cusum_k,
        h=default.h if o.cusum_h is None else o.cusum_h,
    )
    shadow = Shadow(params, band, test)
    p_hour = test.false_alarm_probability(band, int(round(3600.0 / shadow.window_s)))
    head = {
        "rig": url,
        "parameters": source,
        "band": band.to_json(),
        "cusum": test.to_json(),
        "false_alarm_probability_per_hour": p_hour,
    }
    if not o.json:
        print(
            f"band: {band.windows} windows of {band.source}; median error ball "
            f"{1e3 * math.exp(band.mean['ball']):.3g} mm, angle {1e3 * math.exp(band.mean['angle']):.3g} mrad"
        )
        print(
            f"drift test: CUSUM k = {test.k:g}, h = {test.h:g} (band sd) per channel; false alarms: "
            f"{test.run_length_normal():.3g} windows on average for normal scores, probability "
            f"{p_hour:.2%} per hour of windows by resampling the band"
        )
    return shadow, head


def _watch(
    o: Options, observer: Observer, shadow: Shadow, head: dict[str, Any], log: Path | None
) -> tuple[WatchResult, dict[str, Any]]:
    """Watch ``--sessions`` sessions: every window scored, its alarms (and unless ``--quiet`` its scores)
    printed, every record written to ``log`` (JSON lines, atomically) if given; the result and summary."""
    import contextlib
    import math
    from dataclasses import asdict

    from calib.shadow import WindowScore
    from twin.app.shadow import watch
    from twin.outputs import atomic_output

    band, test = shadow.band, shadow.test
    out = atomic_output(log, overwrite=o.overwrite) if log is not None else contextlib.nullcontext(None)
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
            if not o.quiet and not o.json and not w.skipped:
                print(
                    f"{w.end_s:8.2f} s  ball {1e3 * w.rms['ball']:7.3f} mm z {w.z['ball']:+5.2f}  angle "
                    f"{1e3 * w.rms['angle']:7.3f} mrad z {w.z['angle']:+5.2f}  cusum "
                    f"{w.cusum['ball']:4.1f} {w.cusum['angle']:4.1f}",
                    flush=True,
                )

        def on_session(n: int, stop: str) -> None:
            line({"session_end": n, "stop": stop})
            if not o.json:
                print(f"session {n} ended: {stop}", flush=True)

        result = watch(
            observer,
            shadow,
            sessions=o.sessions,
            idle_timeout_s=o.idle,
            start_timeout_s=o.start_wait,
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
    return result, summary
