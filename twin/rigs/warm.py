"""Warm-up before a clock starts: whatever a tick of a simulated rig imports, compiles or builds on first use is
done here, once, so that no tick of a served session, a served rig or the live view pays for it.

A tick of a simulated rig runs the plant, the angle chain and the ball chain; the ball chain's rare paths
(a dropout of the wiper's contact, a table point or a track end crossed, the ball off the track) are the ones
a session reaches only seconds in. ``warm`` takes each of them once on a throwaway rig of the same kind,
built from the same parameters, with a dropout rate high enough to meet several dropouts. Nothing here
changes a later run: the throwaway rig has its own seed and is dropped.

The single-run path imports no numba at all (``twin.sensors.dropout_effects_v`` runs the Python form of its
function for a chain alone): numba and its compilation belong to the batch engines, which have no clock.
``tests/test_no_tick_imports.py`` holds both: after ``warm``, ticks over a ball crossing table points and
meeting dropouts import no module and compile nothing."""

from __future__ import annotations

import bisect

from twin.parameters import Parameters
from twin.rigs.backends import DEFAULT_PLANT
from twin.rigs.sim import SimRig, make_rig

__all__ = ["warm"]

WARM_TICKS = 40  # 0.8 s at the thesis's 20 ms: the ball still for 10 ticks, then flicked off the track
_FLICK_M_S = 0.5  # the live view's fastest flick
_DROPOUTS = {"ball_sensor.noise_enabled": True, "ball_sensor.dropout_rate_hz": 200.0}

_warmed: set[tuple[str, bool]] = set()


def warm(
    params: Parameters | None = None, *, plant: str = DEFAULT_PLANT, ideal_sensors: bool = False
) -> None:
    """Take every path a tick of ``make_rig(params, plant=plant, ideal_sensors=ideal_sensors)`` may take, once
    per process and rig kind (a few tens of ms of CPU the first time, nothing after): call it before a session,
    the view or a served rig starts its clock."""
    key = (plant, ideal_sensors)
    if key in _warmed:
        return
    base = params if params is not None else Parameters()
    try:
        _throwaway_run(make_rig(base.with_overrides(_DROPOUTS), plant=plant, ideal_sensors=ideal_sensors))
    except Exception:  # noqa: BLE001 - best effort: a rig that cannot run fails its own session, with its message
        return
    _warmed.add(key)


def _throwaway_run(rig: SimRig) -> None:
    """The ball still on one piece of the wiper curve (dropouts there), then flicked over the table's points
    and off the track's end, the board writing its actuator's rest command (the DAC's zero on the thesis's rig)."""
    half = rig.params.track.half_length_m
    curve = rig.params.ball_sensor.curve_position_m
    x0 = 0.5 * half
    piece = bisect.bisect(curve, x0)
    if 0 < piece < len(curve) and abs(curve[piece]) < half:
        x0 = 0.5 * (curve[piece - 1] + curve[piece])  # between two table points
    rig.reset(x0, 0.0)
    rig.read()  # the held block
    zero_v = rig.parts.actuator.rest_command(rig.params)
    for tick in range(WARM_TICKS):
        if tick == WARM_TICKS // 4:
            rig.kick_ball(_FLICK_M_S)
        rig.write(zero_v)
        rig.read()
        if rig.ball_lost:
            break
