"""The acceptance figures of the physical core and the I/O chain, measured on the twin's own code.

Each function runs one experiment and returns the numbers it measured; it judges nothing. The scripts
``scripts/core_figures.py`` and ``scripts/io_figures.py`` print them, the tests assert on them against the
thesis, physics or an independent computation. The expected values (theory, thesis tables, tolerances) are
not here: they belong to whoever compares.

Analysis code, not runtime. It drives only the core (plant, reference model, rig, sensor chain, log), so it
lives in the core layer and the core's tests use it without the application layer (docs/design.md,
"Layers"); a measurement that needs a controller belongs in ``twin.app``.
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import mujoco
import numpy as np
import scipy.signal

from twin import converters, daq, sensors
from twin.linearize import linearize_mujoco
from twin.log import RunLog, load_mat, save_mat
from twin.output_stage import motor_volts
from twin.parameters import Parameters
from twin.plant import Plant
from twin.reference import InputKind, ReferenceModel
from twin.rigs.sim import TwinRig

# One 20 ms block at the 1 ms physics step: the knots the angle and ball chains are advanced over.
_BLOCK_KNOTS_S = np.arange(21) * 1e-3


# --- physical core ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Rolling:
    """The ball rolling down a held beam from x = 0.25 m for 0.3 s (1 ms steps)."""

    accel_m_s2: float  # along the beam, from a quadratic fit of x(t) (independent of the velocity readout)
    speed_over_spin: np.ndarray  # v / (−r*·ω) from the 50th step on (1 when rolling without slip)
    ball_lost: bool


def rolling(params: Parameters, theta_rad: float) -> Rolling:
    plant = Plant(params, hold_beam_rad=theta_rad)
    plant.reset(x_m=0.25)
    times, xs, speeds, spins = [], [], [], []
    for _ in range(300):  # 0.3 s; the ball stays on the track at every angle up to 0.3 rad
        plant.step(0.0)
        state = plant.state()
        times.append(plant.time_s)
        xs.append(state[0])
        speeds.append(state[2])
        spins.append(plant.ball_kinematics().spin_rad_s)
    accel = 2.0 * float(np.polyfit(times, xs, 2)[0])
    ratio = np.array(speeds[50:]) / (-params.rolling_radius_m * np.array(spins[50:]))
    return Rolling(accel_m_s2=accel, speed_over_spin=ratio, ball_lost=plant.ball_lost)


def motor_torque_nm(
    params: Parameters, volts: float, thetadot_rad_s: float, plant: Plant | None = None
) -> float:
    """MuJoCo's joint torque at the beam for terminal ``volts`` (before the rails) and beam rate."""
    plant = plant if plant is not None else Plant(params)
    plant.reset(theta_rad=0.0, thetadot_rad_s=thetadot_rad_s)
    plant.data.ctrl[0] = volts
    mujoco.mj_forward(plant.model, plant.data)
    return plant.motor_torque_nm()


@dataclass(frozen=True)
class MotorGrid:
    """MuJoCo's joint torque over the operating range: 13 volts from −12 to 12 V × 11 rates from −10 to
    10 rad/s; ``torque_nm[i, j]`` at ``volts_v[i]``, ``thetadot_rad_s[j]``."""

    volts_v: np.ndarray
    thetadot_rad_s: np.ndarray
    torque_nm: np.ndarray


def motor_torque_grid(params: Parameters) -> MotorGrid:
    plant = Plant(params)
    volts = np.linspace(-12.0, 12.0, 13)
    rates = np.linspace(-10.0, 10.0, 11)
    torque = np.array([[motor_torque_nm(params, float(v), float(w), plant) for w in rates] for v in volts])
    return MotorGrid(volts_v=volts, thetadot_rad_s=rates, torque_nm=torque)


@dataclass(frozen=True)
class LinearizationError:
    """The MuJoCo twin's (A, B) at the origin against the reference model's: the worst relative error over
    the entries the reference has above 1e-3, and the largest twin entry where the reference's is not."""

    worst_rel_a: float
    worst_rel_b: float
    worst_small_abs: float

    @property
    def worst_rel(self) -> float:
        return max(self.worst_rel_a, self.worst_rel_b)


def linearization_error(params: Parameters, kind: InputKind) -> LinearizationError:
    a, b = linearize_mujoco(params, kind)
    a_ref, b_ref = ReferenceModel(params).linearize(kind)
    rels, small = [], 0.0
    for got, want in ((a, a_ref), (b, b_ref)):
        big = np.abs(want) > 1e-3
        rels.append(float((np.abs(got - want)[big] / np.abs(want)[big]).max()))
        small = max(small, float(np.abs(got[~big]).max(initial=0.0)))
    return LinearizationError(worst_rel_a=rels[0], worst_rel_b=rels[1], worst_small_abs=small)


@dataclass(frozen=True)
class TrajectoryAgreement:
    """The twin and the reference model driven by the same 1 s voltage profile from the same start."""

    max_dx_m: float
    max_dtheta_rad: float
    max_abs_volts_v: float  # the profile's largest |V| (inside the rails: no clipping difference)


def trajectory_agreement(params: Parameters, x0: Sequence[float], ticks: int = 50) -> TrajectoryAgreement:
    """Volts computed in closed loop on the reference (poles −2…−5, 20 ms hold), then replayed open loop on
    both models (the open-loop plant is unstable, so a random profile would diverge)."""
    ref = ReferenceModel(params)
    a, b = ref.linearize("voltage")
    gain = scipy.signal.place_poles(a, b, [-2.0, -3.0, -4.0, -5.0]).gain_matrix[0]
    start = np.array(x0, dtype=float)
    state, volts = start.copy(), []
    for _ in range(ticks):
        volts.append(float(-gain @ state))
        state = ref.simulate(state, np.array([volts[-1]]), 0.02, samples_per_hold=1)[1][-1]
    _, ref_states = ref.simulate(start, np.array(volts), 0.02, samples_per_hold=20)
    plant = Plant(params)
    plant.reset(*start)
    twin_states = [plant.state()]
    for u in volts:
        for _ in range(20):
            plant.step(u)
            twin_states.append(plant.state())
    twin = np.array(twin_states)
    return TrajectoryAgreement(
        max_dx_m=float(np.abs(twin[:, 0] - ref_states[:, 0]).max()),
        max_dtheta_rad=float(np.abs(twin[:, 1] - ref_states[:, 1]).max()),
        max_abs_volts_v=float(np.abs(volts).max()),
    )


@dataclass(frozen=True)
class BallLoss:
    """A ball released at the centre of a beam held at 0.2 rad, 4 s in 20 ms ticks at 0 V."""

    lost: bool
    lost_time_s: float | None
    last_on_track_x_m: float  # x at the last tick the ball was still on the track
    final_x_m: float  # the ball centre's x (world) at the end
    finite_every_tick: bool
    warnings: dict[str, int]


def ball_loss(params: Parameters) -> BallLoss:
    plant = Plant(params, hold_beam_rad=0.2)
    plant.reset(x_m=0.0)
    last_on_track_x, finite = 0.0, True
    for _ in range(200):
        plant.step(0.0, n_steps=20)
        finite = finite and bool(np.all(np.isfinite(plant.state())))
        if not plant.ball_lost:
            last_on_track_x = float(plant.state()[0])
    return BallLoss(
        lost=plant.ball_lost,
        lost_time_s=plant.ball_lost_time_s,
        last_on_track_x_m=last_on_track_x,
        final_x_m=float(plant.ball_kinematics().position_m[0]),
        finite_every_tick=finite,
        warnings=plant.warnings(),
    )


# --- I/O chain ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AngleStaircase:
    """A beam held still at every count of its ±43.4° range (counts −216…216 from the zero switch) and at
    ``offsets`` within each count (in counts), read as the software reads it: the block mean, then eq 6.2.10
    with the default calibration."""

    counts: np.ndarray
    readings_v: np.ndarray  # [count, offset]
    angle_rad: np.ndarray  # the software's angle of the reading at the first offset
    count_step_rad: float  # eq 6.2.1
    lsb_v: float  # the ADC's step

    @property
    def volts_v(self) -> np.ndarray:
        return self.readings_v[:, 0]

    @property
    def steps_count(self) -> np.ndarray:
        """Each step of the read-back angle between neighbouring counts, in counts (1 = one count)."""
        return np.diff(self.angle_rad) / self.count_step_rad

    @property
    def steps_lsb(self) -> np.ndarray:
        """Each step of the reading between neighbouring counts, in ADC steps."""
        return np.diff(self.volts_v) / self.lsb_v


def angle_staircase(params: Parameters, offsets: Sequence[float] = (0.0,)) -> AngleStaircase:
    step = sensors.angle_count_step_rad(params)
    counts = np.arange(-216, 217)
    readings = np.array(
        [
            [sensors.angle_block_mean_v(_BLOCK_KNOTS_S, np.full(21, (c + f) * step), params) for f in offsets]
            for c in counts
        ]
    )
    return AngleStaircase(
        counts=counts,
        readings_v=readings,
        angle_rad=converters.beam_angle_rad(readings[:, 0], params.software),
        count_step_rad=step,
        lsb_v=daq.adc_lsb_v(params.daq),
    )


# Eq 6.2.4: the counter's DAC output measured on the rig at three inputs (DI → volts).
EQ_6_2_4_MEASURED_V = {0: -5.042, 512: -0.014, 1023: 5.002}


@dataclass(frozen=True)
class CounterLevel:
    """One of eq 6.2.4's measured counter outputs against the twin: eq 6.2.6 (the DAC model) and what the
    ±5 V ADC makes of it, errors in ADC LSB."""

    di: int
    measured_v: float
    dac_v: float
    adc_v: float
    dac_error_lsb: float
    adc_error_lsb: float


def counter_levels(params: Parameters) -> list[CounterLevel]:
    lsb = daq.adc_lsb_v(params.daq)
    out = []
    for di, measured in EQ_6_2_4_MEASURED_V.items():
        dac_v = float(sensors.counter_dac_v(di, params))
        adc_v = float(daq.adc_quantize_v(dac_v, params.daq))
        out.append(
            CounterLevel(di, measured, dac_v, adc_v, abs(dac_v - measured) / lsb, abs(adc_v - measured) / lsb)
        )
    return out


@dataclass(frozen=True)
class BallTableReadings:
    """The twin's rig (noise off) with the ball placed at each point of the wiper curve (Table 6.3 by
    default): the first block's ball reading against the curve's volts."""

    position_m: np.ndarray
    curve_v: np.ndarray
    reading_v: np.ndarray
    lsb_v: float

    @property
    def worst_error_lsb(self) -> float:
        return float(np.abs(self.reading_v - self.curve_v).max() / self.lsb_v)


def ball_table_readings(params: Parameters) -> BallTableReadings:
    rig = TwinRig(params, noise=False)
    positions = np.array(params.ball_sensor.curve_position_m, dtype=float)
    readings = []
    for x in positions:
        rig.reset(x_m=float(x))
        readings.append(rig.read().ball_v)
    return BallTableReadings(
        position_m=positions,
        curve_v=np.array(params.ball_sensor.curve_volts_v, dtype=float),
        reading_v=np.array(readings),
        lsb_v=daq.adc_lsb_v(params.daq),
    )


@dataclass(frozen=True)
class RcStep:
    """The ball channel's RC filter (noise off) from steady state at x = 0.30 m (the wiper's 4.340 V): the
    wiper opens for 15 ms (a step to 0 V), then closes for 15 ms; τ fitted to each from 0.1 ms samples."""

    tau_fall_s: float
    tau_rise_s: float
    final_filtered_v: float
    final_reading_v: float


def _fit_time_constant_s(times: np.ndarray, v: np.ndarray, v_final: float) -> float:
    """τ from a straight-line fit of log|v − v_final| against time."""
    return -1.0 / float(np.polyfit(times, np.log(np.abs(v - v_final)), 1)[0])


def rc_step(params: Parameters) -> RcStep:
    quiet = params.with_overrides({"ball_sensor.noise_enabled": False})
    chain = sensors.BallPositionChain(quiet, seed=0, x_m=0.30)
    v_wiper = chain.wiper_v
    times, falling = [], []
    for _ in range(150):
        t = chain.time_s + np.array([0.0, 1e-4])
        chain.advance(t, np.full(2, 0.30), in_contact=False)
        times.append(t[-1])
        falling.append(chain.filtered_v)
    rising = []
    for _ in range(150):
        chain.advance(chain.time_s + np.array([0.0, 1e-4]), np.full(2, 0.30))
        rising.append(chain.filtered_v)
    t = np.array(times)
    return RcStep(
        tau_fall_s=_fit_time_constant_s(t, np.array(falling), 0.0),
        tau_rise_s=_fit_time_constant_s(t, np.array(rising), v_wiper),
        final_filtered_v=chain.filtered_v,
        final_reading_v=chain.reading_v,
    )


@dataclass(frozen=True)
class Dropouts:
    """The ball chain's contact dropouts over ``seconds`` of 20 ms blocks, the ball moving as 0.2·sin(1.3 t)."""

    seconds: float
    count: int
    durations_s: np.ndarray  # of the dropouts kept in the chain's history


def dropouts(params: Parameters, seconds: float = 200.0, seed: int = 2024) -> Dropouts:
    chain = sensors.BallPositionChain(params, seed=seed, x_m=0.0)
    for _ in range(round(seconds / 0.02)):
        times = chain.time_s + _BLOCK_KNOTS_S
        chain.advance(times, 0.2 * np.sin(1.3 * times))
    durations = np.array([b - a for a, b in chain.dropout_intervals])
    return Dropouts(seconds=seconds, count=chain.dropout_count, durations_s=durations)


# The software's command extremes and limits (§6.4) and the card's ends: 0, 1.25, 2.5, 3.75, 5 V.
OUTPUT_COMMANDS_V = (0.0, 1.25, 2.5, 3.75, 5.0)


def output_stage(params: Parameters, commands_v: Sequence[float] = OUTPUT_COMMANDS_V) -> dict[float, float]:
    """Motor volts for each DAC command (DAC, then amplifier and its rails)."""
    return {float(c): float(motor_volts(c, params)) for c in commands_v}


@dataclass(frozen=True)
class SeedDeterminism:
    """Two rigs (noise on) run the same 300-tick programme (start at x = 0.1 m, θ = 0.02 rad; command
    2.5 + 0.5·sin(t) V) with the same seed and with another."""

    same_seed_identical: bool  # every time, ball and angle reading
    other_seed_ball_differs: bool
    other_seed_angle_identical: bool  # the angle channel has no random source


def _rig_readings(params: Parameters, seed: int, ticks: int = 300) -> np.ndarray:
    rig = TwinRig(params, seed=seed)
    rig.reset(x_m=0.1, theta_rad=0.02)
    out = []
    for _ in range(ticks):
        s = rig.read()
        rig.write(2.5 + 0.5 * np.sin(s.time_s))
        out.append((s.time_s, s.ball_v, s.angle_v))
    return np.array(out)


def seed_determinism(params: Parameters, seed: int = 11, other_seed: int = 12) -> SeedDeterminism:
    a, b, c = _rig_readings(params, seed), _rig_readings(params, seed), _rig_readings(params, other_seed)
    return SeedDeterminism(
        same_seed_identical=bool(np.array_equal(a, b)),
        other_seed_ball_differs=not np.array_equal(a[:, 1], c[:, 1]),
        other_seed_angle_identical=bool(np.array_equal(a[:, 2], c[:, 2])),
    )


def log_mismatches(a: RunLog, b: RunLog) -> list[str]:
    """The fields in which two logs differ: dtype, shape or any bit (NaN included), and ``k``."""
    bad = []
    for f in fields(RunLog):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if x.dtype != y.dtype or x.shape != y.shape:
            bad.append(f.name)
        elif x.dtype == bool:
            if not np.array_equal(x, y):
                bad.append(f.name)
        elif not np.array_equal(x.view(np.uint64), y.view(np.uint64)):
            bad.append(f.name)
    if a.k != b.k:
        bad.append("k")
    return bad


def mat_round_trip_mismatches(log: RunLog, folder: Path | None = None) -> list[str]:
    """Save ``log`` as data_file.mat (in ``folder``, else a temporary one), load it back: what differs."""
    if folder is None:
        with tempfile.TemporaryDirectory() as tmp:
            return mat_round_trip_mismatches(log, Path(tmp))
    path = Path(folder) / "data_file.mat"
    save_mat(log, path)
    return log_mismatches(log, load_mat(path))
