"""What the three ranging ball sensors (``twin.parts.vl53l0x``, ``hcsr04``, ``gp2y0a21``) share: a sensor that
looks along the beam at the ball and puts out a new value at its own pace, which the board reads as it stands.

A ranging sensor samples the ball every ``period_s`` (its timing budget, measurement cycle or update period),
not when the board reads: sample k is taken at t_k = t_reset + k·period from the ball's position at t_k and its
mean over (t_k−1, t_k] (the window a time-of-flight range integrates), and published ``delay`` later (an echo's
width: the board has the value when the echo ends). Between publications the output holds, so a board that
reads faster than the sensor samples reads the same value again (stale). At ``reset`` the ball has rested at x
since long ago: the sensor's last sample is of it, published at once.

``SampledBatch`` runs N runs in step on shared block times, vectorized in numpy over the runs; a run alone
(``SampledChain``) is the batch of one run, so one run gives the same bits alone or in a batch. The sensor itself
is a ``Sampler``: its per-run parameters, its seeded generators and its equations (what a sample reads for the
ball's distance, the delay to its publication, and the board's reading of the output).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Protocol

import mujoco
import numpy as np

from twin import model as mdl
from twin.parameters import Parameters
from twin.parts.contract import vary
from twin.physics import PhysicsBlock

__all__ = [
    "SampledBatch",
    "SampledChain",
    "Sampler",
    "add_housing",
    "form_batch",
    "form_inputs",
    "form_single",
    "make_rng",
    "near_distance_m",
    "runs_of",
]

# The chain's clock and a block's first time may differ by rounding (the rig's times are sums of steps).
_CONTINUITY_S = 1e-9


def near_distance_m(mount_x_m: np.ndarray, x_m: np.ndarray, radius_m: np.ndarray) -> np.ndarray:
    """The distance from a sensor at ``mount_x_m`` on the beam, looking toward −x along it at the ball's centre
    height, to the ball's near surface: mount − x − r (m), never below 0 (the ball against the sensor)."""
    return np.maximum(mount_x_m - x_m - radius_m, 0.0)


def make_rng(seed: int | np.integer | np.random.Generator | None) -> np.random.Generator:
    """A run's generator: ``np.random.default_rng(seed)`` for a non-negative integer, the generator itself, or
    fresh entropy for None (not reproducible)."""
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
        raise ValueError(f"seed = {seed!r} is not a non-negative integer, a numpy Generator or None")
    return np.random.default_rng(seed)


def runs_of(
    params: Parameters | Sequence[Parameters], seeds: np.ndarray | Sequence[np.random.Generator], n: int
) -> tuple[list[Parameters], list[np.random.Generator]]:
    """A batch's n runs: their parameters (one set for all, or one each) and their generators (one seed or
    generator each: ``make_rng``)."""
    runs = [params] * n if isinstance(params, Parameters) else list(params)
    rngs = [make_rng(s) for s in (seeds.tolist() if isinstance(seeds, np.ndarray) else seeds)]
    if len(runs) != n or len(rngs) != n:
        raise ValueError(f"{n} runs need {n} parameter sets and {n} seeds (got {len(runs)} and {len(rngs)})")
    return runs, rngs


class Sampler(Protocol):
    """A ranging sensor over N runs: its per-run parameters (``use_params``), its sample period per run, what a
    sample puts out, and the board's reading of the output."""

    period_s: np.ndarray
    radius_m: np.ndarray
    half_length_m: np.ndarray

    def use_params(self, params: Sequence[Parameters]) -> None: ...

    def sample(
        self, rows: np.ndarray, x_mean_m: np.ndarray, x_m: np.ndarray, present: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For the runs ``rows`` sampling now: the output values, the delays to their publication (s) and which
        are disturbed (a wrong return, a lost or spurious echo), from the ball's mean position over the window,
        its position now and whether it is on the track (each run draws from its own generator, in order)."""
        ...

    def reading(self, rows: np.ndarray, output: np.ndarray) -> np.ndarray:
        """The board's reading of the runs' outputs (its unit: mm, µs, the ADC's)."""
        ...


class SampledBatch:
    """N runs of one ranging sensor in step (see the module docstring). ``output``: each run's published output
    (the sensor's unit); ``readings``: the board's reading of it; ``disturbed``: disturbed samples per run."""

    def __init__(self, sampler: Sampler, x_m: np.ndarray, t_s: float, present: np.ndarray) -> None:
        x = np.asarray(x_m, dtype=float)
        if not np.all(np.isfinite(x)) or not math.isfinite(t_s):
            raise ValueError(f"x_m = {x_m!r}, t_s = {t_s!r}: the ball's start must be finite")
        n = len(x)
        self.sampler = sampler
        rows = np.arange(n)
        here = np.asarray(present, dtype=bool) & (np.abs(x) <= sampler.half_length_m)
        values, _, disturbed = sampler.sample(rows, x, x, here)  # the sample of the ball at rest, published
        self.output = np.asarray(values, dtype=float).copy()
        self.pending = self.output.copy()
        self.pending_at = np.full(n, math.inf)
        self.time_s = float(t_s)
        self.t_last = np.full(n, float(t_s))
        self.t_next = self.t_last + sampler.period_s
        self.acc = np.zeros(n)  # ∫x dt from each run's last sample to the chain's time
        self.disturbed = np.asarray(disturbed, dtype=np.int64).copy()
        self.readings = np.asarray(sampler.reading(rows, self.output), dtype=float).copy()

    def advance(
        self, runs: np.ndarray, times_s: np.ndarray, x_m: np.ndarray, on_track: np.ndarray
    ) -> np.ndarray:
        """The runs ``runs`` (indices) over the shared ``times_s`` (K,) from the chain's time, their positions and
        on-track flags one row each (len(runs), K), x linear between the times (the interval (t_j, t_j+1] takes
        the flag at t_j+1): the board's readings at the block's end."""
        t = np.asarray(times_s, dtype=float)
        x = np.asarray(x_m, dtype=float)
        on = np.asarray(on_track, dtype=bool)
        s = self.sampler
        end = float(t[-1])
        if len(t) >= 2:
            # ∫x dt from the block's start to each knot (trapezoids: x is linear between knots), per run
            cum = np.zeros(x.shape)
            np.cumsum(0.5 * (x[:, :-1] + x[:, 1:]) * np.diff(t), axis=1, out=cum[:, 1:])
            due = self.t_next[runs] <= end
            while due.any():
                sel = np.flatnonzero(due)
                r = runs[sel]
                ts = self.t_next[r]
                j = np.clip(np.searchsorted(t, ts, side="left") - 1, 0, len(t) - 2)
                ta = t[j]
                xa, xb = x[sel, j], x[sel, j + 1]
                xs = xa + (xb - xa) * ((ts - ta) / (t[j + 1] - ta))
                so_far = cum[sel, j] + 0.5 * (xa + xs) * (ts - ta)  # ∫x dt from the block's start to t_k
                x_mean = (self.acc[r] + so_far) / (ts - self.t_last[r])
                present = on[sel, j + 1] & (np.abs(xs) <= s.half_length_m[r])
                ready = r[self.pending_at[r] <= ts]  # the previous sample's publication comes first
                self.output[ready] = self.pending[ready]
                values, delays, disturbed = s.sample(r, x_mean, xs, present)
                self.pending[r] = values
                self.pending_at[r] = ts + delays
                self.acc[r] = -so_far
                self.t_last[r] = ts
                self.t_next[r] = ts + s.period_s[r]
                self.disturbed[r] += disturbed
                due = self.t_next[runs] <= end
            self.acc[runs] += cum[:, -1]
        ready = runs[self.pending_at[runs] <= end]
        self.output[ready] = self.pending[ready]
        self.pending_at[ready] = math.inf
        self.time_s = end
        self.readings[runs] = s.reading(runs, self.output[runs])
        return self.readings[runs].copy()

    def set_params(self, params: Sequence[Parameters]) -> None:
        """New parameters from now on: the sample already scheduled keeps its time, the next ones the new period."""
        self.sampler.use_params(params)


def _finite_increasing(times_s: np.ndarray, x_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(times_s, dtype=float)
    x = np.asarray(x_m, dtype=float)
    if t.ndim != 1 or t.shape != x.shape or len(t) < 1:
        raise ValueError(f"times_s and x_m must be 1-D of one length (shapes {t.shape}, {x.shape})")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(x))):
        raise ValueError("times_s and x_m must be finite")
    if np.any(np.diff(t) <= 0.0):
        raise ValueError("times_s must increase strictly")
    return t, x


class SensorBatch(SampledBatch):
    """A ranging sensor's batch of N runs built from their parameters and seeds (each run its own, or one set for
    all): a sensor's module gives its ``Sampler`` (``make_sampler``, from the runs' parameters and generators)
    and nothing else. ``one`` is its one-run batch, what its ``SampledChain`` is made of."""

    @classmethod
    def make_sampler(cls, runs: list[Parameters], rngs: list[np.random.Generator]) -> Sampler:
        raise NotImplementedError(f"{cls.__name__} names no sampler")

    def __init__(
        self,
        params: Parameters | Sequence[Parameters],
        seeds: np.ndarray | Sequence[np.random.Generator],
        x_m: np.ndarray,
        t_s: float,
        present: np.ndarray | bool = True,
    ) -> None:
        n = len(x_m)
        runs, rngs = runs_of(params, seeds, n)
        super().__init__(
            self.make_sampler(runs, rngs), np.asarray(x_m, dtype=float), t_s, np.broadcast_to(present, (n,))
        )

    @classmethod
    def one(
        cls, params: Parameters, rng: np.random.Generator, x_m: float, t_s: float, present: bool
    ) -> SampledBatch:
        return cls(params, [rng], np.array([x_m]), t_s, present)


class RunsBatch(Protocol):
    """What a chain of one run needs of its batch (``SampledBatch``, or another sensor's batch form)."""

    readings: np.ndarray
    output: np.ndarray
    disturbed: np.ndarray
    time_s: float

    def advance(
        self, runs: np.ndarray, times_s: np.ndarray, x_m: np.ndarray, on_track: np.ndarray
    ) -> np.ndarray: ...

    def set_params(self, params: Sequence[Parameters]) -> None: ...


class SampledChain:
    """One run of a sensor's batch (``twin.parts.contract.BallSensorChain``): the batch of one run
    (``SampledBatch`` for a ranging sensor, ``RunsBatch`` for any), built by
    ``make_batch(params, rng, x_m, t_s, present)``. ``reading_v``: the board's last
    reading (its unit); ``filtered_v``: the sensor's output now (its unit: mm, µs or volts at the pin)."""

    reading_v: float
    filtered_v: float

    def __init__(
        self,
        params: Parameters,
        seed: int | np.random.Generator | None,
        make_batch: Callable[[Parameters, np.random.Generator, float, float, bool], RunsBatch],
        *,
        x_m: float = 0.0,
    ) -> None:
        self.params = params
        self._make_batch = make_batch
        self._rng = make_rng(seed)
        self.reset(x_m)

    def reset(
        self,
        x_m: float,
        t_s: float = 0.0,
        *,
        in_contact: bool = True,
        seed: int | np.random.Generator | None = None,
    ) -> None:
        """The ball at rest at ``x_m`` since long ago, the sensor's last sample of it published; ``seed``
        (optional) restarts the noise from that seed (else the generator runs on)."""
        if seed is not None:
            self._rng = make_rng(seed)
        self._batch = self._make_batch(self.params, self._rng, float(x_m), float(t_s), bool(in_contact))
        self._sync()

    def set_params(self, params: Parameters) -> None:
        """New parameters from now on (the noise switched, a new temperature); the generator runs on."""
        self.params = params
        self._batch.set_params([params])
        self._sync()

    @property
    def dropout_count(self) -> int:
        """Disturbed samples since the last reset (wrong returns, lost or spurious echoes)."""
        return int(self._batch.disturbed[0])

    @property
    def time_s(self) -> float:
        return self._batch.time_s

    def _sync(self) -> None:
        self.reading_v = float(self._batch.readings[0])
        self.filtered_v = float(self._batch.output[0])

    def advance(self, times_s: np.ndarray, x_m: np.ndarray, in_contact: bool | np.ndarray = True) -> float:
        """Advance over one block (``times_s`` from the chain's time, the ball at ``x_m`` there, linear between;
        ``in_contact`` one flag or one per time) and return the board's reading at its end."""
        t, x = _finite_increasing(times_s, x_m)
        if abs(t[0] - self._batch.time_s) > _CONTINUITY_S:
            raise ValueError(
                f"times_s[0] = {t[0]!r} s: the block must start at the chain's time {self.time_s!r} s"
            )
        contact = np.asarray(in_contact)
        if contact.dtype != np.bool_ or contact.shape not in ((), t.shape):
            raise ValueError(
                f"in_contact = {in_contact!r}: it must be a bool or one bool per time in times_s"
            )
        return self._advance(t, x, np.broadcast_to(contact, t.shape))

    def advance_block(self, block: PhysicsBlock) -> float:
        """``advance`` for a block the rig built."""
        return self._advance(block.time_s, block.x_m, block.on_track)

    def advance_rig_block(
        self,
        times_s: np.ndarray,
        x_m: np.ndarray,
        in_contact: np.ndarray,
        equal_steps: bool,
        x_range_m: tuple[float, float] | None = None,
        all_on_track: bool | None = None,
    ) -> float:
        """``advance`` for a block the rig built (checked by the rig; the hints are the wire's and unused)."""
        return self._advance(np.asarray(times_s, dtype=float), np.asarray(x_m, dtype=float), in_contact)

    def _advance(self, t: np.ndarray, x: np.ndarray, contact: np.ndarray) -> float:
        self._batch.advance(_ONE_RUN, t, x[None, :], np.asarray(contact, dtype=bool)[None, :])
        self._sync()
        return self.reading_v


_ONE_RUN = np.zeros(1, dtype=np.int64)


# --- the batch form the three sensors share ---------------------------------------------------------------
_FORM_BLOCKS = 12  # 240 ms: several samples of each sensor, a stale read or more
_FORM_STEPS = 20  # physics steps per block (a 20 ms period at 1 ms)


def _form_track(params: Parameters, row: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ball rolling at constant speed from the row's start: the times, positions and on-track flags."""
    times = np.arange(_FORM_BLOCKS * _FORM_STEPS + 1) * params.physics.timestep_s
    x = row[1] + row[2] * times
    return times, x, np.abs(x) <= params.track.half_length_m


def form_single(
    chain: Callable[[Parameters, int], SampledChain],
) -> Callable[[Parameters, np.ndarray], np.ndarray]:
    """A batch form's one-run side: the chain as the rig resets and advances it, each block's reading and the
    output at the end."""

    def single(params: Parameters, row: np.ndarray) -> np.ndarray:
        times, x, on = _form_track(params, row)
        seed = int(row[0])
        one = chain(params, seed)
        one.reset(float(x[0]), 0.0, seed=seed)
        out = []
        for b in range(_FORM_BLOCKS):
            k = slice(b * _FORM_STEPS, (b + 1) * _FORM_STEPS + 1)
            out.append(one.advance_rig_block(times[k], x[k], on[k], True))
        return np.array([*out, one.filtered_v])

    return single


def form_batch(
    batch: Callable[[Sequence[Parameters], np.ndarray, np.ndarray, float], RunsBatch],
) -> Callable[[Sequence[Parameters], np.ndarray], np.ndarray]:
    """A batch form's batch side: every run at once (``batch(params, seeds, x0, t0)``)."""

    def run(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
        tracks = [_form_track(p, row) for p, row in zip(params, rows, strict=True)]
        times = tracks[0][0]
        x = np.array([track[1] for track in tracks])
        on = np.array([track[2] for track in tracks])
        many = batch(list(params), rows[:, 0].astype(np.int64), x[:, 0], 0.0)
        runs = np.arange(len(rows))
        out = []
        for b in range(_FORM_BLOCKS):
            k = slice(b * _FORM_STEPS, (b + 1) * _FORM_STEPS + 1)
            out.append(many.advance(runs, times[k], x[:, k], on[:, k]))
        return np.column_stack([*out, many.output])

    return run


def form_inputs(
    base: Parameters, names: Sequence[str]
) -> Callable[[np.random.Generator, int], tuple[list[Parameters], np.ndarray]]:
    """A batch form's inputs: n runs around ``base`` (each with its own ``names``), each a seed, a start anywhere
    on the track and a speed that takes some past the +x end (off the track) or close to the sensor."""

    def inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
        params = vary(base, names, rng, n)
        seeds = rng.integers(0, 2**31, n).astype(float)
        return params, np.column_stack([seeds, rng.uniform(-0.3, 0.3, n), rng.uniform(-1.0, 1.0, n)])

    return inputs


def add_housing(
    spec: mujoco.MjSpec,
    p: Parameters,
    mount_x_m: float,
    names: tuple[str, str],
    half_m: tuple[float, float, float],
    rgba: tuple[float, float, float, float],
) -> None:
    """Adds a sensor's housing ``names[0]`` (a box of half-sizes ``half_m``, drawn only: group 2, no contacts,
    no mass) and a site ``names[1]`` at its aperture to the beam at ``mount_x_m``, at the ball's centre height
    (``Parameters.ball_centre_height_m``), the housing behind the aperture (+x), facing −x along the beam."""
    beam = spec.body(mdl.BEAM_BODY)
    if beam is None:
        raise ValueError(f"the model has no body {mdl.BEAM_BODY!r} to mount the sensor on")
    z = p.ball_centre_height_m
    geom = beam.add_geom()
    geom.name = names[0]
    geom.type = mujoco.mjtGeom.mjGEOM_BOX
    geom.size = list(half_m)
    geom.pos = [mount_x_m + half_m[0], 0.0, z]
    geom.contype = 0
    geom.conaffinity = 0
    geom.group = 2
    geom.mass = 0.0
    geom.rgba = list(rgba)
    site = beam.add_site()
    site.name = names[1]
    site.pos = [mount_x_m, 0.0, z]
    site.size = [0.001, 0.0, 0.0]
