"""The HC-SR04 ultrasonic ball sensor (echo pulse timed by the board's ``pulseIn``): its parameter group
``hcsr04``, its equations, its chain (one run and a batch), its MJCF fragment (the housing drawn at the +x end of
the beam) and its ``BallSensorPart``, registered as ``hcsr04``.

The sensor sits at ``mount_x_m`` on the beam, its transducers facing −x along it. Every measurement cycle the
board triggers it; the module sends its 40 kHz burst and raises its echo line until the echo returns, so the
echo's width is the sound's round trip to the ball's near surface and back, 2·d/c, with the speed of sound
c(T) = 331.3·√(1 + T/273.15) m/s at the air's temperature T (°C). ``pulseIn`` returns the width in whole µs when
the echo ends. An echo may be lost (``pulseIn`` times out and returns 0) or come early off something nearer (a
spurious echo); with no ball on the track, or a ball beyond range, there is no echo: 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.parameters import ParameterError, Parameters, check_group, param, register_group
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
    "HCSR04",
    "Hcsr04",
    "Hcsr04Batch",
    "Hcsr04Chain",
    "apply_hcsr04",
    "hcsr04_echo_us",
    "speed_of_sound_m_s",
]

HOUSING = "hcsr04_housing"
APERTURE = "hcsr04_aperture"
# The module's size (user guide: 45 × 20 × 15 mm), the 45 mm across the beam: drawn only.
_HOUSING_HALF_M = (0.0075, 0.0225, 0.010)


@dataclass(frozen=True)
class Hcsr04:
    """The HC-SR04's mounting, its user guide's numbers and the disturbances of its echoes (ElecFreaks HC-SR04
    user guide)."""

    mount_x_m: float = param(
        0.333,
        "m",
        "assumed: on the beam 10 mm beyond the track's +x end (track.half_length_m = 0.323 m), its transducers "
        "at the ball's centre height, facing −x along the beam",
        ge=-10.0,
        le=10.0,
        why="a position on a bench-top beam at most 10 m long",
    )
    temperature_c: float = param(
        20.0,
        "°C",
        "assumed: a room at 20 °C (c = 343.2 m/s); the speed of sound c(T) = 331.3·√(1 + T/273.15) m/s",
        ge=-40.0,
        le=85.0,
        why="air on a lab bench, within the range a hobby module survives",
    )
    cycle_s: float = param(
        0.060,
        "s",
        "user guide, timing diagram: 'we suggest to use over 60ms measurement cycle, in order to prevent "
        "trigger signal to the echo signal'; one echo per cycle",
        ge=0.005,
        le=1.0,
        why="a cycle shorter than 5 ms is shorter than the echo of the ball 0.8 m away; one of 1 s cannot follow "
        "a rolling ball",
    )
    pulse_timeout_us: float = param(
        30000.0,
        "µs",
        "assumed: the sketch's pulseIn(echo, HIGH, 30000): an echo longer than this, or none, returns 0 after it",
        gt=0.0,
        le=1e6,
        why="pulseIn's default timeout is 1 s; the timeout must end within the cycle (checked with cycle_s)",
    )
    max_range_m: float = param(
        4.0,
        "m",
        "user guide, electric parameters: Max Range 4m",
        gt=0.0,
        le=10.0,
        why="an ultrasonic module of this kind hears no echo from beyond a few metres",
    )
    min_range_m: float = param(
        0.02,
        "m",
        "user guide, electric parameters: Min Range 2cm (the nearest a spurious echo comes from)",
        ge=0.0,
        le=1.0,
        why="the transducers ring for the first centimetres; 1 m is beyond any beam's end",
    )
    echo_jitter_us: float = param(
        5.0,
        "µs",
        "assumed: the user guide's 0.3 cm resolution as one step of a uniform error (0.6 cm of round trip = "
        "17.5 µs at 343 m/s, standard deviation 17.5/√12 ≈ 5 µs), drawn normal; fit from a log",
        ge=0.0,
        le=1000.0,
        why="a jitter of 1 ms is 17 cm of position: no longer a measurement of the ball",
    )
    lost_echo_probability: float = param(
        0.01,
        "-",
        "assumed: the chance per cycle that the echo off the round ball is too weak to trigger the receiver "
        "(pulseIn returns 0); fit from a log",
        ge=0.0,
        le=1.0,
        why="a probability",
    )
    spurious_echo_probability: float = param(
        0.005,
        "-",
        "assumed: the chance per cycle of an early echo off something nearer than the ball (the beam, the "
        "track's end), from a distance drawn uniformly between min_range_m and the ball; fit from a log",
        ge=0.0,
        le=1.0,
        why="a probability",
    )

    def __post_init__(self) -> None:
        check_group(self, "hcsr04")
        if self.pulse_timeout_us * 1e-6 >= self.cycle_s:
            raise ParameterError(
                f"hcsr04.pulse_timeout_us = {self.pulse_timeout_us!r} µs is impossible: pulseIn must return within "
                f"the measurement cycle hcsr04.cycle_s = {self.cycle_s!r} s, before the next trigger"
            )


register_group("hcsr04", Hcsr04)


def speed_of_sound_m_s(temperature_c: np.ndarray | float) -> np.ndarray:
    """The speed of sound in dry air at ``temperature_c`` (°C): c = 331.3·√(1 + T/273.15) m/s, an ideal gas's
    c ∝ √T_abs from 331.3 m/s at 0 °C."""
    return 331.3 * np.sqrt(1.0 + np.asarray(temperature_c, dtype=float) / 273.15)


def hcsr04_echo_us(
    distance_m: np.ndarray,
    present: np.ndarray,
    z: np.ndarray,
    lost: np.ndarray,
    spurious_at_m: np.ndarray,
    *,
    temperature_c: np.ndarray | float,
    jitter_us: np.ndarray | float,
    max_range_m: np.ndarray | float,
    timeout_us: np.ndarray | float,
) -> tuple[np.ndarray, np.ndarray]:
    """One cycle's echo: (what ``pulseIn`` returns in whole µs, when it returns after the trigger in s). The echo
    comes off the ball's near surface at ``distance_m``, or off ``spurious_at_m`` where that is finite (a
    spurious early echo); its width is the round trip 2·d/c(T) (``speed_of_sound_m_s``) plus a jitter
    (``jitter_us``·z, z a standard normal draw), truncated to whole µs as ``pulseIn`` counts (never below 0);
    ``pulseIn`` returns when the echo ends. No ball (``present`` false), a ball beyond ``max_range_m``, a ``lost``
    echo or one longer than ``timeout_us``: 0, returned at the timeout."""
    d = np.where(np.isfinite(spurious_at_m), spurious_at_m, distance_m)
    width_us = np.maximum(2.0 * d / speed_of_sound_m_s(temperature_c) * 1e6 + jitter_us * z, 0.0)
    silent = lost | ~present | (d > max_range_m) | (width_us > timeout_us)
    echo_us = np.where(silent, 0.0, np.floor(width_us))
    return echo_us, np.where(silent, timeout_us, width_us) * 1e-6


class _Sampler:
    """The HC-SR04 over N runs (``twin.parts.ranging.Sampler``): four draws per cycle, in order, from the run's
    generator: uniforms for the lost echo, the spurious echo and where it comes from, then a standard normal for
    the jitter; with ``ball_sensor.noise_enabled`` off (the rig's noise switch) the draws are made and their
    effects dropped."""

    def __init__(self, params: Sequence[Parameters], rngs: Sequence[np.random.Generator]) -> None:
        self.rngs = list(rngs)
        self.use_params(params)

    def use_params(self, params: Sequence[Parameters]) -> None:
        groups = [p.of(Hcsr04) for p in params]
        self.mount_x_m = np.array([g.mount_x_m for g in groups])
        self.period_s = np.array([g.cycle_s for g in groups])
        self.temperature_c = np.array([g.temperature_c for g in groups])
        self.timeout_us = np.array([g.pulse_timeout_us for g in groups])
        self.max_range_m = np.array([g.max_range_m for g in groups])
        self.min_range_m = np.array([g.min_range_m for g in groups])
        self.jitter_us = np.array([g.echo_jitter_us for g in groups])
        self.lost_probability = np.array([g.lost_echo_probability for g in groups])
        self.spurious_probability = np.array([g.spurious_echo_probability for g in groups])
        self.radius_m = np.array([p.ball.radius_m for p in params])
        self.half_length_m = np.array([p.track.half_length_m for p in params])
        self.noisy = np.array([p.ball_sensor.noise_enabled for p in params])

    def sample(
        self, rows: np.ndarray, x_mean_m: np.ndarray, x_m: np.ndarray, present: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        order = rows.tolist()
        u = np.array([self.rngs[i].random(3) for i in order]).reshape(len(order), 3)
        z = np.array([self.rngs[i].standard_normal() for i in order])
        noisy = self.noisy[rows]
        d = near_distance_m(self.mount_x_m[rows], x_m, self.radius_m[rows])
        lost = noisy & (u[:, 0] < self.lost_probability[rows])
        nearest = np.minimum(self.min_range_m[rows], d)
        early = noisy & ~lost & present & (u[:, 1] < self.spurious_probability[rows])
        spurious_at = np.where(early, nearest + u[:, 2] * (d - nearest), np.inf)
        echo_us, delay_s = hcsr04_echo_us(
            d,
            present,
            np.where(noisy, z, 0.0),
            lost,
            spurious_at,
            temperature_c=self.temperature_c[rows],
            jitter_us=self.jitter_us[rows],
            max_range_m=self.max_range_m[rows],
            timeout_us=self.timeout_us[rows],
        )
        return echo_us, delay_s, lost | early

    def reading(self, rows: np.ndarray, output: np.ndarray) -> np.ndarray:
        return output  # pulseIn's whole µs is what the board reads


class Hcsr04Batch(SensorBatch):
    """N runs of the HC-SR04 in step (``twin.parts.ranging.SampledBatch``), each with its own seed and parameters
    (any of the ``hcsr04`` group's, the ball's radius, the track's length)."""

    @classmethod
    def make_sampler(cls, runs: list[Parameters], rngs: list[np.random.Generator]) -> Sampler:
        return _Sampler(runs, rngs)


class Hcsr04Chain(SampledChain):
    """One run of the HC-SR04 (``twin.parts.contract.BallSensorChain``): ``reading_v`` the last echo's width in
    whole µs (0 for none), ``filtered_v`` the same (the board times the echo: it reads no analog level)."""

    def __init__(
        self, params: Parameters, seed: int | np.random.Generator | None, *, x_m: float = 0.0
    ) -> None:
        super().__init__(params, seed, Hcsr04Batch.one, x_m=x_m)


def apply_hcsr04(spec: mujoco.MjSpec, p: Parameters) -> None:
    """Adds the module (drawn only) and a site at its transducers to the beam at ``mount_x_m``
    (``twin.parts.ranging.add_housing``)."""
    add_housing(
        spec, p, p.of(Hcsr04).mount_x_m, (HOUSING, APERTURE), _HOUSING_HALF_M, (0.15, 0.35, 0.75, 1.0)
    )


def _chain(params: Parameters, seed: int) -> Hcsr04Chain:
    return Hcsr04Chain(params, seed)


# Disturbances often enough that a few of a batch form's runs hold one; a cycle that falls within blocks.
_NOISY = Parameters().with_overrides(
    {"hcsr04.lost_echo_probability": 0.2, "hcsr04.spurious_echo_probability": 0.2, "hcsr04.cycle_s": 0.045}
)


def hcsr04_position_of(params: Parameters) -> Callable[[float], float]:
    """The software's conversion: an echo (µs) → d = echo·c(T)/2 → x = mount − r − d (``hcsr04_echo_us``'s nominal
    law inverted, at the part's temperature); NaN for ``pulseIn``'s 0 (no echo)."""
    s, r = params.of(Hcsr04), params.ball.radius_m
    c = float(speed_of_sound_m_s(s.temperature_c))

    def x_m(echo_us: float) -> float:
        if echo_us <= 0.0:
            return math.nan
        return s.mount_x_m - r - echo_us * 1e-6 * c / 2.0

    return x_m


HCSR04 = register(
    BallSensorPart(
        name="hcsr04",
        source="ElecFreaks HC-SR04 user guide: 2 cm–4 m, 0.3 cm resolution, width/58 = cm, 60 ms cycle; c(T) of "
        "an ideal gas; lost and spurious echoes and the jitter assumed (fit from a log)",
        groups={"hcsr04": Hcsr04},
        equations=(speed_of_sound_m_s, hcsr04_echo_us, near_distance_m, Hcsr04Chain, Hcsr04Batch),
        mjcf=MjcfFragment((("geom", HOUSING), ("site", APERTURE)), apply_hcsr04),
        batch=BatchForm(
            form_single(_chain),
            form_batch(Hcsr04Batch),
            form_inputs(
                _NOISY, ("hcsr04.temperature_c", "hcsr04.echo_jitter_us", "hcsr04.mount_x_m", "ball.radius_m")
            ),
            "twin.parts.hcsr04.Hcsr04Batch",
        ),
        chain=_chain,
        batch_chain=Hcsr04Batch,
        position_of=hcsr04_position_of,
        reading_unit=fixed_unit("µs"),  # pulseIn's echo width
    )
)
