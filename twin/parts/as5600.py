"""The ams AS5600 12-bit magnetic angle sensor on the beam's pivot (``as5600``), group ``as5600``.

A diametric magnet on the beam's shaft turns over the chip, fixed to the frame. Sources: ams AS5600 data sheet
(v1-06, 2018): "ANGLE/RAW ANGLE Register" and "ZPOS/MPOS/MANG Registers" (12 bits, 4096 counts a turn; RAW ANGLE
unscaled, ANGLE after the zero position ZPOS), Figure 22 "CONF Register" (HYST: off, 1, 2 or 3 LSB; OUTS: analog
full range, analog 10 %–90 % of VDD, PWM; SF: slow filter 16x (the power-up default), 8x, 4x, 2x), "Step
Response and Filter Settings" (the slow filter's settling time 2.2, 1.1, 0.55, 0.286 ms and its RMS output
noise 0.015°, 0.021°, 0.030°, 0.043°), "Analog Output Mode" (a 12-bit DAC ratiometric to VDD), "Hysteresis"
(1 to 3 LSB against toggling while the magnet stands still), "Direction" (the DIR pin: here wired so that the
count rises with θ).

The chain (``AS5600Chain``) per block of the rig:

    x = (φ_level + θ)·4096/2π                the magnet's angle in counts (``as5600_counts``), unwrapped;
                                             φ_level: the magnet's angle when the beam is level (as mounted)
    y ← y + α·(x − y), α = 1 − e^(−Δt/τ)     the slow filter at every physics step (``as5600_filter``), a first
                                             order lag; τ = settling time/3 (assumed: "settled" read as within
                                             5 % of a step, e^−3)
    c = hysteresis(y + σ·n, c_prev, H)       the output count at the block's end (``as5600_hysteresis``): the
                                             data sheet's RMS noise σ added (one standard normal n per reading),
                                             then an H-LSB play: the count moves only when the angle leaves
                                             c_prev ± (H + ½), and then to within H of it (H = 0: the nearest
                                             count); modulo 4096, so 4095 + 1 wraps to 0

The board reads, in "i2c" mode (``as5600.analog_output`` false), the RAW ANGLE register: c (counts, as the
controller gets them over I²C); in analog mode the OUT pin, V = VDD·(0.1 + 0.8·ANGLE/4096) with ANGLE =
(c − ZPOS) mod 4096 (OUTS = 01, ``as5600_out_v``), through the board's ADC. Not modelled: the ANGLE register's
10-LSB hysteresis at the ends of its range (keep the beam's swing away from ZPOS), the fast filter (FTH = 000,
slow filter only, the default), the I²C read's own 0.48 ms (``twin.parts.arduino.i2c_read_time_s``: the value
read is the one at the block's end). The noise is seeded by the parameter ``as5600.noise_seed`` (a chain is
built from the parameters alone): the same parameters give bit-identical readings. A block that starts before
the last one ended (the rig was reset) starts a new run: the filter settled on its first angle, no previous
output, the noise from its seed; steps between two blocks that the rig did not show run the filter on.
``level_v`` (a
microcontroller's pin every physics step) is the noiseless, unfiltered output at one angle: the count in
"i2c" mode, the OUT pin's volts in analog mode.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from twin import model as mdl
from twin.parameters import Parameters, check_group, flag, param, register_group
from twin.parts.contract import (
    AngleSensorPart,
    BatchForm,
    MjcfFragment,
    board_adc,
    board_batch_adc,
    board_reading_unit,
    board_volts_of,
    register,
)
from twin.parts.potentiometer import RESET_TOLERANCE_S
from twin.physics import PhysicsBlock

__all__ = [
    "AS5600",
    "AS5600_PART",
    "COUNTS",
    "HOUSING",
    "AS5600Batch",
    "AS5600Chain",
    "as5600_counts",
    "as5600_filter",
    "as5600_hysteresis",
    "as5600_out_v",
    "slow_filter_alpha",
]

COUNTS = 4096  # data sheet: 12 bits a turn
_HALF = COUNTS // 2
# Analog output, OUTS = 01: 10 % to 90 % of VDD (data sheet, "Analog Output Mode", Figure 29).
_OUT_LOW, _OUT_SPAN = 0.1, 0.8
# Settled read as within e^-3 (5 %) of a step: τ = settling time / 3 (assumed).
_SETTLING_TAUS = 3.0
HOUSING = "as5600_board"
# A common AS5600 breakout: a 23 × 23 mm board, 1.6 mm thick, 3 mm behind the magnet on the pivot's axis, on the
# side facing away from the motor (clear of the beam bar's 22 mm half-width).
_BOARD_HALF_M = (0.0115, 0.0008, 0.0115)
_AXIS_OFFSET_M = -0.027


@dataclass(frozen=True)
class AS5600:
    """The AS5600 on the pivot: its output mode, supply, the magnet's mounting, ZPOS, hysteresis, slow filter
    and noise (with the noise's seed)."""

    analog_output: bool = flag(
        False,
        "false: the RAW ANGLE register read over I²C (counts); true: the OUT pin, analog 10–90 % of VDD (CONF "
        "OUTS = 01), read by the board's ADC",
    )
    supply_v: float = param(
        5.0,
        "V",
        "data sheet, operating conditions: VDD 4.5–5.5 V in 5 V mode (an Arduino's 5 V); 3.0–3.6 V in 3.3 V mode",
        ge=3.0,
        le=5.5,
        why="the data sheet's supply range, 3.3 V and 5 V modes",
    )
    magnet_angle_at_level_rad: float = param(
        math.pi,
        "rad",
        "assumed: the magnet glued so that the level beam reads half a turn (RAW ANGLE 2048), far from the "
        "4095 → 0 wrap",
        ge=0.0,
        lt=2.0 * math.pi,
        why="an angle within one turn",
    )
    zpos_counts: int = param(
        0,
        "count",
        "data sheet, ZPOS register: the zero of the ANGLE register and the OUT pin; 0 as shipped",
        ge=0,
        le=COUNTS - 1,
        integer=True,
        why="a 12-bit register",
    )
    hysteresis_lsb: int = param(
        0,
        "LSB",
        "data sheet, CONF register HYST: 00 = off (the power-up default), 1, 2 or 3 LSB",
        ge=0,
        le=3,
        integer=True,
        why="the HYST bits offer 0 to 3 LSB",
    )
    settling_time_s: float = param(
        2.2e-3,
        "s",
        "data sheet, 'Step Response and Filter Settings': slow filter 16x (SF = 00, the default) settles in 2.2 ms "
        "(8x 1.1 ms, 4x 0.55 ms, 2x 0.286 ms)",
        ge=0.0,
        le=0.01,
        why="the slowest setting is 2.2 ms; 10 ms leaves room for a fit; 0 is no filter",
    )
    noise_rms_rad: float = param(
        math.radians(0.015),
        "rad",
        "data sheet, 'Step Response and Filter Settings': RMS output noise 0.015° with the 16x slow filter "
        "(8x 0.021°, 4x 0.030°, 2x 0.043°)",
        ge=0.0,
        le=math.radians(1.0),
        why="1° RMS is eleven LSB: a magnet out of range, not the chip's noise",
    )
    noise_seed: int = param(
        0,
        "seed",
        "the chain's seed (np.random.default_rng): an angle chain is built from the parameters alone",
        ge=0,
        le=2**31 - 1,
        integer=True,
        why="a numpy seed, a non-negative 31-bit integer",
    )

    def __post_init__(self) -> None:
        check_group(self, "as5600")


register_group("as5600", AS5600)


def as5600_counts(theta_rad: float | np.ndarray, sensor: AS5600) -> float | np.ndarray:
    """The magnet's angle in counts for beam angle(s) θ: (φ_level + θ)·4096/2π, unwrapped (not yet an output)."""
    counts = (sensor.magnet_angle_at_level_rad + np.asarray(theta_rad, dtype=float)) * (
        COUNTS / (2.0 * math.pi)
    )
    return float(counts) if np.ndim(theta_rad) == 0 else counts


def slow_filter_alpha(dt_s: np.ndarray, settling_s: float | np.ndarray) -> np.ndarray:
    """The slow filter's gain per step, α = 1 − e^(−Δt/τ), τ = settling time/3 (α = 1 for no filter). ``dt_s``
    (..., K) steps; ``settling_s`` a number or one per row."""
    tau = np.asarray(settling_s, dtype=float)[..., None] / _SETTLING_TAUS
    with np.errstate(divide="ignore"):
        return np.where(tau > 0.0, -np.expm1(-np.asarray(dt_s) / np.where(tau > 0.0, tau, 1.0)), 1.0)


def as5600_filter(y: np.ndarray, alpha: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The slow filter over a block: y ← y + α_k·(x_k − y) for each knot k ≥ 1 (knot 0 is the previous block's
    end); ``y`` (N,), ``alpha`` (N, K − 1), ``x`` (N, K) counts. Returns the filtered counts at the block's end."""
    if (
        len(y) == 1
    ):  # one run (a rig's tick): Python floats, the same IEEE operations, without numpy's overhead
        v = float(y[0])
        for a, xk in zip(alpha[0].tolist(), x[0, 1:].tolist(), strict=True):
            v = v + a * (xk - v)
        return np.array([v])
    y = np.array(y, dtype=float)
    for k in range(1, x.shape[1]):
        y = y + alpha[:, k - 1] * (x[:, k] - y)
    return y


def as5600_hysteresis(x: np.ndarray, previous: np.ndarray, hysteresis_lsb: np.ndarray) -> np.ndarray:
    """The output count for angle(s) ``x`` (counts, unwrapped) after ``previous`` (0 … 4095): unchanged while x
    is within previous ± (H + ½) around the circle, else the count H behind x, rounded; modulo 4096."""
    d = np.mod(x - previous + _HALF, COUNTS) - _HALF
    band = hysteresis_lsb + 0.5
    moved = np.where(
        d > band,
        np.floor(previous + d - hysteresis_lsb + 0.5),
        np.where(d < -band, np.ceil(previous + d + hysteresis_lsb - 0.5), previous),
    )
    return np.mod(moved, COUNTS)


def as5600_out_v(count: float | np.ndarray, sensor: AS5600) -> float | np.ndarray:
    """The OUT pin's volts for an output count (OUTS = 01): VDD·(0.1 + 0.8·ANGLE/4096), ANGLE = (count − ZPOS)
    mod 4096."""
    angle = np.mod(np.asarray(count, dtype=float) - sensor.zpos_counts, COUNTS)
    volts = sensor.supply_v * (_OUT_LOW + _OUT_SPAN * angle / COUNTS)
    return float(volts) if np.ndim(count) == 0 else volts


def _first_count(x: np.ndarray) -> np.ndarray:
    """The output at power-up: the nearest count (no previous output for the hysteresis)."""
    return np.mod(np.floor(x + 0.5), COUNTS)


class AS5600Chain:
    """One run's AS5600 (``AngleSensorChain``): its slow filter and output count carried from block to block,
    its noise seeded by ``as5600.noise_seed``, read over I²C or through the board's ADC."""

    def __init__(self, params: Parameters) -> None:
        self.sensor = params.of(AS5600)
        self.adc = board_adc(params) if self.sensor.analog_output else None
        self.rng = np.random.default_rng(self.sensor.noise_seed)
        self.sigma_counts = self.sensor.noise_rms_rad * COUNTS / (2.0 * math.pi)
        self.filtered: np.ndarray | None = None  # (1,) counts, unwrapped
        self.count: np.ndarray | None = None  # (1,) the output count 0 … 4095
        self.last_reading_v: float | None = None
        self._end_s: float | None = None  # the last block's end

    def level_v(self, theta_rad: float) -> float:
        """The output at one angle, noiseless and unfiltered: the count ("i2c"), the OUT pin's volts (analog)."""
        count = float(_first_count(np.array([as5600_counts(float(theta_rad), self.sensor)]))[0])
        return float(as5600_out_v(count, self.sensor)) if self.sensor.analog_output else count

    def read_block_v(self, block: PhysicsBlock) -> float:
        """The board's reading at the block's end (the module docstring's chain)."""
        x = np.asarray(as5600_counts(block.theta_rad, self.sensor))[None, :]
        t0 = float(block.time_s[0])
        settling = np.array([self.sensor.settling_time_s])
        if self.filtered is None or self._end_s is None or t0 < self._end_s - RESET_TOLERANCE_S:
            # the first block, or the rig reset (the protocol has no reset): settled on the held rig, no
            # output yet, the noise from its seed again (as the rig's ball chain's)
            self.filtered, self.count = x[:, 0], None
            self.rng = np.random.default_rng(self.sensor.noise_seed)
        elif t0 > self._end_s + RESET_TOLERANCE_S:  # steps the rig ran unobserved: the filter ran on
            gap = slow_filter_alpha(np.array([[t0 - self._end_s]]), settling)
            self.filtered = as5600_filter(self.filtered, gap, np.column_stack([self.filtered, x[:, 0]]))
        self._end_s = float(block.time_s[-1])
        alpha = slow_filter_alpha(np.diff(block.time_s)[None, :], settling)
        self.filtered = as5600_filter(self.filtered, alpha, x)
        noisy = self.filtered + self.sigma_counts * self.rng.standard_normal(1)
        h = np.array([self.sensor.hysteresis_lsb])
        self.count = _first_count(noisy) if self.count is None else as5600_hysteresis(noisy, self.count, h)
        if self.adc is None:
            self.last_reading_v = float(self.count[0])
        else:
            self.last_reading_v = self.adc(float(as5600_out_v(float(self.count[0]), self.sensor)))
        return self.last_reading_v


class AS5600Batch:
    """N runs' AS5600s read in step (``twin.parts.contract.AngleSensorBatch``): each run a fresh ``AS5600Chain``
    bit for bit: the slow filter, the noise (each run's generator, its ``noise_seed``) and the hysteresis on arrays
    over the runs, each analog run's OUT pin through its board's ADC (``board_batch_adc``)."""

    def __init__(self, params: Sequence[Parameters]) -> None:
        self.sensors = [p.of(AS5600) for p in params]
        n = len(self.sensors)
        self.phase_rad = np.array([s.magnet_angle_at_level_rad for s in self.sensors])
        self.settling_s = np.array([s.settling_time_s for s in self.sensors])
        self.sigma_counts = np.array([s.noise_rms_rad * COUNTS / (2.0 * math.pi) for s in self.sensors])
        self.hysteresis_lsb = np.array([float(s.hysteresis_lsb) for s in self.sensors])
        self.analog = np.array([s.analog_output for s in self.sensors], dtype=bool)
        self.adc = board_batch_adc(params) if self.analog.any() else None
        self.filtered = np.zeros(n)  # counts, unwrapped
        self.count = np.zeros(n)  # the output count 0 … 4095
        self.started = np.zeros(n, dtype=bool)  # a run's filter has its first angle
        self.has_count = np.zeros(n, dtype=bool)  # a run has put out a count (the hysteresis' previous)
        self.rngs = [np.random.default_rng(s.noise_seed) for s in self.sensors]
        self._end_s: float | None = None  # the last block's end (the runs are in step)

    def read(self, runs: np.ndarray, times_s: np.ndarray, theta_rad: np.ndarray) -> np.ndarray:
        """``AS5600Chain.read_block_v`` for runs ``runs`` (the module docstring's chain)."""
        t0 = float(times_s[0])
        if self._end_s is not None and t0 < self._end_s - RESET_TOLERANCE_S:  # the rig reset: every run anew
            self.started[:] = False
            self.has_count[:] = False
            self.rngs = [np.random.default_rng(s.noise_seed) for s in self.sensors]
        x = (self.phase_rad[runs][:, None] + np.asarray(theta_rad, dtype=float)) * (COUNTS / (2.0 * math.pi))
        settling = self.settling_s[runs]
        first = ~self.started[runs]
        y = np.where(first, x[:, 0], self.filtered[runs])  # a first block: settled on the held rig
        on = np.flatnonzero(~first)
        if on.size and self._end_s is not None and t0 > self._end_s + RESET_TOLERANCE_S:
            # steps the rig ran unobserved: the filter ran on toward the block's first angle
            gap = slow_filter_alpha(np.array([[t0 - self._end_s]]), settling[on])
            y[on] = as5600_filter(y[on], gap, np.column_stack([y[on], x[on, 0]]))
        self._end_s = float(times_s[-1])
        alpha = slow_filter_alpha(np.diff(times_s)[None, :], settling)
        y = as5600_filter(y, alpha, x)
        self.filtered[runs] = y
        self.started[runs] = True
        draws = np.array([self.rngs[i].standard_normal(1)[0] for i in runs.tolist()])
        noisy = y + self.sigma_counts[runs] * draws
        count = _first_count(noisy)
        held = np.flatnonzero(self.has_count[runs])
        if held.size:
            count[held] = as5600_hysteresis(
                noisy[held], self.count[runs[held]], self.hysteresis_lsb[runs[held]]
            )
        self.count[runs] = count
        self.has_count[runs] = True
        out = count.astype(float)
        analog = np.flatnonzero(self.analog[runs])
        if analog.size:
            assert self.adc is not None
            volts = np.array(
                [float(as5600_out_v(float(count[j]), self.sensors[int(runs[j])])) for j in analog.tolist()]
            )
            out[analog] = self.adc(runs[analog], volts)
        return out


# --- the MJCF fragment: the sensor's board at the pivot, drawn only ------------------------------------------
def apply_board(spec: mujoco.MjSpec, params: Parameters) -> None:
    """Add the AS5600's breakout board on the pivot's axis (a visual box: no contact, geom group 2, no mass)."""
    pivot = np.asarray(spec.body(mdl.BEAM_BODY).pos, dtype=float)
    spec.worldbody.add_geom(
        name=HOUSING,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(_BOARD_HALF_M),
        pos=(pivot + np.array([0.0, _AXIS_OFFSET_M, 0.0])).tolist(),
        contype=0,
        conaffinity=0,
        group=2,
        mass=0.0,
        rgba=[0.1, 0.35, 0.6, 1.0],
    )


# --- the batch form: N runs over a few blocks at once ---------------------------------------------------------
_BLOCKS = 3
_KNOTS = 21  # a 20 ms block at 1 ms steps


def _times() -> np.ndarray:
    return 0.1 + np.arange(_BLOCKS * (_KNOTS - 1) + 1) * Parameters().physics.timestep_s


def _inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    params = []
    for _ in range(n):
        params.append(
            Parameters().with_overrides(
                {
                    "parts.io_board": str(rng.choice(["pci1712", "arduino_uno"])),
                    "as5600.analog_output": bool(rng.integers(0, 2)),
                    # some magnets mounted at the wrap, so that blocks cross 4095 → 0
                    "as5600.magnet_angle_at_level_rad": float(
                        rng.choice([math.pi, 1e-3, 2.0 * math.pi - 1e-3])
                    ),
                    "as5600.zpos_counts": int(rng.integers(0, COUNTS)),
                    "as5600.hysteresis_lsb": int(rng.integers(0, 4)),
                    "as5600.settling_time_s": float(rng.choice([0.0, 0.286e-3, 2.2e-3])),
                    "as5600.noise_rms_rad": float(rng.uniform(0.0, 0.002)),
                    "as5600.noise_seed": int(rng.integers(0, 2**31 - 1)),
                }
            )
        )
    rates = rng.uniform(-2.0, 2.0, n)
    rates[: n // 4] = 0.0  # a still beam: the hysteresis holds against the noise
    return params, np.column_stack([rng.uniform(-0.1, 0.1, n), rates])


def _theta(row: np.ndarray) -> np.ndarray:
    times = _times()
    return row[0] + row[1] * (times - times[0])


def _block(times: np.ndarray, theta: np.ndarray, b: int) -> PhysicsBlock:
    k = slice(b * (_KNOTS - 1), (b + 1) * (_KNOTS - 1) + 1)
    return PhysicsBlock(times[k], np.zeros(_KNOTS), theta[k], np.ones(_KNOTS, dtype=bool))


def _single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One run's chain over the blocks, and its level at the last angle."""
    chain, times, theta = AS5600Chain(params), _times(), _theta(row)
    readings = [chain.read_block_v(_block(times, theta, b)) for b in range(_BLOCKS)]
    return np.array([*readings, chain.level_v(float(theta[-1]))])


def _batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every run at once: the filter, the noise and the hysteresis on arrays over the runs (each its own
    sensor and seed), then each analog run's board ADC (the board part's per-reading converter)."""
    sensors = [p.of(AS5600) for p in params]
    times = _times()
    theta = np.array([_theta(row) for row in rows])
    phase = np.array([s.magnet_angle_at_level_rad for s in sensors])[:, None]
    x = (phase + theta) * (COUNTS / (2.0 * math.pi))
    settling = np.array([s.settling_time_s for s in sensors])
    sigma = np.array([s.noise_rms_rad * COUNTS / (2.0 * math.pi) for s in sensors])
    draws = np.array([np.random.default_rng(s.noise_seed).standard_normal(_BLOCKS) for s in sensors])
    hyst = np.array([float(s.hysteresis_lsb) for s in sensors])
    analog = [s.analog_output for s in sensors]
    adcs = [board_adc(p) if s.analog_output else None for p, s in zip(params, sensors, strict=True)]
    filtered, count = x[:, 0], None
    out = []
    for b in range(_BLOCKS):
        k = slice(b * (_KNOTS - 1), (b + 1) * (_KNOTS - 1) + 1)
        alpha = slow_filter_alpha(np.diff(times[k])[None, :], settling)
        filtered = as5600_filter(filtered, alpha, x[:, k])
        noisy = filtered + sigma * draws[:, b]
        count = _first_count(noisy) if count is None else as5600_hysteresis(noisy, count, hyst)
        volts = np.array([as5600_out_v(c, s) for c, s in zip(count.tolist(), sensors, strict=True)])
        out.append(
            np.array(
                [
                    adc(v) if adc is not None else c
                    for adc, v, c in zip(adcs, volts, count.tolist(), strict=True)
                ]
            )
        )
    level = _first_count(x[:, -1])
    level_v = np.array([as5600_out_v(c, s) for c, s in zip(level.tolist(), sensors, strict=True)])
    level_out = np.where(analog, level_v, level)
    return np.column_stack([*out, level_out])


def as5600_angle_of(params: Parameters) -> Callable[[float], float]:
    """The software's conversion: a count (I²C RAW ANGLE; or the OUT pin's volts through the board's reading,
    ``as5600_out_v`` inverted, ZPOS added back) → θ = count·2π/4096 − the magnet's angle at level, within ±π."""
    sensor = params.of(AS5600)
    volts_of = board_volts_of(params) if sensor.analog_output else None

    def theta_rad(reading: float) -> float:
        count = reading
        if volts_of is not None:
            fraction = (volts_of(reading) / sensor.supply_v - _OUT_LOW) / _OUT_SPAN
            count = fraction * COUNTS + sensor.zpos_counts
        return math.remainder(
            count * 2.0 * math.pi / COUNTS - sensor.magnet_angle_at_level_rad, 2.0 * math.pi
        )

    return theta_rad


def as5600_reading_unit(params: Parameters) -> str:
    """Its reading's unit: RAW ANGLE counts over I²C, the board's ADC's for the analog OUT pin."""
    return board_reading_unit(params) if params.of(AS5600).analog_output else "counts"


AS5600_PART = register(
    AngleSensorPart(
        name="as5600",
        source="ams AS5600 data sheet v1-06: 12-bit RAW ANGLE, ZPOS, CONF (HYST 0–3 LSB, OUTS 10–90 % analog, "
        "SF), 'Step Response and Filter Settings' (settling 2.2 ms, noise 0.015° RMS at 16x); filter shape assumed",
        groups={"as5600": AS5600},
        equations=(
            as5600_counts,
            slow_filter_alpha,
            as5600_filter,
            as5600_hysteresis,
            as5600_out_v,
            AS5600Chain,
        ),
        mjcf=MjcfFragment((), apply_board),
        batch=BatchForm(_single, _batch, _inputs, "twin.parts.as5600.as5600_hysteresis"),
        chain=AS5600Chain,
        batch_read=AS5600Batch,
        angle_of=as5600_angle_of,
        reading_unit=as5600_reading_unit,
    )
)
