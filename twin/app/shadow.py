"""``ballbeam shadow``: the twin watching a rig on the wire (``calib.shadow``), and the band it tests against.

The shadow is an observer of the rig's sessions (``twin.serving.observer.Observer``: the samples, and the commands the
rig applied, echoed to observers): it never writes to the rig. ``watch`` feeds each sample with the DAC volts
of its block (``twin.serving.observer.block_dac_v``) to a ``calib.shadow.Shadow`` and works off the complete windows
whenever no sample is waiting (a lock-step session outruns the shadow: its windows are worked off in
batches, none lost).

The band (the in-control distribution of a window's prediction error) comes from windows a right model
predicts: by default the twin's own runs at the shadow's parameters — a hardware controller (appendix A's
state feedback unless told) from the four chapter 6 hardware starts, with the sensor chain and its noise
(``reference_band``) — or logs the user recorded on the rig when it was known good (``logs_band``, e.g. the
logs its calibration was fitted to).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from calib.compare import windowed_prediction
from calib.logs import RigLog, load_rig_log, rig_log
from calib.shadow import MAX_BATCH_WINDOWS, Band, Shadow, WindowScore
from twin.rigs.remote import RemoteError
from twin.serving.observer import Joined, Observer, block_dac_v
from twin.wire import protocol as p

if TYPE_CHECKING:
    from twin.interface import Controller
    from twin.parameters import Parameters

__all__ = [
    "REFERENCE_CONTROLLER",
    "REFERENCE_DURATION_S",
    "WatchResult",
    "load_reference",
    "logs_band",
    "reference_band",
    "view_monitor",
    "watch",
]

REFERENCE_CONTROLLER = "appendix-sf"
# Four runs of 150 s: 592 predicted windows, enough for the band's tails that set the false-alarm rate
# (a band of 4 × 60 s put the resampled false-alarm probability per hour at twice that of 4 × 150 s).
REFERENCE_DURATION_S = 150.0
FALSE_ALARM_HOURS = 1.0  # the false-alarm probability is stated over an hour of windows
# A band's build reports (done, total, stage), as ``twin.app.commands.common.progress_bar`` takes them.
Progress = Callable[[int, int, str], None]
# The commands kept for the echo lookup: the applied one is at most a few periods old (the watchdog's).
_COMMANDS_KEPT = 256


def reference_band(
    params: Parameters,
    controller: Callable[[], Controller],
    *,
    name: str = REFERENCE_CONTROLLER,
    duration_s: float = REFERENCE_DURATION_S,
    seed: int = 0,
    progress: Progress | None = None,
) -> Band:
    """The band of the twin at ``params``: ``controller`` run from each chapter 6 hardware start for
    ``duration_s`` with the hardware sensor chain (noise seeds ``seed``, ``seed`` + 1, …), each run's windows
    predicted at ``params`` — a model exactly right, with the estimate's error only.

    ``progress`` gets ``(done, total, stage)`` over the whole build, in ticks: each run's closed loop counts
    its ticks, the fit of its windows as many again (the two take about as long)."""
    from calib.compare import TickProgress
    from controllers.thesis_numbers import HARDWARE_STARTS
    from twin.engine import update_ticks
    from twin.rigs.sim import run_closed_loop

    n = len(HARDWARE_STARTS)
    ticks = update_ticks(duration_s, params)
    total = 2 * n * ticks
    predictions = []
    for i, (x0, th0) in enumerate(HARDWARE_STARTS.values()):
        offset, what = 2 * i * ticks, f"reference run {i + 1} of {n}"

        def ran(done: int, _total: int, offset: int = offset, what: str = what) -> None:
            if progress is not None:
                progress(offset + done, total, f"{what}, the twin")

        def fitted(done: int, of: int, offset: int = offset + ticks, what: str = what) -> None:
            if progress is not None:
                progress(offset + ticks * done // max(1, of), total, f"{what}, its windows predicted")

        run = run_closed_loop(
            controller(),
            x0_m=x0,
            theta0_rad=th0,
            duration_s=duration_s,
            seed=seed + i,
            params=params,
            pacer=None if progress is None else TickProgress(ticks, ran),
        )
        predictions.append(
            windowed_prediction([rig_log(run.log, f"reference run {i}")], params, progress=fitted)
        )
    return Band.from_predictions(
        predictions,
        f"the twin at these parameters: {name} from the {n} chapter 6 hardware starts, "
        f"{duration_s:g} s each, noise seeds {seed}…{seed + n - 1}",
    )


def load_reference(paths: Sequence[str | Path]) -> list[RigLog]:
    """The logs of a band, each read and checked (before anything else is done: a refusal names the file)."""
    return [load_rig_log(path) for path in paths]


def view_monitor(controller: str = REFERENCE_CONTROLLER) -> Callable[[Parameters], Shadow]:
    """The live view's shadow (``twin.viewer.monitor.MonitorFactory``): a ``Shadow`` at the parameters it is
    given, against the band of the twin's own runs of ``controller`` at them; its ``progress`` keyword gets
    the fraction of the band built (the view shows it)."""

    def make(params: Parameters, progress: Callable[[float], None] | None = None) -> Shadow:
        """The shadow at ``params``; ``progress`` gets the fraction of its band built so far."""
        from controllers import registry
        from twin.interface import Controller

        def build() -> Controller:
            made = registry.make(controller, params)
            assert isinstance(made, Controller)
            return made

        def fraction(done: int, total: int, _stage: str) -> None:
            if progress is not None:
                progress(done / max(1, total))

        return Shadow(params, reference_band(params, build, name=controller, progress=fraction))

    return make


def logs_band(logs: Sequence[RigLog], params: Parameters, *, progress: Progress | None = None) -> Band:
    """The band of logs recorded on the rig when it was known good, predicted at ``params``. ``progress`` gets
    ``(done, total, stage)`` in the logs' ticks (a log's share advancing with its windows' fit)."""
    sizes = [len(log.time_s) for log in logs]
    total = sum(sizes)
    predictions = []
    for i, log in enumerate(logs):

        def fitted(
            done: int, of: int, offset: int = sum(sizes[:i]), size: int = sizes[i], log: RigLog = log
        ) -> None:
            if progress is not None:
                progress(offset + size * done // max(1, of), total, f"predicting the windows of {log.path}")

        predictions.append(windowed_prediction([log], params, progress=fitted))
    return Band.from_predictions(predictions, "the logs " + ", ".join(str(g.path) for g in logs))


@dataclass
class WatchResult:
    """What ``watch`` saw: sessions, windows scored and skipped, the alarms, why it ended."""

    sessions: int = 0
    windows: list[WindowScore] = field(default_factory=list)
    ended: str = ""
    wall_s: float = 0.0


def watch(
    observer: Observer,
    shadow: Shadow,
    *,
    sessions: int = 1,
    idle_timeout_s: float = 5.0,
    start_timeout_s: float | None = None,
    on_window: Callable[[WindowScore], None] | None = None,
    on_session: Callable[[int, str], None] | None = None,
    keep_windows: bool = False,
) -> WatchResult:
    """Follow ``observer``'s sessions into ``shadow`` until ``sessions`` have ended (0: until the rig is
    silent for ``idle_timeout_s`` after a session), the rig goes silent within a session, or Ctrl-C (the
    watch ends there, keeping what it saw). A session joined before its controller started waits for its
    first sample ``start_timeout_s`` (None: ``idle_timeout_s``): a served rig sends nothing until a
    controller says HELLO. ``on_window`` gets each window as it is processed, ``on_session`` each session's
    end (its number, the STOP in words)."""
    from twin.serving.server import STOP_NAMES

    result = WatchResult()
    started = time.perf_counter()
    commands: dict[int, float] = {}
    zero_v = observer.config.zero_command_v if observer.config else math.nan
    in_session = False
    # The rig time of the session's latest sample (NaN: none yet, its controller has not started).
    last_s = math.nan
    start_wait = idle_timeout_s if start_timeout_s is None else start_timeout_s

    def work_off(max_windows: int = MAX_BATCH_WINDOWS) -> None:
        for score in shadow.process(max_windows):
            if keep_windows:
                result.windows.append(score)
            if on_window is not None:
                on_window(score)

    try:
        while True:
            event = observer.next_event(0.0)
            if event is None:
                if shadow.pending():
                    work_off()
                    continue
                waiting = in_session and math.isnan(last_s)
                event = observer.next_event(start_wait if waiting else idle_timeout_s)
                if event is None:
                    result.ended = _silence(in_session, last_s, idle_timeout_s, start_wait)
                    break
            if isinstance(event, Joined):
                shadow.new_session()
                commands.clear()
                zero_v = event.config.zero_command_v
                in_session = True
                last_s = math.nan
            elif isinstance(event, p.Command):
                commands[event.seq] = event.dac_v
                if len(commands) > 2 * _COMMANDS_KEPT:
                    for seq in sorted(commands)[:-_COMMANDS_KEPT]:
                        del commands[seq]
            elif isinstance(event, p.Sample):
                last_s = event.time_s
                shadow.add(
                    event.seq,
                    event.time_s,
                    event.ball_v,
                    event.angle_v,
                    event.flags,
                    block_dac_v(event, commands, zero_v),
                )
                if shadow.pending() >= MAX_BATCH_WINDOWS:
                    work_off()
            elif isinstance(event, p.Stop):
                while shadow.pending():
                    work_off()
                in_session = False
                result.sessions += 1
                if on_session is not None:
                    on_session(result.sessions, STOP_NAMES.get(event.reason, str(event.reason)))
                if sessions and result.sessions >= sessions:
                    result.ended = f"{result.sessions} session(s) watched"
                    break
    except KeyboardInterrupt:
        result.ended = "stopped (Ctrl-C)"
    except RemoteError as exc:
        result.ended = str(exc)
    result.wall_s = time.perf_counter() - started
    return result


def _silence(in_session: bool, last_s: float, idle_s: float, start_s: float) -> str:
    """Why the watch ended on a silent rig: what was awaited, for how long, and what to do."""
    if not in_session:
        return "no further session"
    if math.isnan(last_s):
        return (
            f"the rig went silent: no controller started the session within {start_s:g} s of the shadow "
            "joining it (start the controller, e.g. `ballbeam run --rig URL`, while the shadow watches; "
            "--start-wait sets how long it waits)"
        )
    return (
        f"the rig went silent during a session: no frame for {idle_s:g} s (--idle) after its sample at "
        f"{last_s:.2f} s (the rig or its controller stopped without STOP)"
    )
