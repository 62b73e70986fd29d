"""The rig's two measurement chains in pure numpy: beam angle (§6.2) and ball position (§6.3).

Beam angle (no randomness)::

    θ → encoder on the motor shaft, 256 pulses/rev, gearbox 1:7: one count = 2π/(256·7) rad at the beam
      → 10-bit up/down counter, set to 512 by the zero switch at the beam angle θ_zero (§6.6, Fig 7.20)
      → AD561 DAC: Va = 0.009818·DI − 5.042 V (eq 6.2.6)
      → ADC (12 bit, ±5 V), 800 samples per 20 ms block; the software uses the block MEAN (appendix A)

  Counting convention: DI = 512 + floor((θ − θ_zero)/Δ + 0.5), i.e. the count changes half a count either
  side of the zeroing angle. The counter is three 4-bit 74LS193 of which the DAC sees the low 10 bits
  (§6.2), so outside 0…1023 the value wraps modulo 1024 (at the ±43.4° stops the count stays within
  512 ± 216 unless the zeroing error exceeds ≈ 59°). Unmodelled: the direction-dependent switching point of
  a real up/down pulse decoder (hysteresis below one count) and gearbox backlash.

Ball position (seeded randomness)::

    x → wiper on the resistance wire, measured static curve Table 6.3 (interpolated piecewise linearly)
      → contact noise: dropouts start as a Poisson process (rate λ), last Exp(mean μ); during a dropout,
        or when the ball is off the track, the wiper is at ``dropout_voltage_v``
      → RC low-pass 147 Ω / 22 µF (τ = 3.234 ms), integrated exactly
      → ADC; the software uses the LAST sample of the block (appendix A)

  Static curve beyond the table's ends (only reachable if ``track.half_length_m`` is set above 0.323 m):
  clamped to the end values, because the table's end points are the wire's ends, where the ball is in the
  last place it can touch the wire; beyond ``track.half_length_m`` the ball has no contact at all.
"""

from __future__ import annotations

import bisect
import functools
import math
import operator
from collections.abc import Sequence
from typing import Any, overload

import numpy as np

from twin import fixedorder as fo
from twin.converters import angle_volts_v, ball_volts_v, finite_values
from twin.daq import adc_quantize_v, adc_quantizer
from twin.jit import njit_cached
from twin.parameters import AngleSensor, BallSensor, Daq, Parameters
from twin.physics import PhysicsBlock

__all__ = [
    "CONTINUITY_TOLERANCE_SAMPLES",
    "SNAP_TOLERANCE_SAMPLES",
    "AngleChain",
    "BallChainBatch",
    "BallPositionChain",
    "IdealSensors",
    "angle_block_mean_bruteforce_v",
    "angle_block_mean_v",
    "angle_block_means_v",
    "angle_counter_mean",
    "angle_count_step_rad",
    "angle_sensor_v",
    "counter_dac_v",
    "counter_value",
    "rc_end_v",
    "wiper_static_v",
    "wiper_v",
]

# Finished dropouts kept in the history (a long live session would otherwise grow it without bound).
DROPOUT_HISTORY = 1000
# A knot time within this many sample periods (25 ps at 40 kHz) of a sample instant is that instant: knot
# times like k·1 ms accumulate rounding, and θ is continuous there, so the choice only removes float noise.
SNAP_TOLERANCE_SAMPLES = 1e-6
# A block must start where the previous one ended, within this fraction of a sample period (0.25 µs): the
# caller's clock (MuJoCo's time += timestep) accumulates float rounding over long runs.
CONTINUITY_TOLERANCE_SAMPLES = 0.01
# Above this many count changes within one block (a beam faster than ≈ 16 rad/s) the 800-sample evaluation
# is cheaper than per-crossing bookkeeping (measured crossover ≈ 90 crossings, ~80 µs); both are exact.
_MAX_CROSSINGS_FAST = 90


_HALF_0D = np.array(0.5)
# A rig block whose |x| stays below this fraction of the track's half length is on the track at every point
# interpolated between its knots (clear of the ends by more than interpolation's rounding).
_CLEAR_OF_ENDS = 1.0 - 1e-9


# --- beam angle ------------------------------------------------------------------------------------------
def angle_count_step_rad(params: Parameters) -> float:
    """One counter count at the beam: 2π/(256·7) = 3.506e-3 rad = 0.2009° (eq 6.2.1)."""
    return 2.0 * math.pi / (params.angle_sensor.encoder_pulses_per_rev * params.motor.gear_ratio)


def _counts_unwrapped(theta: np.ndarray, params: Parameters) -> np.ndarray:
    s = params.angle_sensor
    return s.counter_zero_count + np.floor((theta - s.zeroing_error_rad) / angle_count_step_rad(params) + 0.5)


def _counter_modulus(params: Parameters) -> int:
    return 2 ** int(params.angle_sensor.counter_bits)


def counter_value(theta_rad: float | np.ndarray, params: Parameters) -> int | np.ndarray:
    """The 10-bit counter's value DI for beam angle(s): 512 + floor((θ − θ_zero)/Δ + 0.5), modulo 1024."""
    theta = finite_values(theta_rad, "theta_rad")
    di = np.mod(_counts_unwrapped(theta, params), _counter_modulus(params)).astype(np.int64)
    return int(di) if np.ndim(theta_rad) == 0 else di


def counter_dac_v(di: int | np.ndarray, params: Parameters) -> float | np.ndarray:
    """AD561 output for counter value(s) DI: Va = 0.009818·DI − 5.042 V (eq 6.2.6)."""
    d = finite_values(di, "di")
    if np.any(d != np.floor(d)) or np.any(d < 0) or np.any(d >= _counter_modulus(params)):
        raise ValueError(
            f"di = {di!r} is impossible: counter values are integers 0…{_counter_modulus(params) - 1}"
        )
    s = params.angle_sensor
    out = s.dac_volts_per_count * d + s.dac_offset_v
    return float(out) if np.ndim(di) == 0 else out


def angle_sensor_v(theta_rad: float | np.ndarray, params: Parameters) -> float | np.ndarray:
    """The angle circuit's analog output (before the ADC) for beam angle(s)."""
    theta = finite_values(theta_rad, "theta_rad")
    out = counter_dac_v(np.asarray(counter_value(theta, params)), params)
    return float(out) if np.ndim(theta_rad) == 0 else out


def _level_v(counts_unwrapped: np.ndarray, params: Parameters) -> np.ndarray:
    """What the ADC reads for unwrapped counter values: wrap, DAC, quantize."""
    s = params.angle_sensor
    di = np.mod(counts_unwrapped, _counter_modulus(params))
    return np.asarray(adc_quantize_v(s.dac_volts_per_count * di + s.dac_offset_v, params.daq))


def _check_trajectory(
    times_s: np.ndarray, values: np.ndarray, value_name: str
) -> tuple[np.ndarray, np.ndarray]:
    t = finite_values(times_s, "times_s")
    v = finite_values(values, value_name)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"times_s has shape {t.shape}: it must be 1-D with at least 2 times")
    if v.shape != t.shape:
        raise ValueError(f"{value_name} has shape {v.shape}: it must match times_s {t.shape}")
    increasing = t[1:] > t[:-1]
    if not increasing.all():
        j = int(np.argmin(increasing))
        raise ValueError(
            f"times_s must increase strictly: times_s[{j + 1}] = {t[j + 1]!r} ≤ times_s[{j}] = {t[j]!r}"
        )
    return t, v


def _snapped_positions(t: np.ndarray, daq: Daq) -> list[float]:
    """Knot times in sample periods from the block start, snapped to sample instants within tolerance."""
    t0, fs = float(t[0]), daq.sample_rate_hz
    positions = []
    for tk in t.tolist():
        sk = (tk - t0) * fs
        nearest = round(sk)
        positions.append(float(nearest) if abs(sk - nearest) < SNAP_TOLERANCE_SAMPLES else sk)
    return positions


_POSITIONS: dict[tuple[bytes, float], list[float]] = {}


def _snapped_positions_cached(t: np.ndarray, daq: Daq) -> list[float]:
    """``_snapped_positions``, remembered by the knots' offsets from the first (a function of those alone:
    the rig's blocks repeat a few offset patterns, the clock's rounding)."""
    key = ((t - t[0]).tobytes(), daq.sample_rate_hz)
    positions = _POSITIONS.get(key)
    if positions is None:
        if len(_POSITIONS) > 256:
            _POSITIONS.clear()
        positions = _POSITIONS[key] = _snapped_positions(t, daq)
    return positions


def _sample_positions(t: np.ndarray, daq: Daq) -> list[float]:
    """``_snapped_positions``, checked to cover the whole block."""
    positions = _snapped_positions(t, daq)
    t0, fs = float(t[0]), daq.sample_rate_hz
    if positions[-1] < daq.block_size:
        raise ValueError(
            f"times_s ends at {t[-1]!r} s, before the block's last sample at "
            f"{t0 + daq.block_size / fs!r} s: it must cover the whole block"
        )
    return positions


@functools.lru_cache(maxsize=16)
def _level_table(sensor: AngleSensor, daq: Daq) -> tuple[float, ...]:
    """ADC reading for every counter value 0…1023 (the DAC output is constant between count changes)."""
    di = np.arange(2 ** int(sensor.counter_bits), dtype=np.float64)
    return tuple(
        np.asarray(adc_quantize_v(sensor.dac_volts_per_count * di + sensor.dac_offset_v, daq)).tolist()
    )


def angle_counter_mean(angle_v: float | np.ndarray, params: Parameters) -> float | np.ndarray:
    """The mean counter value DI over a block, from the angle channel's block-mean volts.

    The channel reads one ADC level per counter value (the AD561's line, then the ADC's 12 bits), so a block
    mean between two adjacent levels is the same mix of the two counts: interpolating the level table
    inverts it exactly while the beam stays within two counts in a block, and closely beyond. Unlike the
    software's eq 6.2.10, this does not carry the ADC's rounding of each level (up to ±0.44 mrad)."""
    levels = np.asarray(_level_table(params.angle_sensor, params.daq))
    v = finite_values(angle_v, "angle_v")
    out = np.interp(v, levels, np.arange(levels.size, dtype=np.float64))
    return float(out) if np.ndim(angle_v) == 0 else out


def angle_block_mean_bruteforce_v(times_s: np.ndarray, theta_rad: np.ndarray, params: Parameters) -> float:
    """Reference: the block mean computed sample by sample at 40 kHz.

    θ is interpolated linearly between ``times_s`` at the 800 sample times t0 + (i + 1)/f_s (t0 = times_s[0]);
    each sample is counted, converted by the DAC, quantized by the ADC, then averaged (appendix A)."""
    t, theta = _check_trajectory(times_s, theta_rad, "theta_rad")
    _sample_positions(t, params.daq)  # coverage check
    daq = params.daq
    sample_t = t[0] + np.arange(1, daq.block_size + 1) / daq.sample_rate_hz
    return float(np.mean(_level_v(_counts_unwrapped(np.interp(sample_t, t, theta), params), params)))


def angle_block_mean_v(times_s: np.ndarray, theta_rad: np.ndarray, params: Parameters) -> float:
    """The angle channel as the software reads it: the mean of the block's 800 ADC samples (appendix A).

    ``times_s`` starts at the block start t0 and reaches at least the block's last sample t0 + 800/f_s;
    θ is linear between the given times (the physics steps). Exact, without per-sample work: when the
    count is the same at every knot (a still or slow beam, the common case) the mean is that level;
    otherwise the samples of each level are counted from the times θ crosses each count boundary (the
    800-sample evaluation is kept for beams crossing more than ``_MAX_CROSSINGS_FAST`` counts per block).
    Equal to ``angle_block_mean_bruteforce_v`` up to float rounding: a sample within ~1e-13 counts of a
    boundary could fall on the other side."""
    t, theta = _check_trajectory(times_s, theta_rad, "theta_rad")
    sensor = params.angle_sensor
    u = ((theta - sensor.zeroing_error_rad) / angle_count_step_rad(params) + 0.5).tolist()
    return _block_mean(_sample_positions(t, params.daq), u, _level_table(sensor, params.daq), params)


def angle_block_means_v(
    times_s: np.ndarray,
    theta_rad: np.ndarray,
    params: Parameters,
    zeroing_error_rad: np.ndarray | None = None,
) -> np.ndarray:
    """``angle_block_mean_v`` for a batch of runs in step: the times shared (K,), θ one row per run (B, K);
    ``zeroing_error_rad``: each run's (B,) in place of ``params``'.

    A row whose count is the same at every knot reads that level (numpy over the batch); the others go
    through ``_block_mean`` one by one, exactly as a run alone does."""
    t = finite_values(times_s, "times_s")
    theta = finite_values(theta_rad, "theta_rad")
    _check_trajectory(t, theta[0] if len(theta) else t, "theta_rad")
    sensor = params.angle_sensor
    levels = _level_table(sensor, params.daq)
    zero_rad = sensor.zeroing_error_rad if zeroing_error_rad is None else zeroing_error_rad[:, None]
    u = (theta - zero_rad) / angle_count_step_rad(params) + 0.5
    c = np.floor(u)
    still = c.min(axis=1) == c.max(axis=1)
    out = np.empty(len(theta))
    zero = int(sensor.counter_zero_count)
    out[still] = np.asarray(levels)[(zero + c[still, 0].astype(np.int64)) % len(levels)]
    moving = np.flatnonzero(~still)
    if moving.size:
        s = _sample_positions(t, params.daq)
        crossings = np.abs(np.diff(c[moving], axis=1)).sum(axis=1)
        fast = crossings <= _MAX_CROSSINGS_FAST
        if fast.any():
            rows = moving[fast]
            out[rows] = _block_means_crossing(
                s, u[rows], c[rows], np.asarray(levels), zero, params.daq.block_size
            )
        for i in moving[~fast].tolist():
            out[i] = _block_mean(s, u[i].tolist(), levels, params)
    return out


def _block_means_crossing(
    s: list[float], u: np.ndarray, c: np.ndarray, levels: np.ndarray, zero: int, n: int
) -> np.ndarray:
    """``_block_mean``'s count-crossing sum for each row of ``u`` (c = floor(u)), compiled (numba, on first
    use): the same terms added in the same order (interval by interval, each interval's level and then its
    crossings one by one), so each row's sum has the bits of ``_block_mean`` on that row alone."""
    return _compiled_crossing()(
        np.asarray(s, dtype=float), np.ascontiguousarray(u), np.ascontiguousarray(c), levels, zero, n
    )


def _crossing_sums(
    s: np.ndarray, u: np.ndarray, c: np.ndarray, levels: np.ndarray, zero: int, n: int
) -> np.ndarray:
    modulus = len(levels)
    out = np.empty(u.shape[0])
    for r in range(u.shape[0]):
        total = 0.0
        for j in range(len(s) - 1):
            first = math.floor(s[j]) + 1
            last = min(math.floor(s[j + 1]), n)
            if last < first:
                continue
            c0, c1 = c[r, j], c[r, j + 1]
            total = total + (last - first + 1) * levels[(zero + int(c0)) % modulus]
            if c1 == c0:
                continue
            # u is linear on the interval; it reaches boundary m at s* = s_j + (m − u_j)/(u_j+1 − u_j)·(s_j+1 − s_j).
            uj = u[r, j]
            ds_du = (s[j + 1] - s[j]) / (u[r, j + 1] - uj)
            rising = c1 > c0
            for i in range(int(abs(c1 - c0))):
                # rising: the count is ≥ m at samples s ≥ s*; falling: the count is < m at samples s > s*
                m = c0 + 1 + i if rising else c0 - i
                at = s[j] + (m - uj) * ds_du
                start = max(first, math.ceil(at) if rising else math.floor(at) + 1)
                upper = levels[(zero + int(m)) % modulus]
                lower = levels[(zero + int(m) - 1) % modulus]
                if start <= last:
                    total = total + (last - start + 1) * (upper - lower if rising else lower - upper)
        out[r] = total / n
    return out


@functools.cache
def _compiled_crossing() -> Any:
    return njit_cached(_crossing_sums)


@functools.lru_cache(maxsize=64)
def _interval_samples(s: tuple[float, ...], n: int) -> tuple[tuple[int, int, int, int], ...]:
    """(j, first, last, count) for each knot interval (s_j, s_j+1] holding samples first … last (count of
    them) of the block's n (the rig's blocks share a few knot patterns: computed once per pattern)."""
    out = []
    for j in range(len(s) - 1):
        first, last = math.floor(s[j]) + 1, min(math.floor(s[j + 1]), n)
        if last >= first:
            out.append((j, first, last, last - first + 1))
    return tuple(out)


def _block_mean(s: list[float], u: list[float], levels: tuple[float, ...], params: Parameters) -> float:
    """Block mean from knot positions ``s`` (sample periods) and ``u`` = (θ − θ_zero)/Δ + 0.5 at the knots.

    Sample i (i = 1…800) in the knot interval (s_j, s_j+1] reads levels[(512 + floor(u(i))) mod 1024]."""
    zero = int(params.angle_sensor.counter_zero_count)
    modulus = len(levels)
    n = params.daq.block_size
    c = [math.floor(v) for v in u]
    if min(c) == max(c):
        return levels[(zero + c[0]) % modulus]
    if sum(map(abs, map(operator.sub, c[1:], c[:-1]))) > _MAX_CROSSINGS_FAST:
        return _block_mean_samplewise(s, u, levels, zero, n)
    total = 0.0
    for j, first, last, count in _interval_samples(tuple(s), n):
        c0, c1 = c[j], c[j + 1]
        total += count * levels[(zero + c0) % modulus]
        if c1 == c0:
            continue
        # u is linear on the interval; it reaches boundary m at s* = s_j + (m − u_j)/(u_j+1 − u_j)·(s_j+1 − s_j).
        ds_du = (s[j + 1] - s[j]) / (u[j + 1] - u[j])
        if c1 > c0:  # rising: the count is ≥ m at samples s ≥ s*
            for m in range(c0 + 1, c1 + 1):
                start = max(first, math.ceil(s[j] + (m - u[j]) * ds_du))
                if start <= last:
                    total += (last - start + 1) * (
                        levels[(zero + m) % modulus] - levels[(zero + m - 1) % modulus]
                    )
        else:  # falling: the count is < m at samples s > s*
            for m in range(c0, c1, -1):
                start = max(first, math.floor(s[j] + (m - u[j]) * ds_du) + 1)
                if start <= last:
                    total += (last - start + 1) * (
                        levels[(zero + m - 1) % modulus] - levels[(zero + m) % modulus]
                    )
    return total / n


def _block_mean_samplewise(
    s: list[float], u: list[float], levels: tuple[float, ...], zero: int, n: int
) -> float:
    """The 800-sample evaluation in sample units (fallback for very fast beams)."""
    u_samples = np.interp(np.arange(1, n + 1, dtype=np.float64), s, u)
    di = (zero + np.floor(u_samples).astype(np.int64)) % len(levels)
    return float(np.mean(np.asarray(levels)[di]))


class AngleChain:
    """The beam-angle chain as one object (no randomness, no state besides the last reading)."""

    def __init__(self, params: Parameters) -> None:
        self.params = params
        self.step_rad = angle_count_step_rad(params)
        self.last_reading_v: float | None = None
        self._levels = _level_table(params.angle_sensor, params.daq)
        self._zero_step_0d = (np.array(params.angle_sensor.zeroing_error_rad), np.array(self.step_rad))
        self._zero_count = int(params.angle_sensor.counter_zero_count)
        self._analog: list[float] = np.asarray(
            counter_dac_v(np.arange(_counter_modulus(params)), params)
        ).tolist()

    def counter_value(self, theta_rad: float | np.ndarray) -> int | np.ndarray:
        return counter_value(theta_rad, self.params)

    def level_v(self, theta_rad: float) -> float:
        """The circuit's analog output at one beam angle, before any ADC: ``angle_sensor_v`` of a Python float
        (a microcontroller's pin sees it every physics step), from a table of the AD561's levels."""
        s = self.params.angle_sensor
        count = math.floor((theta_rad - s.zeroing_error_rad) / self.step_rad + 0.5)
        return self._analog[(self._zero_count + count) % len(self._analog)]

    def read_v(self, times_s: np.ndarray, theta_rad: np.ndarray) -> float:
        """The block-mean ADC volts for one block (see ``angle_block_mean_v``)."""
        self.last_reading_v = angle_block_mean_v(times_s, theta_rad, self.params)
        return self.last_reading_v

    def read_block_v(self, block: PhysicsBlock) -> float:
        """``read_v`` for a block the rig built (finite, increasing times covering the block): a block whose
        count is the same at both extremes of θ (a still or slow beam, most blocks) reads that level, as
        ``_block_mean`` does from every knot (u is monotonic in θ in float arithmetic and floor is
        monotonic: the same level, the same bits), without the per-knot Python; any other block goes through
        ``read_v``."""
        lo, hi = block.theta_range_rad or (float(block.theta_rad.min()), float(block.theta_rad.max()))
        zero, step = self.params.angle_sensor.zeroing_error_rad, self.step_rad
        count = math.floor((lo - zero) / step + 0.5)
        if count != math.floor((hi - zero) / step + 0.5):  # ``read_v`` without re-checking the rig's block
            zero_0d, step_0d = self._zero_step_0d  # 0-d arrays: numpy converts Python floats every call
            u = ((block.theta_rad - zero_0d) / step_0d + _HALF_0D).tolist()
            positions = _snapped_positions_cached(block.time_s, self.params.daq)
            self.last_reading_v = _block_mean(positions, u, self._levels, self.params)
            return self.last_reading_v
        levels = self._levels
        self.last_reading_v = levels[(self._zero_count + count) % len(levels)]
        return self.last_reading_v


# --- ball position ---------------------------------------------------------------------------------------
def wiper_static_v(x_m: float | np.ndarray, sensor: BallSensor) -> float | np.ndarray:
    """Wiper volts for a ball touching the wire at x: the measured curve (Table 6.3 by default)
    interpolated linearly, clamped at its ends."""
    x = finite_values(x_m, "x_m")
    out = np.interp(x, sensor.curve_position_m, sensor.curve_volts_v)
    return float(out) if np.ndim(x_m) == 0 else out


class BallPositionChain:
    """Ball-position chain with its RC filter state and its seeded contact-noise process.

    ``seed`` is an int (or a ``np.random.Generator``; ``None`` draws fresh entropy — not reproducible). The
    dropout process is generated in time order, two draws per dropout (duration, then the wait to the next
    start), so its realization does not depend on how the run is cut into blocks: the same seed and the
    same calls give bit-identical readings.
    """

    def __init__(
        self, params: Parameters, seed: int | np.random.Generator | None, *, x_m: float = 0.0
    ) -> None:
        self.params = params
        self._rng = self._make_rng(seed)
        self._use_params(params)
        self.reset(x_m)

    def _use_params(self, params: Parameters) -> None:
        self.params = params
        s = params.ball_sensor
        self.tau_s = s.rc_resistance_ohm * s.rc_capacitance_f
        self._adc = adc_quantizer(params.daq)
        self._dropout_v = s.dropout_voltage_v
        self._curve_x = np.asarray(s.curve_position_m)
        self._curve_v = np.asarray(s.curve_volts_v)
        # Positions where the wiper's slope or the contact changes: the curve's points and the track's ends.
        half = params.track.half_length_m
        self._breakpoints_m = np.unique(np.concatenate([self._curve_x, [-half, half]]))
        self._breakpoint_list = self._breakpoints_m.tolist()  # bisect on a list: np.searchsorted's answer

    @staticmethod
    def _make_rng(seed: int | np.random.Generator | None) -> np.random.Generator:
        if isinstance(seed, np.random.Generator):
            return seed
        if seed is not None and (
            isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0
        ):
            raise ValueError(f"seed = {seed!r} is not a non-negative integer, a numpy Generator or None")
        return np.random.default_rng(seed)

    @property
    def _noise_on(self) -> bool:
        s = self.params.ball_sensor
        return bool(s.noise_enabled) and s.dropout_rate_hz > 0.0

    def _wiper_v(self, x_m: np.ndarray, connected: bool | np.ndarray = True) -> np.ndarray:
        """``wiper_v`` with this chain's curve and open-contact volts."""
        return wiper_v(x_m, connected, self._curve_x, self._curve_v, self._dropout_v)

    def _connected_v(self, x: float, in_contact: bool) -> float:
        """Wiper volts with no dropout: the static curve on the track, else the open-wiper voltage."""
        connected = in_contact and abs(x) <= self.params.track.half_length_m
        return float(self._wiper_v(np.array([x]), np.array([connected]))[0])

    def reset(
        self,
        x_m: float,
        t_s: float = 0.0,
        *,
        in_contact: bool = True,
        seed: int | np.random.Generator | None = None,
    ) -> None:
        """Ball at rest at ``x_m`` since long ago: the capacitor at the wiper's steady state, no dropouts so far.

        ``seed`` (optional) restarts the noise process from that seed."""
        x = float(finite_values(x_m, "x_m"))
        t = float(finite_values(t_s, "t_s"))
        if seed is not None:
            self._rng = self._make_rng(seed)
        self.time_s = t
        self.wiper_v = self._connected_v(x, in_contact)
        self.filtered_v = self.wiper_v
        self.reading_v = float(adc_quantize_v(self.filtered_v, self.params.daq))
        self._dropouts: list[tuple[float, float]] = []
        self._busy_until_s = -math.inf  # the latest end of a dropout so far
        self._first_open = 0
        self._forgotten = 0  # dropouts over and dropped from the history (it stays bounded in long sessions)
        self._next_start_s = (
            t + self._rng.exponential(1.0 / self.params.ball_sensor.dropout_rate_hz)
            if self._noise_on
            else math.inf
        )

    def set_params(self, params: Parameters) -> None:
        """New sensor parameters from now on (e.g. noise switched on or off mid-run); the filter keeps its
        charge and the noise process its seed."""
        was_on = self._noise_on
        self._use_params(params)
        s = params.ball_sensor
        if not self._noise_on:
            self._next_start_s = math.inf
        elif not was_on:
            self._next_start_s = self.time_s + self._rng.exponential(1.0 / s.dropout_rate_hz)

    @property
    def dropout_count(self) -> int:
        """Dropouts started since the last reset."""
        return self._forgotten + len(self._dropouts)

    @property
    def dropout_intervals(self) -> list[tuple[float, float]]:
        """(start, end) times of the dropouts kept: every one since the last reset, up to the last
        ``DROPOUT_HISTORY`` that are over (may extend past ``time_s``)."""
        return list(self._dropouts)

    def _schedule_until(self, t_end: float) -> None:
        mean_s = self.params.ball_sensor.dropout_mean_duration_s
        rate = self.params.ball_sensor.dropout_rate_hz
        while self._next_start_s <= t_end:
            start = self._next_start_s
            self._dropouts.append((start, start + self._rng.exponential(mean_s)))
            self._busy_until_s = max(self._busy_until_s, self._dropouts[-1][1])
            self._next_start_s = start + self._rng.exponential(1.0 / rate)

    def _forget_finished(self, t0: float) -> None:
        """Move past the dropouts over by ``t0``; forget the oldest once there are twice the history's."""
        while self._first_open < len(self._dropouts) and self._dropouts[self._first_open][1] <= t0:
            self._first_open += 1
        if self._first_open > 2 * DROPOUT_HISTORY:
            forget = self._first_open - DROPOUT_HISTORY
            del self._dropouts[:forget]
            self._first_open -= forget
            self._forgotten += forget

    def advance_block(self, block: PhysicsBlock) -> float:
        """``advance`` for a block the rig built (see ``advance_rig_block``)."""
        return self.advance_rig_block(
            block.time_s, block.x_m, block.on_track, block.equal_steps, block.x_range_m, block.all_on_track
        )

    def advance_rig_block(
        self,
        times_s: np.ndarray,
        x_m: np.ndarray,
        in_contact: np.ndarray,
        equal_steps: bool,
        x_range_m: tuple[float, float] | None = None,
        all_on_track: bool | None = None,
    ) -> float:
        """``advance`` for a block the rig built: finite times from the chain's time, one contact flag per
        time; ``equal_steps`` if the times are equally spaced (physics steps only: no held stretch before
        release); ``x_range_m``, ``all_on_track``: x's extremes and ``in_contact.all()`` when the caller
        has them. The common block — equal steps, in contact throughout, no table point or track end
        crossed — has the wiper on one linear piece of the curve between equally spaced knots: its filter
        is one dot product with cached weights (``rc_filter_uniform_end_v``), plus, for each dropout in it,
        the closed-form effect of the wiper at the open-contact volts there (``_dropout_effect_v``). Any
        other block goes through ``advance``'s piecewise filter."""
        t0, t_end = float(times_s[0]), float(times_s[-1])
        if equal_steps and (all_on_track if all_on_track is not None else bool(in_contact.all())):
            lo, hi = x_range_m or (float(x_m.min()), float(x_m.max()))
            # Within the track at both extremes (clear of its ends by more than interpolation's rounding):
            # every point in between is too. One segment between breakpoints: bisect is monotonic, so the
            # extremes' segments bound every knot's.
            bp = self._breakpoint_list
            if max(-lo, hi) < self.params.track.half_length_m * _CLEAR_OF_ENDS and bisect.bisect_left(
                bp, lo
            ) == bisect.bisect_left(bp, hi):
                self._schedule_until(t_end)
                if self._first_open < len(self._dropouts):
                    self._forget_finished(t0)
                vk = self._wiper_v(x_m)
                decay, _, weights, _ = _uniform_rc_weights(len(vk) - 1, t_end - t0, self.tau_s)
                y = rc_end_v(self.filtered_v, decay, vk.tolist(), weights)
                if self._busy_until_s > t0:  # a dropout reaches into the block
                    y += self._dropout_effect_v(times_s.tolist(), vk.tolist())
                self.filtered_v = y
                self.wiper_v = float(vk[-1]) if self._busy_until_s < t_end else self._dropout_v
                self.time_s = t_end
                self.reading_v = self._adc(y)
                return self.reading_v
        if equal_steps and all_on_track is not True and not in_contact[1:].any():
            # Out of contact throughout (the ball off the track): the wiper sits at the open-contact volts.
            self._schedule_until(t_end)  # the noise process draws as it would
            self._forget_finished(t0)
            decay, _, _, gain = _uniform_rc_weights(len(times_s) - 1, t_end - t0, self.tau_s)
            y = rc_end_v(self.filtered_v, decay, (self._dropout_v,), (gain,))  # one knot: the constant wiper
            self.filtered_v, self.wiper_v, self.time_s = y, self._dropout_v, t_end
            self.reading_v = self._adc(y)
            return self.reading_v
        return self._advance(times_s, x_m, in_contact)

    def _dropout_effect_v(self, t: list[float], v: list[float]) -> float:
        """What the dropouts in (t[0], t[-1]] change in the filter's output at t[-1] (``dropout_effects_v``
        for this chain's dropouts, the wiper linear between the knots ``t`` with values ``v``)."""
        drops = self._dropouts[self._first_open :]
        return float(
            dropout_effects_v(
                np.asarray(t), np.asarray(v)[None, :], np.array([d[0] for d in drops]),
                np.array([d[1] for d in drops]), np.array([0, len(drops)]), np.array([self.tau_s]), self._dropout_v,
                compiled=False,
            )[0]
        )  # fmt: skip

    def advance(self, times_s: np.ndarray, x_m: np.ndarray, in_contact: bool | np.ndarray = True) -> float:
        """Advance over one block and return the ADC reading of the ball channel at its end.

        ``times_s`` runs from the chain's current time (the previous block's end) to this block's last
        sample; ``x_m`` is the ball position there (linear in between). ``in_contact`` is one flag for the
        block or one per time: the interval (times_s[j], times_s[j+1]] uses ``in_contact[j+1]`` (the state
        at the end of that physics step). The block is split at table breakpoints and track ends crossed and
        at dropout starts/ends, so the wiper is exactly linear or constant on each piece, and the RC update
        is exact (closed form, not a numerical integration).
        """
        t, x = _check_trajectory(times_s, x_m, "x_m")
        if abs(t[0] - self.time_s) > CONTINUITY_TOLERANCE_SAMPLES / self.params.daq.sample_rate_hz:
            raise ValueError(
                f"times_s[0] = {t[0]!r} s: the block must start at the chain's time {self.time_s!r} s"
            )
        contact = np.asarray(in_contact)
        if contact.dtype != np.bool_ or contact.shape not in ((), t.shape):
            raise ValueError(
                f"in_contact = {in_contact!r}: it must be a bool or one bool per time in times_s"
            )
        return self._advance(t, x, contact)

    def _advance(self, t: np.ndarray, x: np.ndarray, contact: np.ndarray) -> float:
        """``advance`` on checked input: the piecewise filter."""
        t0, t_end = float(t[0]), float(t[-1])
        self._schedule_until(t_end)
        self._forget_finished(t0)
        drops = [d for d in self._dropouts[self._first_open :] if d[1] > t0]

        # Extra breakpoints: where x crosses a table point or a track end (the wiper's slope or contact
        # changes there) and where a dropout starts or ends.
        extra = [edge for d in drops for edge in d if t0 < edge < t_end]
        segment = np.searchsorted(self._breakpoints_m, x)
        for j in np.flatnonzero(segment[1:] != segment[:-1]).tolist():
            lo, hi = sorted((segment[j], segment[j + 1]))
            crossed = self._breakpoints_m[lo:hi]
            extra.extend((t[j] + (crossed - x[j]) / (x[j + 1] - x[j]) * (t[j + 1] - t[j])).tolist())
        if extra:
            knots = np.unique(np.concatenate([t, extra]))
            xk = np.interp(knots, t, x)
        else:
            knots, xk = t, x
        connected = np.abs(0.5 * (xk[:-1] + xk[1:])) <= self.params.track.half_length_m
        if contact.ndim == 0:
            connected &= bool(contact)
        elif not contact.all():
            mid = 0.5 * (knots[:-1] + knots[1:])
            connected &= contact[np.searchsorted(t, mid, side="left")]
        if drops:
            mid = 0.5 * (knots[:-1] + knots[1:])
            d = np.array(drops)
            connected &= ~((d[None, :, 0] < mid[:, None]) & (mid[:, None] < d[None, :, 1])).any(axis=1)
        vk = self._wiper_v(xk)
        if connected.all():  # the common case: the wiper on the curve throughout
            v_start, v_end = vk[:-1], vk[1:]
        else:
            v_start = self._wiper_v(xk[:-1], connected)
            v_end = self._wiper_v(xk[1:], connected)

        end = rc_filter_end_v(
            knots, v_start[None, :], v_end[None, :], np.array([self.filtered_v]), self.tau_s
        )
        y = float(end[0])
        self.filtered_v = y
        self.wiper_v = float(v_end[-1])
        self.time_s = t_end
        self.reading_v = self._adc(y)
        return self.reading_v


def _dropout_sums(
    t: np.ndarray,
    v: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    first: np.ndarray,
    tau: np.ndarray,
    open_v: float,
) -> np.ndarray:
    t0, t_end, n = t[0], t[-1], len(t)
    out = np.zeros(v.shape[0])
    for r in range(v.shape[0]):
        m = first[r + 1] - first[r]
        lo_s, hi_s = np.empty(m), np.empty(m)
        kept = 0
        for q in range(first[r], first[r + 1]):  # the dropouts within the block
            a, b = max(starts[q], t0), min(ends[q], t_end)
            if b > a:
                lo_s[kept], hi_s[kept] = a, b
                kept += 1
        order = np.argsort(lo_s[:kept], kind="mergesort")
        merged_a, merged_b = np.empty(kept), np.empty(kept)
        count = 0
        for q in order:  # overlapping ones merged
            a, b = lo_s[q], hi_s[q]
            if count and a <= merged_b[count - 1]:
                merged_b[count - 1] = max(merged_b[count - 1], b)
            else:
                merged_a[count], merged_b[count] = a, b
                count += 1
        effect = 0.0
        for d in range(count):
            a, b = merged_a[d], merged_b[d]
            j = max(np.searchsorted(t, a, side="right") - 1, 0)
            while j < n - 1 and t[j] < b:
                lo, hi = max(a, t[j]), min(b, t[j + 1])
                if hi > lo:
                    slope = (v[r, j + 1] - v[r, j]) / (t[j + 1] - t[j])
                    alpha = open_v - (v[r, j] + slope * (lo - t[j]))
                    u = (hi - lo) / tau[r]
                    one_minus = -math.expm1(-u)
                    # u − (1 − e^(−u)) by its series for tiny u (cancellation); pow as Python's ** takes it
                    if u < 1e-4:
                        excess = u * u / 2.0 - math.pow(u, 3.0) / 6.0 + math.pow(u, 4.0) / 24.0
                    else:
                        excess = u - one_minus
                    effect += math.exp((hi - t_end) / tau[r]) * (alpha * one_minus - slope * tau[r] * excess)
                j += 1
        out[r] = effect
    return out


@functools.cache
def _compiled_dropouts() -> Any:
    return njit_cached(_dropout_sums)


def dropout_effects_v(
    t: np.ndarray,
    v: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    first: np.ndarray,
    tau_s: np.ndarray,
    open_v: float,
    *,
    compiled: bool = True,
) -> np.ndarray:
    """What the dropouts change in each row's filter output at t[-1] over the knots ``t`` (K,), the wiper
    linear between them with row r's values ``v[r]`` (R, K): row r's dropouts are ``starts``/``ends``
    [first[r]:first[r + 1]], its time constant ``tau_s[r]``, the open wiper at ``open_v``. The integral of
    (v_drop − v(t))·e^(−(t_end − t)/τ)/τ over the dropped time (the dropouts clipped to the block, overlapping
    ones merged): on a piece [a, b] of one knot interval, with v_drop − v = α + β·(s − a), u = (b − a)/τ and
    w = e^(−(t_end − b)/τ), exactly w·(α·(1 − e^(−u)) + β·τ·(u − (1 − e^(−u)))). The one home of the
    dropouts' effect, for a chain alone and for a batch's rows at once: compiled (numba) for a batch;
    ``compiled=False`` runs the same function as Python, with the same bits (``tests/test_no_tick_imports.py``),
    for a chain alone: a single run never imports numba nor compiles on a tick (a served session's clock)."""
    sums = _compiled_dropouts() if compiled else _dropout_sums
    return sums(
        np.ascontiguousarray(t, dtype=float), np.ascontiguousarray(v, dtype=float),
        np.asarray(starts, dtype=float), np.asarray(ends, dtype=float), np.asarray(first, dtype=np.int64),
        np.asarray(tau_s, dtype=float), float(open_v),
    )  # fmt: skip


class BallChainBatch:
    """The ball chains of a batch of runs in step (one seed each), advanced block by block together.

    A run's block that crosses no table point or track end, has no dropout in it and stays in contact (the
    common block) is filtered in numpy over the batch with ``rc_filter_uniform_end_v``, as a run alone
    filters it; any other block goes through the run's own ``BallPositionChain``, which also owns its noise
    process (the next dropout is drawn there, so each run draws the same numbers in the same order as
    alone). Same bits as ``BallPositionChain`` run by run."""

    def __init__(
        self, params: Parameters | Sequence[Parameters], seeds: np.ndarray, x_m: np.ndarray, t_s: float
    ) -> None:
        """``params``: one set for every run, or one per run that differ at most in the filter's R and C and
        the dropout rate (``twin.rigs.batch.PER_RUN_IO``; a run's dropouts are its own chain's)."""
        run_params = [params] * len(seeds) if isinstance(params, Parameters) else list(params)
        self.params = run_params[0]
        self.chains = []
        for p, seed, x in zip(run_params, seeds.tolist(), x_m.tolist(), strict=True):
            chain = BallPositionChain(p, int(seed), x_m=x)
            chain.reset(x, t_s, seed=int(seed))  # as SimRig.reset: the noise process from the seed
            self.chains.append(chain)
        self.tau_s = np.array([c.tau_s for c in self.chains])
        taus = np.unique(self.tau_s)
        self._one_tau_s = float(taus[0]) if len(taus) == 1 else None  # one filter: no per-tick gather
        self.time_s = float(t_s)
        self.filtered_v = np.array([c.filtered_v for c in self.chains])
        self._next_start_s = np.array([c._next_start_s for c in self.chains])
        self._busy_until_s = np.full(len(self.chains), -math.inf)  # the latest end of a dropout so far

    def advance(
        self, runs: np.ndarray, times_s: np.ndarray, x_m: np.ndarray, on_track: np.ndarray
    ) -> np.ndarray:
        """``BallPositionChain.advance`` for the runs ``runs`` (indices), their x and contact one row each
        (len(runs), K) over the shared ``times_s`` (K,): the ADC readings at the block's end."""
        t0, t_end = float(times_s[0]), float(times_s[-1])
        chain0 = self.chains[0]
        half = self.params.track.half_length_m
        segment = np.searchsorted(chain0._breakpoints_m, x_m)
        equal_steps = equally_spaced(times_s)
        # ``advance_rig_block``'s common block: equal steps, in contact throughout, on one piece of the curve.
        smooth = (
            equal_steps
            & (segment == segment[:, :1]).all(axis=1)
            & (np.abs(x_m).max(axis=1) < half * _CLEAR_OF_ENDS)  # as ``advance_rig_block`` tells it
            & on_track.all(axis=1)
        )
        y = np.empty(len(runs))
        readings = np.empty(len(runs))
        if smooth.any():
            vk = chain0._wiper_v(x_m[smooth])
            rows = runs[smooth]
            tau = self.tau_s[rows] if self._one_tau_s is None else self._one_tau_s
            y[smooth] = rc_filter_uniform_end_v(vk, self.filtered_v[rows], t_end - t0, tau)
            # The runs whose noise process draws in the block or whose dropouts reach into it: the chain's own
            # draws (its seed's numbers in its order) and the dropouts' closed-form effect, run by run.
            at = np.cumsum(smooth) - 1  # a smooth run's row of vk
            due = smooth & ((self._next_start_s[runs] <= t_end) | (self._busy_until_s[runs] > t0))
            dropped: list[int] = []  # the due runs with a dropout in the block, and their dropouts
            starts: list[float] = []
            ends: list[float] = []
            first = [0]
            for j in np.flatnonzero(due).tolist():
                chain = self.chains[int(runs[j])]
                chain._schedule_until(t_end)
                if chain._first_open < len(chain._dropouts):
                    chain._forget_finished(t0)
                if chain._busy_until_s > t0:
                    for a, b in chain._dropouts[chain._first_open :]:
                        starts.append(a)
                        ends.append(b)
                    first.append(len(starts))
                    dropped.append(j)
                self._sync_noise(int(runs[j]))
            if dropped:
                rows = np.array(dropped)
                y[rows] += dropout_effects_v(
                    times_s, vk[at[rows]], np.array(starts), np.array(ends), np.array(first),
                    self.tau_s[runs[rows]], chain0._dropout_v,
                )  # fmt: skip
            readings[smooth] = adc_quantize_v(y[smooth], self.params.daq)
        for j in np.flatnonzero(~smooth).tolist():
            i = int(runs[j])
            chain = self.chains[i]
            chain.filtered_v, chain.time_s = float(self.filtered_v[i]), self.time_s
            readings[j] = chain.advance_rig_block(times_s, x_m[j], on_track[j], equal_steps)
            y[j] = chain.filtered_v
            self._sync_noise(i)
        self.filtered_v[runs] = y
        self.time_s = t_end
        return readings

    def _sync_noise(self, i: int) -> None:
        """Run i's next dropout start and latest dropout end, from its chain."""
        chain = self.chains[i]
        self._next_start_s[i] = chain._next_start_s
        self._busy_until_s[i] = chain._busy_until_s


def rc_filter_end_v(
    knots_s: np.ndarray, v_start: np.ndarray, v_end: np.ndarray, y0_v: np.ndarray, tau_s: float
) -> np.ndarray:
    """The RC filter's output at ``knots_s[-1]`` for each row: wiper volts linear on each piece from
    ``v_start[:, k]`` at ``knots_s[k]`` to ``v_end[:, k]`` at ``knots_s[k + 1]``, the capacitor at ``y0_v`` at
    ``knots_s[0]``. Rows share the knots (a batch of runs in step); each row's sum over the pieces is
    ``rc_end_v``'s, so a run gives the same bits alone or in a batch."""
    knots = knots_s
    t0, t_end = float(knots[0]), float(knots[-1])
    # τ·y' = v − y with v linear on a piece of length h from v_k to v_k+1 gives exactly
    #   y_k+1 = E·y_k + (1 − E)·v_k + (v_k+1 − v_k)·(1 − (1 − E)/(h/τ)),  E = e^(−h/τ)
    # (the last factor by its series for tiny h/τ, to avoid cancellation). Chained over all pieces:
    #   y_end = e^(−T/τ)·y_0 + Σ_k e^(−(t_end − t_k+1)/τ)·[(1 − E_k)·v_k + (v_k+1 − v_k)·ramp_k].
    # The pieces' exponentials by ``math`` (libm), as ``_uniform_rc_weights`` and ``_dropout_effect_v``
    # take theirs: numpy's np.exp/np.expm1 have other last bits under AVX-512 than without.
    a = ((knots[1:] - knots[:-1]) / tau_s).tolist()
    one_minus = [-math.expm1(-u) for u in a]
    # the ramp by its series for tiny pieces (only pieces cut short by an extra knot; a step is a ≈ 0.3)
    ramp = [
        u / 2.0 - u * u / 6.0 + u**3 / 24.0 if u < 1e-4 else 1.0 - e / u
        for u, e in zip(a, one_minus, strict=True)
    ]
    drive = np.array(one_minus) * v_start + (v_end - v_start) * np.array(ramp)
    weight = [math.exp(u) for u in ((knots[1:] - t_end) / tau_s).tolist()]
    decay = math.exp((t0 - t_end) / tau_s)
    if len(drive) == 1:  # one run: the float form (the same bits, without a numpy call per piece)
        return np.array([rc_end_v(float(y0_v[0]), decay, drive[0].tolist(), weight)])
    return rc_end_v(y0_v, decay, drive, np.array(weight))


def equally_spaced(times_s: np.ndarray) -> bool:
    """Whether the knots are equally spaced up to the clock's rounding (a block of physics steps alone)."""
    steps = np.diff(times_s)
    return bool(steps.max() - steps.min() <= 1e-9 * (times_s[-1] - times_s[0]))


@functools.lru_cache(maxsize=4096)  # a handful of spans for each filter of a batch (a spread's rigs: 50)
def _uniform_rc_weights(n: int, span_s: float, tau_s: float) -> tuple[float, np.ndarray, list[float], float]:
    """(decay, P, P as floats, ΣP) such that y_end = decay·y_0 + P·v for the RC filter driven by a wiper
    linear between n + 1 equally spaced knots over ``span_s`` (volts v_0 … v_n): ``rc_filter_end_v``'s sum
    with every piece the same length, its terms gathered per knot (ΣP: the gain for a constant wiper).
    Cached: a run's blocks have a handful of distinct spans (the clock's rounding), and the weights are the
    filter's whole cost."""
    a = span_s / n / tau_s
    one_minus = -math.expm1(-a)
    ramp = a / 2.0 - a * a / 6.0 + a**3 / 24.0 if a < 1e-4 else 1.0 - one_minus / a
    decay_per_piece = np.array([math.exp(-a * k) for k in range(n - 1, -1, -1)])  # e^(−(n − 1 − k)·a), libm
    weights = np.zeros(n + 1)
    weights[:-1] += decay_per_piece * (one_minus - ramp)
    weights[1:] += decay_per_piece * ramp
    weights.flags.writeable = False
    return math.exp(-span_s / tau_s), weights, weights.tolist(), fo.total(weights.tolist())


def rc_filter_uniform_end_v(
    v: np.ndarray, y0_v: np.ndarray, span_s: float, tau_s: float | np.ndarray
) -> np.ndarray:
    """The RC filter's output at the end of ``span_s`` for each row of ``v`` (B, n + 1): the wiper volts at
    n + 1 equally spaced knots, linear in between, the capacitor at ``y0_v`` at the first; ``tau_s`` one
    time constant or each row's (B,). Equal to ``rc_filter_end_v`` on those knots up to float rounding
    (~1e-16 V); each row is ``rc_end_v``'s, the bits a run alone gets."""
    n = v.shape[1] - 1
    if isinstance(tau_s, np.ndarray):
        taus, row_of = np.unique(tau_s, return_inverse=True)
        if len(taus) > 1:
            each = [_uniform_rc_weights(n, span_s, float(t)) for t in taus.tolist()]
            decays = np.array([w[0] for w in each])[row_of]
            return rc_end_v(y0_v, decays, v, np.stack([w[1] for w in each])[row_of])
        tau_s = float(taus[0])
    decay, weights, _, _ = _uniform_rc_weights(n, span_s, tau_s)
    return rc_end_v(y0_v, decay, v, weights)


def wiper_v(
    x_m: np.ndarray, connected: bool | np.ndarray, curve_x: np.ndarray, curve_v: np.ndarray, open_v: float
) -> np.ndarray:
    """The ball wiper's volts at positions ``x_m``: the measured static curve (linear between its points,
    clamped at its ends) where ``connected`` (in contact, on the track, no dropout), ``open_v`` elsewhere.
    The one home of the wiper for every path of the ball chain, alone and in a batch."""
    v = np.interp(x_m, curve_x, curve_v)
    if connected is True:
        return v
    return np.where(connected, v, open_v)


@overload
def rc_end_v(y0_v: float, decay: float, drive_v: Sequence[float], weights: Sequence[float]) -> float: ...
@overload
def rc_end_v(
    y0_v: np.ndarray, decay: float | np.ndarray, drive_v: np.ndarray, weights: np.ndarray
) -> np.ndarray: ...
def rc_end_v(
    y0_v: float | np.ndarray,
    decay: float | np.ndarray,
    drive_v: Sequence[float] | np.ndarray,
    weights: Sequence[float] | np.ndarray,
) -> float | np.ndarray:
    """The RC filter's output at a block's end: decay·y₀ + Σ_k drive_k·weight_k, the sum left to right
    (``twin.fixedorder``): the one home of the ball chain's filter arithmetic (the piecewise filter's pieces,
    a rig block's knots, a constant wiper's gain). A float ``y0_v`` with sequences of floats gives a float;
    ``y0_v`` (n,) with ``drive_v`` (n, K) gives (n,), each row the float form's bits (``decay`` (n,) and
    ``weights`` (n, K): each row's own)."""
    if isinstance(y0_v, np.ndarray):
        return decay * y0_v + fo.dots(np.asarray(drive_v), np.asarray(weights))
    assert not isinstance(drive_v, np.ndarray) and not isinstance(weights, np.ndarray), "floats: sequences"
    return decay * y0_v + fo.dot(drive_v, weights)


class IdealSensors:
    """Ideal converters: the exact x and θ at the block's end, in the volts the rig software reads as them.

    No quantization, no nonlinearity, no RC filter, no noise, no block averaging: the inverse of the
    software's conversions (``params.software``, eq 6.3.1 and eq 6.2.10) applied to the true state. The
    encoder's zeroing error is kept (the counter was zeroed at that angle: an offset, not a converter
    effect). Used to tell a design flaw from a sensor-chain effect, for the reference rig, and for smooth
    identification."""

    def __init__(self, params: Parameters) -> None:
        self.params = params

    @overload
    def read_v(self, x_m: float, theta_rad: float) -> tuple[float, float]: ...
    @overload
    def read_v(
        self, x_m: np.ndarray, theta_rad: np.ndarray, zeroing_error_rad: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]: ...
    def read_v(
        self,
        x_m: float | np.ndarray,
        theta_rad: float | np.ndarray,
        zeroing_error_rad: np.ndarray | None = None,
    ) -> tuple[float, float] | tuple[np.ndarray, np.ndarray]:
        """(ball volts, angle volts) for a ball at ``x_m`` and a beam at ``theta_rad``: floats, or arrays over
        the runs of a batch (the same operations element by element; ``zeroing_error_rad``: each run's)."""
        sw = self.params.software
        zero_rad = (
            self.params.angle_sensor.zeroing_error_rad if zeroing_error_rad is None else zeroing_error_rad
        )
        angle = theta_rad - zero_rad
        ball_v, angle_v = ball_volts_v(x_m, sw), angle_volts_v(angle, sw)
        if isinstance(x_m, np.ndarray):
            return np.asarray(ball_v), np.asarray(angle_v)
        return float(ball_v), float(angle_v)
