"""Sessions of a controller on a rig served over protocol 1 (``ballbeam run --rig``): connect, run, judge.

A rig layer module: it knows no controller catalogue. The caller hands in ``make_controller``, which builds
a fresh controller from a session's parameters (the rig's period, DAC and software calibration), and
``on_run``, which keeps or prints a session's run. The rig's initial state, duration and noise are the
server's; a run is judged from the measured signals (a rig has no true state).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from twin.engine import RunResult
    from twin.parameters import Parameters
    from twin.rigs.remote import RemoteRig

# A session's controller from the rig's parameters: a twin.interface.Controller, or anything else (a law on
# the true state) that the session then refuses.
MakeController = Callable[["Parameters"], object]
# A session that ran to its end: (its 1-based number, the run, the summary).
OnRun = Callable[[int, "RunResult", dict[str, Any]], None]


@dataclass(frozen=True)
class Waits:
    """A client's waits once connected (``RemoteRig``): the longest silence, or repeat of an answered
    sample, before the server counts as gone (``--wait-sample``); how long a held session may wait to start
    (``--wait-start``; ``None``: as long as the server holds it, repeating the held sample)."""

    sample_s: float = 5.0
    start_s: float | None = None


def connect(
    url: str,
    client: str,
    wait_s: float,
    *,
    retry_refused: bool,
    adc_range_v: tuple[float, float] | None = None,
    waits: Waits | None = None,
) -> RemoteRig:
    """``open_remote`` within ``wait_s``; ``retry_refused``: a refusal (the rig is still another session's,
    e.g. a dead client's waiting out its timeout) is asked again until then. ``adc_range_v``: the card's
    analog input range that the samples' volts are checked against (``RemoteRig``); ``waits``: its waits
    for a sample and for the session's start."""
    waits = waits or Waits()
    import time

    from twin.rigs.remote import Refused, open_remote

    deadline = time.monotonic() + wait_s
    while True:
        try:
            return open_remote(
                url,
                client=client,
                connect_timeout_s=max(deadline - time.monotonic(), 0.2),
                adc_range_v=adc_range_v,
                timeout_s=waits.sample_s,
                start_wait_s=waits.start_s,
                wait_names=("--wait-sample", "--wait-start"),
            )
        except Refused:
            if not retry_refused or time.monotonic() >= deadline:
                raise
            time.sleep(0.2)


def run_on_remote_rig(
    url: str,
    params: Parameters,
    make_controller: MakeController,
    *,
    name: str,
    sessions: int,
    wait_s: float,
    on_run: OnRun,
    waits: Waits | None = None,
) -> int:
    """The controller named ``name`` (built by ``make_controller``) on the rig at ``url``: ``sessions``
    sessions one after the other (0: until the server stops answering HELLO within ``wait_s``), a fresh
    controller each, built from that session's CONFIG (a served job's runs, ``sweep --serve``). Returns the
    exit code: 0 every session held to its last sample, 1 not (or no rig), 2 a controller that cannot drive
    a rig."""
    from twin.engine import ENDED_LAST_SAMPLE
    from twin.rigs.remote import RemoteError

    many = sessions != 1
    done, ok = 0, True
    while sessions == 0 or done < sessions:
        try:
            adc = (
                params.daq.adc_min_v,
                params.daq.adc_max_v,
            )  # not in CONFIG: the card's as the client knows it
            rig = connect(
                url, f"ballbeam run {name}"[:32], wait_s, retry_refused=many, adc_range_v=adc, waits=waits
            )
        except RemoteError as exc:
            if sessions == 0 and done:  # the server has no further session: the job is over
                break
            print(f"ballbeam run: {exc}", file=sys.stderr)
            return 1
        done += 1
        with rig:
            session = remote_session(rig, params, make_controller, name=name, url=url, many=many)
        if session is None:
            return 2  # a law on the true state (reported): refused at the first session
        held, run, summary = session
        if run is None:  # the controller failed (reported, STOP sent): the server records that run failed
            if not many:
                return 1
            ok = False
            continue
        ok = ok and held and run.ended == ENDED_LAST_SAMPLE
        on_run(done, run, summary)
    return 0 if ok else 1


def remote_session(
    rig: RemoteRig,
    params: Parameters,
    make_controller: MakeController,
    *,
    name: str,
    url: str,
    many: bool,
) -> tuple[bool, RunResult | None, dict[str, Any]] | None:
    """One session of ``run --rig`` on the open ``rig``: (held, the run or None if the controller failed,
    the summary); None when the controller cannot drive a rig (reported)."""
    from twin.engine import ENDED_BALL_LOST, ENDED_LAST_SAMPLE, ControllerError, run_on_rig
    from twin.interface import Controller
    from twin.rigs.remote import RemoteError
    from twin.wire.protocol import STOP_BALL_LOST, printable

    rig_params = rig.parameters(params)  # the rig's period, DAC and software calibration
    controller = make_controller(rig_params)
    if not isinstance(controller, Controller):
        rig.stop()
        print(
            f"ballbeam run: {name} is a law on the true state (simulation only): it cannot drive a rig",
            file=sys.stderr,
        )
        return None
    try:
        run = run_on_rig(controller, rig, params=rig_params)  # the one loop, to the rig's last sample
    except ControllerError as exc:
        rig.stop()
        print(f"ballbeam run: the controller failed: {exc}", file=sys.stderr)
        return False, None, {}
    if run.ended not in (ENDED_LAST_SAMPLE, ENDED_BALL_LOST):
        # The rig's fault (a bad SAMPLE, silence): said where the user looks, not only in the summary.
        print(f"ballbeam run: the rig ended the run: {run.ended}", file=sys.stderr)
    if run.ended == ENDED_BALL_LOST:
        # The rig reported the ball lost without ending the session (a rig that stops on a lost ball flags that
        # sample last): its sample is answered; the session ends here, and the rig is told so.
        rig.stop(STOP_BALL_LOST)
    if many and run.ended in (ENDED_LAST_SAMPLE, ENDED_BALL_LOST):
        # Wait for the server's STOP (answering a repeated last sample): the next HELLO then reaches the next
        # session, not this one, which would refuse a second controller.
        try:
            while True:
                rig.read()
        except RemoteError:
            pass
    # A rig has no true state: the run is judged from what it measured, as a recorded log is.
    verdict = run.verdict
    summary = {
        "controller": name,
        "rig": url,
        "rig_identity": printable(rig.config.rig),  # the rig's own words: escaped, a terminal is not its
        "ticks": int(run.log.timem.size),
        "ended": run.ended,
        "rig_ball_lost": rig.ball_lost,  # the rig's own flag; "ball_lost" below is the measured verdict's
        "sequence_gaps": rig.sequence_gaps,  # seq numbers that never arrived (blocks lost on the way)
        "verdict_source": "measured (the rig's volts through its calibration: ballbeam judge)",
        **verdict.to_json(),
        **({} if run.timing is None else {"realtime": run.timing.to_json()}),
    }
    return verdict.held, run, summary
