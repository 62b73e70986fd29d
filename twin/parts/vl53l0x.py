"""The VL53L0X time-of-flight ball sensor (ST VL53L0X, read over I²C): its parameter group ``vl53l0x``, its
equations, its chain (one run and a batch), its MJCF fragment (the housing drawn at the +x end of the beam) and
its ``BallSensorPart``, registered as ``vl53l0x``.

The sensor sits at ``mount_x_m`` on the beam and ranges along it toward −x, continuously back to back: a new
range every timing budget, the mean distance to the ball's near surface over that budget, plus noise whose
standard deviation grows with the distance (never below a floor), less a cover glass's crosstalk offset. Off a
round ball the return is weak: with a probability per range the sensor ranges the background beyond the ball
instead. No target within range (the ball gone, the background too far) reads ``OUT_OF_RANGE_MM``. The board reads
the last range in whole millimetres (what ``VL53L0X_GetRangingMeasurementData`` returns in ``RangeMilliMeter``).

A MEASURED CURVE (``curve_distance_mm``/``curve_reading_mm``, a ruler table's true distances and mean readings;
empty by default) replaces "distance less the crosstalk" for the ball: off a round ball a VL53L0X reads neither
the distance nor the distance less an offset (Open Ball & Beam's table reads 14 mm long at 14 mm and 93 mm long
at 196 mm). The curve is interpolated piecewise linearly between its points and extended beyond its ends along
its end segments (``vl53l0x_curve_mm``): it passes through every measured mean, it is monotone wherever the
table is, and its inverse (the software's conversion, ``vl53l0x_position_of``) is the same broken line read the
other way, exact and in closed form. A monotone cubic (PCHIP) would pass the points too, but its inverse is no
cubic of the same kind (a root to solve per reading); on Open Ball & Beam's 18 points it predicts a left-out
point 1.56 mm RMS against the broken line's 1.77 mm, both well under one reading's 2.6 mm.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.parameters import ParameterError, Parameters, check_group, curve, param, register_group
from twin.parts.contract import BallSensorPart, BatchForm, MjcfFragment, fixed_unit, register
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
    "OUT_OF_RANGE_MM",
    "SIGMA_BUDGET_S",
    "VL53L0X",
    "Vl53l0x",
    "Vl53l0xBatch",
    "Vl53l0xChain",
    "apply_vl53l0x",
    "vl53l0x_curve_mm",
    "vl53l0x_position_of",
    "vl53l0x_range_mm",
    "vl53l0x_sigma_mm",
]

# What the ST API (and the Pololu and Adafruit libraries after it) reports when no target is found: the range
# register's 8190 mm (pololu/vl53l0x-arduino issue #28: "8190 means out of range").
OUT_OF_RANGE_MM = 8190.0
# The timing budget the ranging accuracy below is stated for (the data sheet's 33 ms default).
SIGMA_BUDGET_S = 0.033

HOUSING = "vl53l0x_housing"
APERTURE = "vl53l0x_aperture"
# The breakout board's size (GY-530 style carrier, 25 × 10.7 mm, about 3 mm deep with the module): drawn only.
_HOUSING_HALF_M = (0.0015, 0.00535, 0.0125)


@dataclass(frozen=True)
class Vl53l0x:
    """The VL53L0X's mounting and its data-sheet numbers (ST VL53L0X data sheet, DocID029104)."""

    mount_x_m: float = param(
        0.333,
        "m",
        "assumed: on the beam 10 mm beyond the track's +x end (track.half_length_m = 0.323 m), its aperture at "
        "the ball's centre height, looking along the beam toward −x",
        ge=-10.0,
        le=10.0,
        why="a position on a bench-top beam at most 10 m long",
    )
    timing_budget_s: float = param(
        0.033,
        "s",
        "data sheet, ranging profiles table: 33 ms, the long-range profile's budget (20 ms high speed, 200 ms "
        "high accuracy); in continuous back-to-back ranging a new range completes every budget",
        ge=0.020,
        le=1.0,
        why="the data sheet's shortest budget is 20 ms (high-speed profile); a range a second cannot follow a "
        "rolling ball",
    )
    sigma_fraction: float = param(
        0.04,
        "-",
        "assumed (not confirmed against a copy of ST's DocID029104): its ranging-accuracy table as commonly "
        "quoted, 4 % at 120 cm for a white target indoors at the 33 ms budget, taken as one standard deviation "
        "proportional to the distance; fit it from a log (Open Ball & Beam measured 2-3 mm at 3-20 cm)",
        ge=0.0,
        le=0.5,
        why="a range whose standard deviation is half the distance carries no position",
    )
    sigma_floor_mm: float = param(
        0.0,
        "mm",
        "assumed: none (0 mm: the proportional law alone). A range's standard deviation is never below it: "
        "σ = max(floor, k·d·√(33 ms/budget)); Open Ball & Beam's table (ballbeam/calibration/"
        "sensor_calibration_data.txt) shows 1.8-3.1 mm over 14-196 mm, no growth: fit it from a ruler table "
        "(calibrate-static --sensor vl53l0x); it is the floor at the rig's budget, not scaled with the budget",
        ge=0.0,
        le=100.0,
        why="a floor of 10 cm on a bench-top beam's ranges carries no position",
    )
    curve_distance_mm: tuple[float, ...] = curve(
        (),
        "mm",
        "assumed: none (the law range = distance − crosstalk). A measured curve's true distances, sensor face to "
        "the ball's near surface, strictly increasing, from a ruler table (calibrate-static --sensor vl53l0x)",
        magnitude=2000.0,
        why="the data sheet's range is at most 2 m",
        optional=True,
    )
    curve_reading_mm: tuple[float, ...] = curve(
        (),
        "mm",
        "assumed: none. The measured curve's mean reading (mm, as the board reads it) at each of "
        "curve_distance_mm, strictly increasing (the software inverts it)",
        magnitude=8190.0,
        why="a range register holds at most 8190 mm (the out-of-range code)",
        optional=True,
    )
    crosstalk_offset_mm: float = param(
        0.0,
        "mm",
        "assumed: no cover glass (0 mm); a cover glass whose crosstalk is not compensated (data sheet, features: "
        "'embedded optical cross-talk compensation') shortens every range by it; set from a ruler",
        ge=-100.0,
        le=100.0,
        why="a crosstalk that moves ranges by more than 10 cm is a cover glass in front of nothing useful",
    )
    wrong_return_probability: float = param(
        0.02,
        "-",
        "assumed: the chance per range that the return off the round ball (a small part of the 25° field of "
        "view) loses to the background beyond it; fit from a log",
        ge=0.0,
        le=1.0,
        why="a probability",
    )
    background_mm: float = param(
        2000.0,
        "mm",
        "assumed: nothing behind the track within range (the room's wall 2 m away), so a wrong return and "
        "the ball gone read the out-of-range code; a wall within range reads its distance",
        ge=0.0,
        le=10000.0,
        why="a room's wall within 10 m",
    )
    max_range_mm: float = param(
        1200.0,
        "mm",
        "assumed (not confirmed against a copy of ST's DocID029104): its maximum range as commonly quoted, "
        "120 cm for a white target (88 %) indoors at the 33 ms budget (the data sheet's front page: up to 2 m)",
        gt=0.0,
        le=2000.0,
        why="the data sheet's range is at most 2 m",
    )

    def __post_init__(self) -> None:
        check_group(self, "vl53l0x")
        d, r = self.curve_distance_mm, self.curve_reading_mm
        if len(d) != len(r):
            raise ParameterError(
                f"vl53l0x.curve_reading_mm has {len(r)} values but vl53l0x.curve_distance_mm has {len(d)}: one "
                "mean reading per distance"
            )
        if d and d[0] < 0.0:
            raise ParameterError(
                f"vl53l0x.curve_distance_mm[0] = {d[0]!r} mm is impossible: it must be >= 0.0 (a distance from "
                "the sensor's face)"
            )
        for name, values in (("curve_distance_mm", d), ("curve_reading_mm", r)):
            for i in range(1, len(values)):
                if not values[i] > values[i - 1]:
                    raise ParameterError(
                        f"vl53l0x.{name}[{i}] = {values[i]!r} mm is impossible: it must increase strictly "
                        f"(previous {values[i - 1]!r} mm): the reading must grow with the distance, or the "
                        "software cannot read a distance back from it"
                    )

    @property
    def has_curve(self) -> bool:
        """A measured curve is set (else the law range = distance − crosstalk holds)."""
        return len(self.curve_distance_mm) > 0


register_group("vl53l0x", Vl53l0x)


def vl53l0x_sigma_mm(
    distance_mm: np.ndarray,
    sigma_fraction: np.ndarray | float,
    budget_s: np.ndarray | float,
    floor_mm: np.ndarray | float = 0.0,
) -> np.ndarray:
    """The standard deviation of one range (mm): σ = max(σ₀, k·d·√(B₀/B)), an accuracy k at the budget
    B₀ = 33 ms proportional to the distance d, and to 1/√B: a range averages the photons of its budget B, whose
    count grows with B (photon statistics); never below the floor σ₀ (``sigma_floor_mm``: what a short range
    shows, measured, not predicted by the proportional law). With σ₀ = 0 it is the proportional law exactly."""
    return np.maximum(floor_mm, sigma_fraction * distance_mm * np.sqrt(SIGMA_BUDGET_S / budget_s))


def _broken_line(x: np.ndarray, knots: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The broken line through (knots, values) at x: on the segment [k_j, k_j+1] holding x (the first or last
    segment beyond the ends), (1 − t)·v_j + t·v_j+1 with t = (x − k_j)/(k_j+1 − k_j); this form is exact at
    both of a segment's knots (t = 0 and t = 1 give v_j and v_j+1 bit for bit)."""
    j = np.clip(np.searchsorted(knots, x, side="right") - 1, 0, knots.size - 2)
    k0, k1 = knots[j], knots[j + 1]
    t = (x - k0) / (k1 - k0)
    return (1.0 - t) * values[j] + t * values[j + 1]


def _broken_line_at(x: float, knots: list[float], values: list[float]) -> float:
    """``_broken_line`` at one float, in plain Python for a controller's tick (the same operations in the same
    order on IEEE doubles: the same bits)."""
    j = min(max(bisect.bisect_right(knots, x) - 1, 0), len(knots) - 2)
    k0, k1 = knots[j], knots[j + 1]
    t = (x - k0) / (k1 - k0)
    return (1.0 - t) * values[j] + t * values[j + 1]


def vl53l0x_curve_mm(
    distance_mm: np.ndarray, curve_distance_mm: Sequence[float], curve_reading_mm: Sequence[float]
) -> np.ndarray:
    """The measured curve's mean reading (mm) at the true distance ``distance_mm`` (sensor face to the ball's
    near surface): piecewise linear between the curve's points, and beyond its ends along its first or last
    segment (module docstring)."""
    return _broken_line(
        np.asarray(distance_mm, dtype=float),
        np.asarray(curve_distance_mm, dtype=float),
        np.asarray(curve_reading_mm, dtype=float),
    )


def vl53l0x_range_mm(
    distance_mm: np.ndarray,
    z: np.ndarray,
    wrong: np.ndarray,
    present: np.ndarray,
    *,
    sigma_fraction: np.ndarray | float,
    budget_s: np.ndarray | float,
    crosstalk_mm: np.ndarray | float,
    background_mm: np.ndarray | float,
    max_range_mm: np.ndarray | float,
    sigma_floor_mm: np.ndarray | float = 0.0,
    curve_mm: np.ndarray | None = None,
) -> np.ndarray:
    """One range as the board reads it (whole mm): the target is the ball's near surface at ``distance_mm`` (its
    mean over the budget), or the background at ``background_mm`` for a wrong return or when the ball is not
    there; the range is target − crosstalk + σ(target)·z (``vl53l0x_sigma_mm``, z a standard normal draw),
    rounded to the millimetre and never below 0; a target beyond ``max_range_mm`` reads ``OUT_OF_RANGE_MM``.
    ``curve_mm``: the measured curve's reading at ``distance_mm`` (``vl53l0x_curve_mm``; NaN for a run without
    one): where finite it replaces target − crosstalk for the ball (the curve holds the cover's crosstalk as
    measured); the background, a flat wall, still reads its distance less the crosstalk."""
    target = np.where(wrong | ~present, background_mm, distance_mm)
    sigma = vl53l0x_sigma_mm(target, sigma_fraction, budget_s, sigma_floor_mm)
    level = target - crosstalk_mm
    if curve_mm is not None:
        level = np.where(~(wrong | ~present) & np.isfinite(curve_mm), curve_mm, level)
    ranged = np.maximum(np.rint(level + sigma * z), 0.0)
    return np.where(target > max_range_mm, OUT_OF_RANGE_MM, ranged)


class _Sampler:
    """The VL53L0X over N runs (``twin.parts.ranging.Sampler``): two draws per range, in order, from the run's
    generator: a uniform (the wrong return) and a standard normal (the noise); with ``ball_sensor.noise_enabled``
    off (the rig's noise switch) the draws are made and their effects dropped."""

    def __init__(self, params: Sequence[Parameters], rngs: Sequence[np.random.Generator]) -> None:
        self.rngs = list(rngs)
        self.use_params(params)

    def use_params(self, params: Sequence[Parameters]) -> None:
        groups = [p.of(Vl53l0x) for p in params]
        self.mount_x_m = np.array([g.mount_x_m for g in groups])
        self.period_s = np.array([g.timing_budget_s for g in groups])
        self.sigma_fraction = np.array([g.sigma_fraction for g in groups])
        self.crosstalk_mm = np.array([g.crosstalk_offset_mm for g in groups])
        self.sigma_floor_mm = np.array([g.sigma_floor_mm for g in groups])
        # The runs' measured curves: each distinct curve once (runs of a batch mostly share one), and each
        # run's index into them (−1: no curve, the law distance − crosstalk)
        self.curves: list[tuple[np.ndarray, np.ndarray]] = []
        index: dict[tuple[tuple[float, ...], tuple[float, ...]], int] = {}
        which = []
        for g in groups:
            if not g.has_curve:
                which.append(-1)
                continue
            key = (g.curve_distance_mm, g.curve_reading_mm)
            if key not in index:
                index[key] = len(self.curves)
                self.curves.append((np.array(key[0]), np.array(key[1])))
            which.append(index[key])
        self.curve_of = np.array(which, dtype=np.int64)
        self.wrong_probability = np.array([g.wrong_return_probability for g in groups])
        self.background_mm = np.array([g.background_mm for g in groups])
        self.max_range_mm = np.array([g.max_range_mm for g in groups])
        self.radius_m = np.array([p.ball.radius_m for p in params])
        self.half_length_m = np.array([p.track.half_length_m for p in params])
        self.noisy = np.array([p.ball_sensor.noise_enabled for p in params])

    def sample(
        self, rows: np.ndarray, x_mean_m: np.ndarray, x_m: np.ndarray, present: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        order = rows.tolist()
        u = np.array([self.rngs[i].random() for i in order])
        z = np.array([self.rngs[i].standard_normal() for i in order])
        noisy = self.noisy[rows]
        wrong = noisy & (u < self.wrong_probability[rows]) & present
        distance_mm = 1000.0 * near_distance_m(self.mount_x_m[rows], x_mean_m, self.radius_m[rows])
        ranges = vl53l0x_range_mm(
            distance_mm,
            np.where(noisy, z, 0.0),
            wrong,
            present,
            sigma_fraction=self.sigma_fraction[rows],
            budget_s=self.period_s[rows],
            crosstalk_mm=self.crosstalk_mm[rows],
            background_mm=self.background_mm[rows],
            max_range_mm=self.max_range_mm[rows],
            sigma_floor_mm=self.sigma_floor_mm[rows],
            curve_mm=self._curve_mm(rows, distance_mm),
        )
        return ranges, np.zeros(len(order)), wrong

    def _curve_mm(self, rows: np.ndarray, distance_mm: np.ndarray) -> np.ndarray | None:
        """The measured curve at each row's distance (NaN for a run without one), or None when no run has one;
        each value is its own row's arithmetic alone (``vl53l0x_curve_mm``), so a run reads the same bits alone
        or in a batch."""
        which = self.curve_of[rows]
        if not np.any(which >= 0):
            return None
        out = np.full(distance_mm.shape, np.nan)
        for c in np.unique(which[which >= 0]).tolist():
            on = which == c
            knots, readings = self.curves[c]
            out[on] = vl53l0x_curve_mm(distance_mm[on], knots, readings)
        return out

    def reading(self, rows: np.ndarray, output: np.ndarray) -> np.ndarray:
        return output  # the range in whole mm is what the board reads over I²C


class Vl53l0xBatch(SensorBatch):
    """N runs of the VL53L0X in step (``twin.parts.ranging.SampledBatch``), each with its own seed and parameters
    (any of the ``vl53l0x`` group's, the ball's radius, the track's length)."""

    @classmethod
    def make_sampler(cls, runs: list[Parameters], rngs: list[np.random.Generator]) -> Sampler:
        return _Sampler(runs, rngs)


class Vl53l0xChain(SampledChain):
    """One run of the VL53L0X (``twin.parts.contract.BallSensorChain``): ``reading_v`` the last range in whole
    mm (``OUT_OF_RANGE_MM`` for none), ``filtered_v`` the same (the sensor's output is digital)."""

    def __init__(
        self, params: Parameters, seed: int | np.random.Generator | None, *, x_m: float = 0.0
    ) -> None:
        super().__init__(params, seed, Vl53l0xBatch.one, x_m=x_m)


def apply_vl53l0x(spec: mujoco.MjSpec, p: Parameters) -> None:
    """Adds the sensor's housing (drawn only) and a site at its aperture to the beam at ``mount_x_m``
    (``twin.parts.ranging.add_housing``)."""
    add_housing(spec, p, p.of(Vl53l0x).mount_x_m, (HOUSING, APERTURE), _HOUSING_HALF_M, (0.1, 0.1, 0.45, 1.0))


def _chain(params: Parameters, seed: int) -> Vl53l0xChain:
    return Vl53l0xChain(params, seed)


# Disturbances often enough that a few of a batch form's runs hold one, and a background within range.
_NOISY = Parameters().with_overrides(
    {"vl53l0x.wrong_return_probability": 0.3, "vl53l0x.background_mm": 800.0}
)


def vl53l0x_position_of(params: Parameters) -> Callable[[float], float]:
    """The software's conversion: a range (mm) → x = mount − r − d/1000, d the distance the range's nominal law
    gives it (``vl53l0x_range_mm`` without noise): d = range + crosstalk, or with a measured curve the curve read
    backwards (the same broken line from reading to distance, extended along its end segments: its exact
    inverse, as a sketch's lookup table is; Open Ball & Beam's own sketch fits a degree-5 polynomial to the same
    points instead, within 1.4 mm of them); NaN for the out-of-range code."""
    s, r = params.of(Vl53l0x), params.ball.radius_m
    readings, distances = list(s.curve_reading_mm), list(s.curve_distance_mm)

    def x_m(reading_mm: float) -> float:
        if reading_mm >= OUT_OF_RANGE_MM:
            return math.nan
        if s.has_curve:
            d = _broken_line_at(float(reading_mm), readings, distances)
            return s.mount_x_m - r - d / 1000.0
        return s.mount_x_m - r - (reading_mm + s.crosstalk_offset_mm) / 1000.0

    return x_m


VL53L0X = register(
    BallSensorPart(
        name="vl53l0x",
        source="ST VL53L0X data sheet (DocID029104): up to 2 m, the timing budget (20 ms minimum, 33 ms "
        "default); 8190 mm for no target (the ST API, as the Pololu library reports it); its accuracy and range "
        "figures and the wrong returns off a round ball assumed (fit from a log); a measured curve and a noise "
        "floor from a ruler table where set (Open Ball & Beam's sensor_calibration_data.txt in its preset)",
        groups={"vl53l0x": Vl53l0x},
        equations=(
            vl53l0x_sigma_mm,
            vl53l0x_curve_mm,
            vl53l0x_range_mm,
            near_distance_m,
            Vl53l0xChain,
            Vl53l0xBatch,
        ),
        mjcf=MjcfFragment((("geom", HOUSING), ("site", APERTURE)), apply_vl53l0x),
        batch=BatchForm(
            form_single(_chain),
            form_batch(Vl53l0xBatch),
            form_inputs(
                _NOISY,
                ("vl53l0x.timing_budget_s", "vl53l0x.sigma_fraction", "vl53l0x.mount_x_m", "ball.radius_m"),
            ),
            "twin.parts.vl53l0x.Vl53l0xBatch",
        ),
        chain=_chain,
        batch_chain=Vl53l0xBatch,
        position_of=vl53l0x_position_of,
        reading_unit=fixed_unit("mm"),  # RangeMilliMeter over I²C
    )
)
