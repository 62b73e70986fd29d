"""The verdict of a closed-loop run: one typed object computed once from the true state.

Every figure comes from the plant's true state at the 50 Hz ticks (and the per-step peaks of each tick), never
from what a controller measured or estimated. The criteria are data (``Criteria``) with the reason for
each default; ``evaluate`` is the only place they are applied and ``settling_time_s`` is the one home of the
settling metric.

    ball_lost, ball_lost_time_s      the ball left the track (and when)
    steady_x_m, steady_theta_rad     means over the final window
    limit_cycle_x_pp_m, _theta_pp_rad  peak-to-peak over the final window
    settling_time_s                  last time |x − steady_x| exceeded max(2 % |x0|, 1 mm), measured from
                                     release; None when that happens inside the final window
    held                             ball kept and the final window within the offset and limit-cycle bands
    peak_motor_voltage_v, saturated_fraction (share of ticks at the ±12 V rails), peak_theta_rad, hit_stops

A lost ball has no steady state: the window fields and the settling time are None and ``held`` is False.

``evaluate_measured`` is the same verdict (through ``evaluate``) from what a rig records, for a rig that has no
true state (a recorded hardware log, a remote rig): the ball channel through eq 6.3.1, the angle channel through
eq 6.2.10, the motor volts from the DAC command through the output stage; what it cannot know it decides from
those signals (its docstring lists each field's source and limits).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from twin.log import RunLog
    from twin.parameters import Parameters

__all__ = [
    "Criteria",
    "MeasuredChannels",
    "at_rail",
    "Trace",
    "Verdict",
    "ball_step_bound_m",
    "evaluate",
    "evaluate_measured",
    "settling_time_s",
]


@dataclass(frozen=True)
class Criteria:
    """What ``held`` and the settling time mean (defaults and their reasons in docs/validate.md: "The verdict")."""

    # ≥ 4 periods of the slowest limit cycle seen on the twin (0.73 s) and ≤ a fifth of a 15 s run.
    window_s: float = 3.0
    # The ball sensor's converter alone puts the balance point 3–4.5 mm off centre (Table 6.3 read through
    # eq 6.3.1); a centimetre is what a person watching the rig still calls "in the middle".
    offset_band_m: float = 0.010
    # Ten encoder counts (one count = 3.5 mrad): far beyond quantization, far below a visible tilt.
    offset_band_rad: float = 0.035
    # A ball wandering less than a centimetre is balanced; the quantization limit cycle is 1–3 mm.
    limit_cycle_band_m: float = 0.010
    # Peak-to-peak beam motion of a balanced rig: the limit cycle moves the beam by a few counts.
    limit_cycle_band_rad: float = 0.035
    # Settling: the usual 2 % of the initial offset, but never below 1 mm (a third of the converter's offset).
    settling_fraction: float = 0.02
    settling_floor_m: float = 1e-3
    # The beam counts as on its stops within 1 mrad of them (MuJoCo's stop is a soft constraint).
    stop_tolerance_rad: float = 1e-3
    # Measured verdict only: a reading this close to the track's end counts as the ball at the end, lost. Eq 6.3.1
    # reads Table 6.3's end points 4.6 mm (−) and 2.3 mm (+) inside the 0.323 m end and the ±0.30 m points
    # 3–4 mm outside them: 10 mm trips within 9 mm of the end, never at 0.30 m.
    track_end_margin_m: float = 0.010

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"criterion {name} = {value!r} must be a finite number ≥ 0")


@dataclass(frozen=True)
class Verdict:
    held: bool
    reason: str
    ball_lost: bool
    ball_lost_time_s: float | None
    steady_x_m: float | None
    steady_theta_rad: float | None
    limit_cycle_x_pp_m: float | None
    limit_cycle_theta_pp_rad: float | None
    settling_time_s: float | None
    peak_motor_voltage_v: float
    saturated_fraction: float
    peak_theta_rad: float
    hit_stops: bool
    duration_s: float

    def to_json(self) -> dict[str, object]:
        """Plain JSON values rounded to their meaning: µm, µrad, ms, mV, 0.01 %."""
        digits = {
            "ball_lost_time_s": 3,
            "steady_x_m": 6,
            "steady_theta_rad": 6,
            "limit_cycle_x_pp_m": 6,
            "limit_cycle_theta_pp_rad": 6,
            "settling_time_s": 3,
            "peak_motor_voltage_v": 3,
            "saturated_fraction": 4,
            "peak_theta_rad": 6,
            "duration_s": 3,
        }
        out: dict[str, object] = {}
        for key, value in asdict(self).items():
            if key in digits and value is not None:
                value = round(float(value), digits[key])
            elif isinstance(value, (bool, np.bool_)):
                value = bool(value)
            out[key] = value
        return out


def settling_time_s(
    t_s: np.ndarray, x_m: np.ndarray, steady_x_m: float, x0_m: float, criteria: Criteria
) -> float | None:
    """The time after which |x − steady_x| stays within max(fraction·|x0|, floor): the time of the first
    sample after the last one outside. 0 if no sample is outside; None if the last one outside lies in
    the final window (the run did not settle in time to tell)."""
    band = max(criteria.settling_fraction * abs(x0_m), criteria.settling_floor_m)
    outside = np.flatnonzero(np.abs(np.asarray(x_m) - steady_x_m) > band)
    if not outside.size:
        return 0.0
    last = int(outside[-1])
    if last + 1 >= len(t_s) or t_s[last + 1] > t_s[-1] - criteria.window_s:
        return None
    return float(max(t_s[last + 1], 0.0))


@dataclass(frozen=True)
class Trace:
    """What a verdict reads of a run, one value per tick: the one record that every holder of a run's
    columns (the loop's recorder, the batch, the environments, a log judged from its volts) hands it.

    ``t_s`` from release (the rows before release are the held rig); ``x_m`` the ball about the point the run
    is judged about; ``peak_abs_theta_rad`` the largest |θ| over the physics steps of each tick while the
    ball was on the track; ``motor_volts_v`` the volts across the motor at each tick."""

    t_s: np.ndarray
    x_m: np.ndarray
    theta_rad: np.ndarray
    motor_volts_v: np.ndarray
    peak_abs_theta_rad: np.ndarray


def at_rail(motor_volts_v: np.ndarray, rail_v: float) -> np.ndarray:
    """Where the motor's volts are at the amplifier's rails (to the volts' rounding): the saturation's ticks."""
    return np.abs(motor_volts_v) >= rail_v - 1e-9


def evaluate(
    trace: Trace,
    *,
    x0_m: float,
    ball_lost_time_s: float | None,
    rail_v: float,
    stop_angle_rad: float,
    criteria: Criteria | None = None,
) -> Verdict:
    """The verdict from the ticks of one run (``Trace``)."""
    c = criteria or Criteria()
    t_s, x_m, theta_rad = trace.t_s, trace.x_m, trace.theta_rad
    motor_volts_v, peak_abs_theta_rad = trace.motor_volts_v, trace.peak_abs_theta_rad
    t = np.asarray(t_s, dtype=float)
    released = t >= 0.0
    volts = np.abs(np.asarray(motor_volts_v, dtype=float)[released])
    peak_v = float(volts.max()) if volts.size else 0.0
    saturated = float(np.mean(at_rail(volts, rail_v))) if volts.size else 0.0
    peak_theta = float(np.max(peak_abs_theta_rad)) if len(peak_abs_theta_rad) else 0.0
    common = dict(
        ball_lost=ball_lost_time_s is not None,
        ball_lost_time_s=ball_lost_time_s,
        peak_motor_voltage_v=peak_v,
        saturated_fraction=saturated,
        peak_theta_rad=peak_theta,
        hit_stops=peak_theta >= stop_angle_rad - c.stop_tolerance_rad,
        duration_s=float(t[-1]),
    )
    none = dict(
        steady_x_m=None,
        steady_theta_rad=None,
        limit_cycle_x_pp_m=None,
        limit_cycle_theta_pp_rad=None,
        settling_time_s=None,
    )
    if ball_lost_time_s is not None:
        return Verdict(held=False, reason=f"ball lost at {ball_lost_time_s:.3f} s", **none, **common)  # type: ignore[arg-type]
    if t[-1] < c.window_s:
        return Verdict(
            held=False,
            reason=f"the run ({t[-1]:.3f} s) is shorter than the final window ({c.window_s:g} s)",
            **none,  # type: ignore[arg-type]
            **common,  # type: ignore[arg-type]
        )
    x = np.asarray(x_m, dtype=float)
    th = np.asarray(theta_rad, dtype=float)
    window = t >= t[-1] - c.window_s
    steady_x, steady_th = float(np.mean(x[window])), float(np.mean(th[window]))
    pp_x, pp_th = float(np.ptp(x[window])), float(np.ptp(th[window]))
    failures = []
    if abs(steady_x) > c.offset_band_m:
        failures.append(f"offset {steady_x * 1e3:+.1f} mm beyond ±{c.offset_band_m * 1e3:g} mm")
    if abs(steady_th) > c.offset_band_rad:
        failures.append(f"beam offset {steady_th * 1e3:+.1f} mrad beyond ±{c.offset_band_rad * 1e3:g} mrad")
    if pp_x > c.limit_cycle_band_m:
        failures.append(f"ball limit cycle {pp_x * 1e3:.1f} mm p-p beyond {c.limit_cycle_band_m * 1e3:g} mm")
    if pp_th > c.limit_cycle_band_rad:
        failures.append(
            f"beam limit cycle {pp_th * 1e3:.1f} mrad p-p beyond {c.limit_cycle_band_rad * 1e3:g} mrad"
        )
    return Verdict(
        held=not failures,
        reason="; ".join(failures) if failures else "held",
        steady_x_m=steady_x,
        steady_theta_rad=steady_th,
        limit_cycle_x_pp_m=pp_x,
        limit_cycle_theta_pp_rad=pp_th,
        settling_time_s=settling_time_s(t[released], x[released], steady_x, x0_m, c),
        **common,  # type: ignore[arg-type]
    )


def ball_step_bound_m(params: Parameters) -> float:
    """The farthest a ball can move in one period: from rest at one end, the whole track downhill at the
    steepest beam (the stops) without rolling inertia or friction (a bound for any ball and contact)."""
    a = params.physics.gravity_m_s2 * math.sin(params.beam.stop_angle_rad)
    t = params.period_s
    v = math.sqrt(2.0 * a * 2.0 * params.track.half_length_m)
    return min(v * t + 0.5 * a * t * t, 2.0 * params.track.half_length_m)


# A rig of other parts whose ball sensor reads no position this long has lost the ball: several of the slowest
# sensor's periods (an HC-SR04's 60 ms cycle), so one wrong return held over the ticks it spans is not a loss.
NO_POSITION_LOST_S = 0.2


@dataclass(frozen=True)
class MeasuredChannels:
    """How a rig of other parts than the thesis's turns its log's channels into what a verdict reads, each
    through its part's software conversion (``twin.parts.measured_channels`` builds it): ``x_m`` the ball
    reading's position (NaN for a reading that carries none: an out-of-range code, a lost echo); ``theta_rad``
    the angle reading's angle, None for a rig that measures no angle; ``control`` the actuator's control for
    the board's command (a servo's target angle, a motor's volts) and ``control_limit`` its magnitude at the
    board's range ends (the "rails"); ``angle_step_rad`` one step of the angle reading (0 without one)."""

    x_m: Callable[[np.ndarray], np.ndarray]
    theta_rad: Callable[[np.ndarray], np.ndarray] | None
    control: Callable[[np.ndarray], np.ndarray]
    control_limit: float
    angle_step_rad: float


def _measured_loss(
    t: np.ndarray,
    ball_v: np.ndarray,
    x: np.ndarray,
    params: Parameters,
    c: Criteria,
    channels: MeasuredChannels | None = None,
) -> tuple[float | None, str]:
    """The time of the first released tick at which the signals say the ball is gone, and why."""
    from twin.daq import adc_lsb_v

    daq = params.daq
    lsb = adc_lsb_v(daq)
    end_m = params.track.half_length_m - c.track_end_margin_m
    step_m = ball_step_bound_m(params)
    n = len(t)
    for i in np.flatnonzero(t >= 0.0).tolist():
        if channels is None and (
            ball_v[i] <= daq.adc_min_v + 0.5 * lsb or ball_v[i] >= daq.adc_max_v - 1.5 * lsb
        ):
            return float(t[i]), f"the ball channel at the ADC's rail ({ball_v[i]:+.4f} V)"
        if channels is not None and not math.isfinite(x[i]):
            # no position read: a wrong return lasts one range (a VL53L0X's 33 ms, an HC-SR04's 60 ms cycle,
            # held over the ticks it spans); a ball gone reads none for good
            gap = np.flatnonzero(np.isfinite(x[i:]))
            last_s = float(t[i + int(gap[0]) - 1]) if gap.size else float(t[-1])
            if last_s - float(t[i]) >= NO_POSITION_LOST_S:
                return float(
                    t[i]
                ), f"the ball sensor read no ball ({ball_v[i]:g}) for {NO_POSITION_LOST_S:g} s"
            continue
        if abs(x[i]) >= end_m:
            return float(t[i]), f"the ball read at {x[i] * 1e3:+.1f} mm, at the track's end"
        # A jump no ball can make in one period that does not come back the next tick: the wiper lost the
        # ball (a contact dropout is one tick's glitch). A jump on the last tick has nothing after it.
        if i > 0 and abs(x[i] - x[i - 1]) > step_m and (i + 1 >= n or abs(x[i + 1] - x[i - 1]) > 2 * step_m):
            return float(t[i]), (
                f"the ball reading jumped {(x[i] - x[i - 1]) * 1e3:+.0f} mm in one tick "
                f"(a ball moves at most {step_m * 1e3:.0f} mm) and stayed: the sensor lost the ball"
            )
    return None, ""


def _without_glitches(x: np.ndarray, half: int = 1) -> np.ndarray:
    """The median of each reading and its ``half`` neighbours on each side (the ends kept): a contact dropout
    reads the open wiper for one tick, a spike of centimetres that no ball makes, which would pass for a limit
    cycle and restart the settling clock; a ball's motion over three ticks (40 ms) is nearly straight and
    passes. A sensor slower than the tick holds a wrong return over two ticks: ``half`` = 2 (five ticks, 80 ms,
    still nearly straight)."""
    width = 2 * half + 1
    if x.size < width:
        return x
    out = x.copy()
    out[half:-half] = np.median(np.stack([x[k : x.size - width + 1 + k] for k in range(width)]), axis=0)
    return out


def _filled(x: np.ndarray) -> np.ndarray:
    """``x`` with each NaN (a reading that carried no position) replaced by the last position read before it
    (the first read one for NaNs at the start): what the software would hold."""
    out = x.copy()
    finite = np.isfinite(out)
    if not finite.any():
        return out
    index = np.where(finite, np.arange(out.size), 0)
    np.maximum.accumulate(index, out=index)
    out = out[index]
    first = int(np.flatnonzero(finite)[0])
    out[:first] = x[first]
    return out


def evaluate_measured(
    log: RunLog,
    params: Parameters,
    *,
    x0_m: float | None = None,
    x_ref_m: float = 0.0,
    criteria: Criteria | None = None,
    channels: MeasuredChannels | None = None,
) -> Verdict:
    """The verdict of a run from the rig's recorded signals only (timem, datam1, datam2, aout of a ``RunLog``;
    its true state, the controller's estimates and ``u`` are not read), judged about ``x_ref_m`` with the
    bands of ``criteria`` and the software calibration ``params.software``: one call of ``evaluate``.

    Of ``params`` it reads the rig's description, not its physics: ``software`` (the conversions), ``daq``
    (the ADC's rails, the DAC, the period), ``amplifier``, ``start.free_run_s``, ``track.half_length_m``,
    ``beam.stop_angle_rad``, the encoder's count (``angle_sensor``, ``motor.gear_ratio``) and gravity. A
    remote rig's caller passes its parameters with what the rig's CONFIG announced put in
    (``Parameters.with_overrides``).

    Each field's source and its limits:

    * time: from release. The twin's ``timem`` is (its held start row before 0). A rig's clock starts
      anywhere: without a row before 0 the first tick is put at ``start.free_run_s``, as the twin's first
      command (the rig is released when Drive Motor is pressed, its first command follows at the next
      timer tick). Row 1 of a rig log, never written (timem, datam1, datam2, aout all 0), is dropped.
    * x: ``datam1`` (last sample of the block) through eq 6.3.1. Eq 6.3.1 is a line through Table 6.3's
      curve: it reads a ball at the centre 1.9 mm off and elsewhere up to 4.6 mm off; it carries the
      ADC's 2.4 mV steps (0.17 mm) and the contact noise, whose one-tick dropouts a median of three ticks
      removes (``_without_glitches``). ``x0_m`` defaults to the first row's reading.
    * θ: ``datam2`` (block mean) through eq 6.2.10: one encoder count (3.5 mrad) of quantization, and the
      zeroing error of the counter, which the rig cannot see.
    * ball lost: no wiper reports that it lost the ball (an open wiper reads its resting volts, near the
      centre). The first released tick at which the ball channel sits at an ADC rail, or x reads within
      ``criteria.track_end_margin_m`` of the track's end, or the reading jumps farther than a ball can move
      in one period (``ball_step_bound_m``) and does not come back the next tick. Its time is the tick's,
      at most a period or two before or after the true one; a ball that leaves the track slowly without
      reading at its end would be missed.
    * motor volts: ``aout`` through the DAC and the amplifier (twin.output_stage.motor_volts): the volts the
      output stage gives, not measured ones (an amplifier fault is invisible).
    * peak θ, hit stops: the largest |θ| of the block means; the stops count within one count more than
      ``stop_tolerance_rad`` (a block mean on the stops reads up to a count inside). A touch shorter than a
      block is averaged away.
    """
    from twin.converters import ball_position_m, beam_angle_rad
    from twin.output_stage import motor_volts
    from twin.sensors import angle_count_step_rad

    c = criteria or Criteria()
    t, ball_v, angle_v, aout = log.timem, log.datam1, log.datam2, log.aout
    if t.size > 1 and t[0] == 0.0 and ball_v[0] == 0.0 and angle_v[0] == 0.0 and aout[0] == 0.0:
        t, ball_v, angle_v, aout = t[1:], ball_v[1:], angle_v[1:], aout[1:]
    if not np.any(t < 0.0):  # no held row: the rig's clock, whose first tick is the first command's
        t = t - t[0] + params.start.free_run_s
    sw = params.software
    if channels is None:
        x = np.asarray(ball_position_m(ball_v, sw), dtype=float)
        theta = np.asarray(beam_angle_rad(angle_v, sw), dtype=float)
        volts = np.asarray(motor_volts(aout, params), dtype=float)
        rail, count_rad = params.amplifier.rail_v, angle_count_step_rad(params)
    else:  # a rig of other parts: its parts' conversions; no angle sensor, no angle (peak 0, stops unseen)
        x = np.asarray(channels.x_m(ball_v), dtype=float)
        theta = (
            np.zeros_like(x) if channels.theta_rad is None else np.asarray(channels.theta_rad(angle_v), float)
        )
        volts = np.asarray(channels.control(aout), dtype=float)
        rail, count_rad = channels.control_limit, channels.angle_step_rad
    lost_s, why = _measured_loss(t, ball_v, x, params, c, channels)
    x = _without_glitches(_filled(x), 1 if channels is None else 2)
    released = t >= 0.0
    kept = released if lost_s is None else released & (t < lost_s)
    peak = np.abs(theta[kept])
    verdict = evaluate(
        Trace(t, x - x_ref_m, theta, volts, peak),
        x0_m=(float(x[0]) if x0_m is None else x0_m) - x_ref_m,
        ball_lost_time_s=lost_s,
        rail_v=rail,
        stop_angle_rad=params.beam.stop_angle_rad - count_rad,
        criteria=c,
    )
    if lost_s is not None:
        return replace(verdict, reason=f"{verdict.reason} ({why})")
    return verdict
