"""The Sharp GP2Y0A21YK0F infrared ball sensor (analog volts read by the board's ADC): its parameter group
``gp2y0a21``, its equations, its chain (one run and a batch), its MJCF fragment (the housing drawn at the +x end
of the beam) and its ``BallSensorPart``, registered as ``gp2y0a21``.

The sensor sits at ``mount_x_m`` on the beam, looking along it toward −x. It triangulates: its output volts fall
with the distance d to the ball's near surface as the data sheet's typical characteristic, an inverse-distance
curve a/(d + b) + c over its 10–80 cm range; closer than ``fold_distance_m`` (about 6 cm) the reflected spot
leaves its detector and the volts fall again (the fold: a near ball reads like a far one). It measures once per
update period and holds its output in between, with noise on each update. With no ball on the track it sees the
background beyond: the curve's far-range level there. The board reads the volts with its ADC (the I/O board
part's ``adc``: the PCI-1712's volts, an Arduino's ``analogRead`` counts).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.parameters import Parameters, check_group, param, register_group
from twin.parts.contract import (
    BallSensorPart,
    BatchForm,
    MjcfFragment,
    board_adc,
    board_volts_of,
    register,
)
from twin.parts.ranging import (
    SampledChain,
    Sampler,
    SensorBatch,
    add_housing,
    form_batch,
    form_inputs,
    form_single,
    near_distance_m,
)

__all__ = [
    "GP2Y0A21",
    "Gp2y0a21",
    "Gp2y0a21Batch",
    "Gp2y0a21Chain",
    "apply_gp2y0a21",
    "gp2y0a21_volts",
]

HOUSING = "gp2y0a21_housing"
APERTURE = "gp2y0a21_aperture"
# The sensor's case (data sheet outline: 29.5 mm across the lenses, 13 mm high, 13.5 mm deep): drawn only.
_HOUSING_HALF_M = (0.00675, 0.01475, 0.0065)
_FIT = "fit (least squares) of a/(d + b) + c to the data sheet's Fig. 2 (white paper, 90 %) read at 10, 20, …, 80 cm"


@dataclass(frozen=True)
class Gp2y0a21:
    """The GP2Y0A21YK0F's mounting and its data sheet's numbers (Sharp GP2Y0A21YK0F data sheet)."""

    mount_x_m: float = param(
        0.333,
        "m",
        "assumed: on the beam 10 mm beyond the track's +x end (track.half_length_m = 0.323 m), its lenses at the "
        "ball's centre height, looking along the beam toward −x (the last ~6 cm of the track lie in the fold)",
        ge=-10.0,
        le=10.0,
        why="a position on a bench-top beam at most 10 m long",
    )
    curve_a_v_m: float = param(
        0.2847360505,
        "V·m",
        f"{_FIT}: 2.25, 1.30, 0.90, 0.75, 0.60, 0.50, 0.45, 0.40 V; rms residual 0.013 V, largest 0.029 V",
        gt=0.0,
        le=10.0,
        why="a triangulation sensor's curve: 10 V·m is 100 V at 10 cm, beyond any 5 V sensor",
    )
    curve_b_m: float = param(
        0.0299884788,
        "m",
        f"{_FIT}: the distance offset of the inverse curve",
        ge=-0.05,
        le=0.5,
        why="an offset beyond −5 cm puts the curve's pole inside the measuring range",
    )
    curve_c_v: float = param(
        0.0592608702,
        "V",
        f"{_FIT}: the level the curve falls to far away",
        ge=-5.0,
        le=5.0,
        why="within the sensor's 0…5 V supply",
    )
    fold_distance_m: float = param(
        0.06,
        "m",
        "data sheet Fig. 2: the output peaks near 6 cm (3.2 V on the fit) and falls below it; modelled as a "
        "straight line from the peak to 0 V at 0 cm (assumed: the figure's falling flank)",
        gt=0.0,
        le=0.1,
        why="the data sheet's measuring range starts at 10 cm: the fold lies below it",
    )
    update_period_s: float = param(
        0.0383,
        "s",
        "data sheet timing chart: one distance measurement every 38.3 ms ± 9.6 ms (a sensor's own period "
        "within that range), the output held until the next",
        ge=0.0287,
        le=0.0479,
        why="the data sheet's 38.3 ± 9.6 ms",
    )
    noise_v: float = param(
        0.01,
        "V",
        "assumed: 10 mV standard deviation on each update's output; fit from a log",
        ge=0.0,
        le=1.0,
        why="noise of 1 V is a third of the whole curve",
    )
    background_m: float = param(
        1.0,
        "m",
        "assumed: a wall 1 m from the sensor behind the track, which it sees when the ball is gone (the curve's "
        "far-range level there, 0.34 V on the fit)",
        gt=0.0,
        le=10.0,
        why="a room's wall within 10 m",
    )

    def __post_init__(self) -> None:
        check_group(self, "gp2y0a21")


register_group("gp2y0a21", Gp2y0a21)


def gp2y0a21_volts(
    distance_m: np.ndarray,
    *,
    a_v_m: np.ndarray | float,
    b_m: np.ndarray | float,
    c_v: np.ndarray | float,
    fold_m: np.ndarray | float,
) -> np.ndarray:
    """The output volts with the object at ``distance_m`` (typical, noiseless): a/(d + b) + c from the fold's
    distance out (the data sheet's inverse-distance characteristic: triangulation makes the spot's offset on the
    detector, hence the volts, grow as 1/d), and below the fold a straight line from the peak (its value at the
    fold) down to 0 V at 0 m: the reflected spot walks off the detector and the volts fall again."""
    d = np.asarray(distance_m, dtype=float)
    peak_v = a_v_m / (fold_m + b_m) + c_v
    return np.where(d < fold_m, peak_v * (d / fold_m), a_v_m / (d + b_m) + c_v)


class _Sampler:
    """The GP2Y0A21YK0F over N runs (``twin.parts.ranging.Sampler``): one standard normal draw per update from
    the run's generator (the noise); with ``ball_sensor.noise_enabled`` off (the rig's noise switch) the draw is
    made and dropped. The reading is each run's board's ADC (``IoBoardPart.adc``)."""

    def __init__(self, params: Sequence[Parameters], rngs: Sequence[np.random.Generator]) -> None:
        self.rngs = list(rngs)
        self.use_params(params)

    def use_params(self, params: Sequence[Parameters]) -> None:
        groups = [p.of(Gp2y0a21) for p in params]
        self.mount_x_m = np.array([g.mount_x_m for g in groups])
        self.period_s = np.array([g.update_period_s for g in groups])
        self.a_v_m = np.array([g.curve_a_v_m for g in groups])
        self.b_m = np.array([g.curve_b_m for g in groups])
        self.c_v = np.array([g.curve_c_v for g in groups])
        self.fold_m = np.array([g.fold_distance_m for g in groups])
        self.noise_v = np.array([g.noise_v for g in groups])
        self.background_m = np.array([g.background_m for g in groups])
        self.radius_m = np.array([p.ball.radius_m for p in params])
        self.half_length_m = np.array([p.track.half_length_m for p in params])
        self.noisy = np.array([p.ball_sensor.noise_enabled for p in params])
        self.adc: list[Callable[[float], float]] = [board_adc(p) for p in params]

    def sample(
        self, rows: np.ndarray, x_mean_m: np.ndarray, x_m: np.ndarray, present: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        order = rows.tolist()
        z = np.array([self.rngs[i].standard_normal() for i in order])
        d = near_distance_m(self.mount_x_m[rows], x_m, self.radius_m[rows])
        d = np.where(present, d, self.background_m[rows])
        volts = gp2y0a21_volts(
            d, a_v_m=self.a_v_m[rows], b_m=self.b_m[rows], c_v=self.c_v[rows], fold_m=self.fold_m[rows]
        )
        volts = volts + np.where(self.noisy[rows], self.noise_v[rows] * z, 0.0)
        return volts, np.zeros(len(order)), np.zeros(len(order), dtype=bool)

    def reading(self, rows: np.ndarray, output: np.ndarray) -> np.ndarray:
        return np.array([self.adc[i](v) for i, v in zip(rows.tolist(), output.tolist(), strict=True)])


class Gp2y0a21Batch(SensorBatch):
    """N runs of the GP2Y0A21YK0F in step (``twin.parts.ranging.SampledBatch``), each with its own seed and
    parameters (any of the ``gp2y0a21`` group's, the ball's radius, the track's length, the board)."""

    @classmethod
    def make_sampler(cls, runs: list[Parameters], rngs: list[np.random.Generator]) -> Sampler:
        return _Sampler(runs, rngs)


class Gp2y0a21Chain(SampledChain):
    """One run of the GP2Y0A21YK0F (``twin.parts.contract.BallSensorChain``): ``reading_v`` the board's ADC
    reading of the output held at the block's end, ``filtered_v`` the output volts at the pin now."""

    def __init__(
        self, params: Parameters, seed: int | np.random.Generator | None, *, x_m: float = 0.0
    ) -> None:
        super().__init__(params, seed, Gp2y0a21Batch.one, x_m=x_m)


def apply_gp2y0a21(spec: mujoco.MjSpec, p: Parameters) -> None:
    """Adds the sensor's case (drawn only) and a site at its lenses to the beam at ``mount_x_m``
    (``twin.parts.ranging.add_housing``)."""
    add_housing(spec, p, p.of(Gp2y0a21).mount_x_m, (HOUSING, APERTURE), _HOUSING_HALF_M, (0.2, 0.2, 0.2, 1.0))


def _chain(params: Parameters, seed: int) -> Gp2y0a21Chain:
    return Gp2y0a21Chain(params, seed)


def gp2y0a21_position_of(params: Parameters) -> Callable[[float], float]:
    """The software's conversion: the board's reading → volts (its ``volts_of``) → d = a/(V − c) − b, the far
    branch of ``gp2y0a21_volts`` (a sketch cannot tell the fold's near branch from it) → x = mount − r − d; NaN
    at or below the curve's asymptote c."""
    s, r = params.of(Gp2y0a21), params.ball.radius_m
    volts_of = board_volts_of(params)

    def x_m(reading: float) -> float:
        v = volts_of(reading)
        if v <= s.curve_c_v:
            return math.nan
        return s.mount_x_m - r - (s.curve_a_v_m / (v - s.curve_c_v) - s.curve_b_m)

    return x_m


GP2Y0A21 = register(
    BallSensorPart(
        name="gp2y0a21",
        source="Sharp GP2Y0A21YK0F data sheet: Fig. 2 typical output against distance (10–80 cm, fitted), the "
        "fold below ~6 cm, the timing chart's 38.3 ± 9.6 ms; noise assumed (fit from a log)",
        groups={"gp2y0a21": Gp2y0a21},
        equations=(gp2y0a21_volts, near_distance_m, Gp2y0a21Chain, Gp2y0a21Batch),
        mjcf=MjcfFragment((("geom", HOUSING), ("site", APERTURE)), apply_gp2y0a21),
        batch=BatchForm(
            form_single(_chain),
            form_batch(Gp2y0a21Batch),
            form_inputs(
                Parameters(),
                ("gp2y0a21.update_period_s", "gp2y0a21.noise_v", "gp2y0a21.mount_x_m", "gp2y0a21.curve_c_v"),
            ),
            "twin.parts.gp2y0a21.Gp2y0a21Batch",
        ),
        chain=_chain,
        batch_chain=Gp2y0a21Batch,
        position_of=gp2y0a21_position_of,
    )
)
